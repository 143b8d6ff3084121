"""The immutable model: topology and parameters, fixed after ``ModelBuilder.finalize``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from softbody.gas import GasLaw
from softbody.sim._model_fields import CoreFields
from softbody.volume import VolumeMethod


@dataclass(frozen=True, eq=False)
class Model(CoreFields):
    """Particles, springs, triangles, bodies and their gas, pins. All arrays are read-only.

    Build one with :class:`softbody.ModelBuilder`. Units are SI. N particles, S springs,
    A attachments, T triangles, B bodies, P pinned particles. The fields the compiled core
    reads come from :class:`~softbody.sim._model_fields.CoreFields`, generated at build time
    from their one declaration in ``core/fields.hpp``; the fields below are Python's alone.
    """

    particle_q: np.ndarray
    """Initial particle positions [m], shape (N, 3)."""
    particle_qd: np.ndarray
    """Initial particle velocities [m/s], shape (N, 3)."""
    attachment_anchor: np.ndarray
    """Default anchor points [m], shape (A, 3); ``Control.attachment_anchor`` moves them."""
    body_mass: np.ndarray
    """Total mass of each body [kg], shape (B,)."""
    particle_source_vertex: np.ndarray
    """For each particle, the index of the vertex of the mesh given to
    ``add_soft_body``/``add_cloth`` whose position it starts at (the first of the input
    vertices welded into it), shape (N,) int64; -1 for a particle added by itself. Welding
    merges duplicate seam vertices, so a body can have fewer particles than its input mesh
    had vertices; this maps each particle back."""
    tri_source_vertex: np.ndarray
    """For each corner of each triangle, the input mesh's vertex at that corner, shape
    (T, 3) int64 (same corner order as ``tri_indices``; a flipped input has its corners
    reversed with its triangles). Seam duplicates stay apart here: per-vertex data of the
    input mesh, such as UVs, maps onto the triangles' corners as ``data[tri_source_vertex]``."""

    def __post_init__(self):
        for name in self.__dataclass_fields__:
            value = getattr(self, name, None)
            if isinstance(value, np.ndarray):
                value.setflags(write=False)

    # -- counts --------------------------------------------------------------------------
    @property
    def particle_count(self) -> int:
        """Number of particles N."""
        return int(self.particle_q.shape[0])

    @property
    def spring_count(self) -> int:
        """Number of springs S (edges, bending and user springs)."""
        return int(self.spring_indices.shape[0])

    @property
    def attachment_count(self) -> int:
        """Number of attachment springs A."""
        return int(self.attachment_particle.shape[0])

    @property
    def tri_count(self) -> int:
        """Number of surface triangles T."""
        return int(self.tri_indices.shape[0])

    @property
    def membrane_count(self) -> int:
        """Number of membrane triangles Tm (a face with two membrane layers counts twice)."""
        return int(self.membrane_indices.shape[0])

    @property
    def body_count(self) -> int:
        """Number of soft bodies B."""
        return int(self.body_particle_range.shape[0])

    @property
    def collider_count(self) -> int:
        """Number of rigid colliders C."""
        return int(self.collider_kind.shape[0])

    @property
    def pin_count(self) -> int:
        """Number of pinned particles P."""
        return int(self.pin_particle.shape[0])

    def body_gas_law_of(self, body: int) -> GasLaw:
        """The gas law of ``body``."""
        return GasLaw(int(self.body_gas_law[body]))

    def body_volume_method_of(self, body: int) -> VolumeMethod:
        """The volume method of ``body``."""
        return VolumeMethod(int(self.body_volume_method[body]))

    # -- factories -----------------------------------------------------------------------
    def state(self):
        """A new :class:`State` at the initial positions and velocities, time 0, with the
        initial gas amounts; its gas temperatures are left None, so that they are set on
        each gas's isentrope at the state's positions when it first meets the model (the
        model's temperatures, unless positions were changed first)."""
        from softbody.sim.state import State

        return State(
            self.particle_q.copy(),
            self.particle_qd.copy(),
            collider_q=self.collider_center.copy(),
            collider_rotation=self.collider_rotation.copy(),
            body_gas_override=np.full(self.body_count, np.nan),
            body_gas_moles=self.initial_gas_moles(),
            vent_open=np.zeros(len(self.vent_body)),
        )

    def gas_temperature_at(self, particle_q: np.ndarray) -> np.ndarray:
        """Each body's gas temperature [K] at positions ``particle_q`` (N, 3), shape (B,),
        on the isentrope through its initial state: the model's temperature for an
        isothermal or fixed-pressure gas, T0 (V_rest / V)^(g - 1) for an adiabatic one
        (V by the body's own volume method)."""
        from softbody import _core
        from softbody.sim.state import kernel_input

        temperature = np.array(self.body_gas_temperature, dtype=np.float64)
        adiabatic = (np.asarray(self.body_gas_law) == GasLaw.ADIABATIC) & (self.body_closed == 1)
        if not adiabatic.any():
            return temperature
        volume = _core.body_volumes(
            kernel_input(particle_q),
            self.tri_indices,
            self.body_particle_range,
            self.body_tri_range,
            self.body_volume_method,
            self.body_mc_range,
            self.mc_samples,
        )
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = (self.body_rest_volume / volume) ** (self.body_gas_gamma - 1.0)
        return np.where(adiabatic & np.isfinite(ratio), temperature * ratio, temperature)

    def initial_gas_moles(self) -> np.ndarray:
        """Each body's amount of gas at the initial positions [mol], shape (B,): nRT / (R T)
        of an isothermal or adiabatic gas (nRT at its reference volume, which is the rest
        volume unless given), P0 V / (R T) of a fixed-pressure one; 0 for an open surface."""
        from softbody.gas import GAS_CONSTANT

        value = np.asarray(self.body_gas_value, dtype=np.float64)
        temperature = np.asarray(self.body_gas_temperature, dtype=np.float64)
        law = np.asarray(self.body_gas_law)
        gamma = np.asarray(self.body_gas_gamma, dtype=np.float64)
        rest, ref = self.body_rest_volume, self.body_gas_reference_volume
        with np.errstate(divide="ignore", invalid="ignore"):
            # an adiabatic gas: T at the rest volume, nRT = R n T_ref at V_ref, with
            # T_ref = T (V_rest / V_ref)^(g - 1) on its isentrope
            at_rest = np.where(law == GasLaw.ADIABATIC, (rest / ref) ** (gamma - 1.0), 1.0)
            nrt = np.where(law == GasLaw.FIXED_PRESSURE, value * rest, value)
            moles = nrt / (GAS_CONSTANT * temperature * at_rest)
        moles = np.where((self.body_closed == 1) & np.isfinite(moles), moles, 0.0)
        return moles.astype(np.float64)

    def control(self):
        """A :class:`Control` that changes nothing: model gas, no forces, anchors in place."""
        from softbody.sim.control import Control

        return Control.neutral(self)

    def __repr__(self) -> str:
        return (
            f"Model(particle_count={self.particle_count}, spring_count={self.spring_count}, "
            f"tri_count={self.tri_count}, body_count={self.body_count}, "
            f"attachment_count={self.attachment_count}, pin_count={self.pin_count}, "
            f"collider_count={self.collider_count})"
        )
