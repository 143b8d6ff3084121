"""softbody: pressure soft bodies (Matyka & Ollila) on a fast spring-mass engine.

Closed triangle meshes with mass-carrying vertices, damped springs on the edges and an
ideal gas inside whose pressure pushes every face outward along its normal.
"""

from softbody.bending import Bending
from softbody.collision import (
    ColliderBox,
    ColliderMesh,
    ColliderPlane,
    ColliderSphere,
    MotionOscillation,
    MotionRotation,
    MotionTranslation,
)
from softbody.diagnostics import (
    Energies,
    body_area,
    body_center_of_mass,
    body_centroid,
    body_gas_flows,
    body_gas_value,
    body_mesh,
    body_pressure,
    body_volume,
    energies,
)
from softbody.errors import MeshError, MeshWarning, SimulationError, StabilityWarning
from softbody.gas import GAS_CONSTANT, Gas, GasLaw
from softbody.integrators import Integrator
from softbody.membrane import Membrane, MembraneMaterial
from softbody.mesh import (
    MeshReport,
    TriMesh,
    box,
    capsule,
    cylinder,
    icosphere,
    inspect_mesh,
    load_mesh,
    read_mesh,
    rectangle,
    save_mesh,
    uv_sphere,
    validate_mesh,
)
from softbody.render.recorder import Recorder
from softbody.sim import Control, Model, ModelBuilder, Simulator, State, StepHistory
from softbody.stability import stable_dt
from softbody.volume import VolumeMethod

__version__ = "0.1.0"


def __getattr__(name: str):
    # sweeps pull in Dask and pyarrow: imported on first use, never by `import softbody`
    if name == "sweep":
        import importlib

        return importlib.import_module("softbody.sweep")
    raise AttributeError(f"module 'softbody' has no attribute {name!r}")


__all__ = [
    "GAS_CONSTANT",
    "Bending",
    "ColliderBox",
    "ColliderMesh",
    "ColliderPlane",
    "ColliderSphere",
    "Control",
    "Energies",
    "Gas",
    "GasLaw",
    "Integrator",
    "Membrane",
    "MembraneMaterial",
    "MeshError",
    "MeshReport",
    "MeshWarning",
    "Model",
    "ModelBuilder",
    "MotionOscillation",
    "MotionRotation",
    "MotionTranslation",
    "Recorder",
    "SimulationError",
    "Simulator",
    "StabilityWarning",
    "State",
    "StepHistory",
    "TriMesh",
    "VolumeMethod",
    "body_area",
    "body_center_of_mass",
    "body_centroid",
    "body_gas_flows",
    "body_gas_value",
    "body_mesh",
    "body_pressure",
    "body_volume",
    "box",
    "capsule",
    "cylinder",
    "energies",
    "icosphere",
    "inspect_mesh",
    "load_mesh",
    "read_mesh",
    "rectangle",
    "save_mesh",
    "stable_dt",
    "uv_sphere",
    "validate_mesh",
]
