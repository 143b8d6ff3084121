"""Triangle meshes: the container, generators, file I/O, topology and validation."""

from softbody.mesh.generators import box, capsule, cylinder, icosphere, rectangle, uv_sphere
from softbody.mesh.io import MESH_SUFFIXES, load_mesh, read_mesh, save_mesh
from softbody.mesh.tri_mesh import TriMesh
from softbody.mesh.validate import MeshReport, inspect_mesh, validate_mesh

__all__ = [
    "MESH_SUFFIXES",
    "MeshReport",
    "TriMesh",
    "box",
    "capsule",
    "cylinder",
    "icosphere",
    "inspect_mesh",
    "load_mesh",
    "read_mesh",
    "rectangle",
    "save_mesh",
    "uv_sphere",
    "validate_mesh",
]
