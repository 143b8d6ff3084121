"""The triangle mesh container."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from softbody.errors import MeshError

if TYPE_CHECKING:
    import trimesh


@dataclass(frozen=True, eq=False)
class TriMesh:
    """A triangle mesh: positions and triangles, nothing else.

    Parameters
    ----------
    vertices : (V, 3) array of float
        Vertex positions [m]. Stored as a read-only float64 array.
    faces : (F, 3) array of int
        Vertex indices of each triangle, counter-clockwise seen from outside
        (so the right-hand normal points out). Stored as a read-only int64 array.

    Construction checks shapes, finiteness and index ranges only; whether the mesh can
    hold gas (closed, manifold, oriented) is checked by :func:`softbody.validate_mesh`,
    which :class:`softbody.ModelBuilder` runs on every body.
    """

    vertices: np.ndarray
    faces: np.ndarray

    def __init__(self, vertices: ArrayLike, faces: ArrayLike):
        v = np.array(vertices, dtype=np.float64, copy=True)
        f_in = np.asarray(faces)
        if v.ndim != 2 or v.shape[1] != 3:
            raise MeshError(f"vertices must have shape (V, 3), got {v.shape}")
        if f_in.ndim != 2 or f_in.shape[1] != 3:
            raise MeshError(f"faces must have shape (F, 3), got {f_in.shape}")
        if f_in.size and not np.issubdtype(f_in.dtype, np.integer):
            if not np.all(np.equal(np.mod(f_in, 1), 0)):
                raise MeshError("faces must hold integer vertex indices")
        f = np.array(f_in, dtype=np.int64, copy=True)
        bad = ~np.isfinite(v).all(axis=1)
        if bad.any():
            raise MeshError(
                f"{int(bad.sum())} of {len(v)} vertices have NaN or infinite coordinates"
            )
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise MeshError(
                f"face indices must lie in [0, {len(v) - 1}], found range "
                f"[{int(f.min())}, {int(f.max())}]"
            )
        v.setflags(write=False)
        f.setflags(write=False)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)

    # -- sizes -------------------------------------------------------------------------
    @property
    def vertex_count(self) -> int:
        """Number of vertices V."""
        return int(self.vertices.shape[0])

    @property
    def face_count(self) -> int:
        """Number of triangles F."""
        return int(self.faces.shape[0])

    # -- geometry ----------------------------------------------------------------------
    @property
    def face_normals_scaled(self) -> np.ndarray:
        """Cross products (b - a) x (c - a): outward normal times twice the area, (F, 3) [m^2]."""
        a, b, c = (self.vertices[self.faces[:, k]] for k in range(3))
        return np.cross(b - a, c - a)

    @property
    def face_areas(self) -> np.ndarray:
        """Triangle areas, (F,) [m^2]."""
        return 0.5 * np.linalg.norm(self.face_normals_scaled, axis=1)

    @property
    def area(self) -> float:
        """Total surface area [m^2]."""
        return float(self.face_areas.sum())

    @property
    def volume(self) -> float:
        """Signed enclosed volume by the divergence theorem [m^3].

        Summed over tetrahedra from the vertex centroid, which keeps round-off small for
        meshes far from the origin. Positive for an outward-wound closed mesh.
        """
        c = self.vertices.mean(axis=0)
        a, b, d = (self.vertices[self.faces[:, k]] - c for k in range(3))
        return float(np.einsum("ij,ij->", a, np.cross(b, d)) / 6.0)

    @property
    def edges(self) -> np.ndarray:
        """Unique undirected edges, (E, 2) int64 with ``edges[:, 0] < edges[:, 1]``."""
        from softbody.mesh.topology import unique_edges

        return unique_edges(self.faces)

    @property
    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]`` [m]."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    # -- transforms (return new meshes) --------------------------------------------------
    def translated(self, offset: ArrayLike) -> TriMesh:
        """This mesh moved by ``offset`` (3,) [m]."""
        return TriMesh(self.vertices + np.asarray(offset, dtype=np.float64), self.faces)

    def scaled(self, factor: float | ArrayLike) -> TriMesh:
        """This mesh scaled about the origin by a scalar or per-axis (3,) factor."""
        s = np.asarray(factor, dtype=np.float64)
        if np.any(s <= 0) or not np.all(np.isfinite(s)):
            raise ValueError(f"scale factor must be finite and > 0, got {factor!r}")
        return TriMesh(self.vertices * s, self.faces)

    def rotated(self, matrix: ArrayLike) -> TriMesh:
        """This mesh rotated about the origin by a (3, 3) rotation matrix."""
        r = np.asarray(matrix, dtype=np.float64)
        if r.shape != (3, 3) or not np.allclose(r @ r.T, np.eye(3), atol=1e-9):
            raise ValueError("matrix must be a (3, 3) rotation (orthonormal)")
        if np.linalg.det(r) < 0:
            raise ValueError("matrix is a reflection (det < 0); it would turn the mesh inside out")
        return TriMesh(self.vertices @ r.T, self.faces)

    def reordered(self, order: ArrayLike | None = None) -> TriMesh:
        """The same surface with vertices renumbered for memory locality.

        ``order`` (V,) lists old vertex indices in their new order; by default a Morton
        (Z-order) curve, so that neighbours in space are neighbours in memory. Faces are
        renumbered and sorted by their smallest vertex. Per-step kernels run faster on
        large meshes ordered this way; the physics is unchanged.
        """
        from softbody.mesh.ordering import morton_order

        perm = morton_order(self.vertices) if order is None else np.asarray(order, np.int64)
        if sorted(perm.tolist()) != list(range(self.vertex_count)):
            raise ValueError("order must be a permutation of the vertex indices")
        rank = np.empty_like(perm)
        rank[perm] = np.arange(len(perm))
        faces = rank[self.faces]
        faces = faces[np.lexsort((faces.max(axis=1), faces.min(axis=1)))]
        return TriMesh(self.vertices[perm], faces)

    def flipped(self) -> TriMesh:
        """This mesh with every triangle's winding reversed (normals turned around)."""
        return TriMesh(self.vertices, self.faces[:, ::-1])

    # -- interop -------------------------------------------------------------------------
    @classmethod
    def from_trimesh(cls, mesh: trimesh.Trimesh) -> TriMesh:
        """Copy vertices and faces out of a :class:`trimesh.Trimesh`."""
        return cls(np.asarray(mesh.vertices), np.asarray(mesh.faces))

    def to_trimesh(self) -> trimesh.Trimesh:
        """A :class:`trimesh.Trimesh` with the same vertices and faces (no processing)."""
        import trimesh

        return trimesh.Trimesh(self.vertices.copy(), self.faces.copy(), process=False)

    def __repr__(self) -> str:
        return f"TriMesh(vertex_count={self.vertex_count}, face_count={self.face_count})"
