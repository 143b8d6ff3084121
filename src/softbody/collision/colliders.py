"""Rigid colliders (ground plane, box container, solid boxes and spheres, closed triangle
meshes) and their motions.

Colliders are rigid, infinitely massive shapes that particles may not enter. Each is
static, follows a prescribed motion, or is driven per call through ``Control`` (a ball
the user pushes). Shapes are described in a local frame: a box by its half-extents, a
sphere by its radius, a plane by the local +y axis as its normal (the allowed side).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np
from numpy.typing import ArrayLike


class ColliderKind(IntEnum):
    """Shape of a collider and on which side particles must stay."""

    PLANE = 0  # half-space: particles stay on the normal side
    BOX_CONTAINER = 1  # closed box: particles stay inside
    SPHERE = 2  # solid sphere: particles stay outside
    BOX = 3  # solid box: particles stay outside
    MESH = 4  # closed triangle mesh: particles stay outside


class SoftContactMode(IntEnum):
    """How soft bodies meet each other (``ModelBuilder.set_soft_contact``)."""

    NONE = 0  # they pass through each other
    BOUNDING = 1  # the paper's bounding objects
    SURFACE = 2  # vertex against triangle, on the surfaces


class MotionKind(IntEnum):
    """Prescribed motion of a collider."""

    STATIC = 0
    ROTATION = 1  # constant angular velocity about a pivot
    TRANSLATION = 2  # constant velocity
    OSCILLATION = 3  # centre + amplitude sin(2 pi f t)


def _vec3(name: str, value: ArrayLike) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return v


def _coefficient(name: str, value: float) -> float:
    x = float(value)
    if not (np.isfinite(x) and 0.0 <= x <= 1.0):
        raise ValueError(f"{name} must lie in [0, 1], got {value!r}")
    return x


def _rotation(value: ArrayLike | None) -> np.ndarray:
    if value is None:
        return np.eye(3)
    r = np.asarray(value, dtype=np.float64)
    if (
        r.shape != (3, 3)
        or not np.allclose(r @ r.T, np.eye(3), atol=1e-9)
        or (np.linalg.det(r) < 0)
    ):
        raise ValueError("rotation must be a (3, 3) proper rotation matrix")
    return r


def rotation_about(axis: ArrayLike, angle: float) -> np.ndarray:
    """Rotation matrix (3, 3) by ``angle`` [rad] about ``axis`` (Rodrigues' formula)."""
    a = _vec3("axis", axis)
    n = np.linalg.norm(a)
    if n == 0:
        return np.eye(3)
    k = a / n
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


@dataclass(frozen=True)
class MotionRotation:
    """Spin at ``angular_velocity`` (3,) [rad/s] about ``pivot`` [m] (default: the centre)."""

    angular_velocity: ArrayLike
    pivot: ArrayLike | None = None


@dataclass(frozen=True)
class MotionTranslation:
    """Move at constant ``velocity`` (3,) [m/s]."""

    velocity: ArrayLike


@dataclass(frozen=True)
class MotionOscillation:
    """Centre + ``amplitude`` (3,) [m] * sin(2 pi ``frequency`` [Hz] t)."""

    amplitude: ArrayLike
    frequency: float


Motion = MotionRotation | MotionTranslation | MotionOscillation | None


@dataclass(frozen=True)
class _ColliderBase:
    restitution: float = 0.5
    """Fraction of the normal approach speed kept after a bounce, in [0, 1]."""
    friction: float = 0.1
    """Fraction of the tangential speed removed at each contact, in [0, 1] (the paper's
    scaling of the tangential velocity)."""
    motion: Motion = None
    """Prescribed motion; None is static (Control can still drive it)."""


@dataclass(frozen=True)
class ColliderPlane(_ColliderBase):
    """Infinite plane through ``point`` [m]; particles stay on the side ``normal`` points to."""

    point: ArrayLike = (0.0, 0.0, 0.0)
    normal: ArrayLike = (0.0, 1.0, 0.0)


@dataclass(frozen=True)
class ColliderBox(_ColliderBase):
    """Box with ``half_extents`` [m] about ``center`` [m], turned by ``rotation`` (3, 3).

    ``container=True`` keeps particles inside (the paper's box); otherwise the box is solid
    and keeps them out.
    """

    center: ArrayLike = (0.0, 0.0, 0.0)
    half_extents: ArrayLike = (0.5, 0.5, 0.5)
    rotation: ArrayLike | None = None
    container: bool = False


@dataclass(frozen=True)
class ColliderSphere(_ColliderBase):
    """Solid sphere of ``radius`` [m] about ``center`` [m]."""

    center: ArrayLike = (0.0, 0.0, 0.0)
    radius: float = 0.5


@dataclass(frozen=True, init=False, eq=False)
class ColliderMesh(_ColliderBase):
    """Any closed triangle mesh as a solid collider: particles stay outside it.

    ``mesh`` is a :class:`~softbody.TriMesh`, a ``trimesh.Trimesh`` or the path of a mesh
    file (read with the project's loader). It must be one closed, consistently wound,
    non-self-intersecting surface: anything else raises ValueError naming the file (or
    "mesh"). Duplicate vertices are welded and an inward-wound mesh is turned outward.

    The mesh is placed as given: its pose is ``center`` [m] (default: the centre of its
    bounding box, where the mesh already is) and ``rotation`` (3, 3) about that centre;
    ``motion`` and ``Control.collider_target`` move that centre as for the other
    colliders. A particle that enters it during a step, or passes through a thin part of
    it, is put back where its path entered, ``margin`` [m] outside the surface (default
    ``1e-4`` of the mesh's bounding-box diagonal).

    The mesh's edges and faces also meet the soft bodies' edges and triangles, so that
    neither surface passes through the other between soft vertices that all stay outside
    (``core/collision/mesh.hpp``): a soft edge across a sharp edge (convex, its two faces'
    normals more than ``sharp_angle`` [deg] apart; default 30: a box's edges) is pushed out
    to ``margin`` beyond it; a soft triangle a corner or a smooth surface's cap pokes
    through, past it; and a soft edge cutting a chord through the mesh anywhere (a rounded
    edge's or a tube's tessellation as well), out to ``margin`` from the surface.
    ``sharp_angle=None`` (or 180): soft vertices against the mesh only.

    After construction, ``mesh`` is the checked (welded, outward-wound) TriMesh, ``name``
    the file it came from (or "mesh"), and ``data`` its arrays for the core
    (:class:`softbody.collision.mesh_collider.MeshColliderData`).
    """

    mesh: Any = None
    center: ArrayLike | None = None
    rotation: ArrayLike | None = None
    margin: float | None = None
    sharp_angle: float | None = 30.0

    def __init__(
        self,
        mesh: Any,
        *,
        restitution: float = 0.5,
        friction: float = 0.1,
        motion: Motion = None,
        center: ArrayLike | None = None,
        rotation: ArrayLike | None = None,
        margin: float | None = None,
        sharp_angle: float | None = 30.0,
    ) -> None:
        from softbody.collision.mesh_collider import checked_mesh, mesh_collider_data

        if sharp_angle is not None:
            angle = float(sharp_angle)
            if not (np.isfinite(angle) and 0.0 <= angle <= 180.0):
                raise ValueError(f"sharp_angle must be in [0, 180] degrees, got {sharp_angle!r}")
        checked, name = checked_mesh(mesh)
        data = mesh_collider_data(checked, sharp_angle)
        for key, value in (("restitution", restitution), ("friction", friction),
                           ("motion", motion), ("center", center), ("rotation", rotation),
                           ("margin", margin), ("sharp_angle", sharp_angle),
                           ("mesh", checked)):  # fmt: skip
            object.__setattr__(self, key, value)
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "data", data)

    def __repr__(self) -> str:
        return (
            f"ColliderMesh({self.name}: {len(self.data.vertices)} vertices, "
            f"{len(self.data.triangles)} triangles)"
        )


Collider = ColliderPlane | ColliderBox | ColliderSphere | ColliderMesh


@dataclass
class ColliderArrays:
    """Flat arrays describing C colliders, as stored in the Model."""

    kind: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    center: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    rotation: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    size: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    restitution: np.ndarray = field(default_factory=lambda: np.zeros(0))
    friction: np.ndarray = field(default_factory=lambda: np.zeros(0))
    motion: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    motion_vector: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    motion_pivot: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    motion_frequency: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mesh_range: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    mesh_root: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    mesh_margin: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mesh_vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    mesh_triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    mesh_vertex_normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    mesh_edge_normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    mesh_sharp_edges: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    mesh_node_sharp: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    mesh_node_children: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    mesh_node_tris: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    mesh_node_bounds: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))


def collider_arrays(colliders: list[Collider]) -> ColliderArrays:
    """Validate ``colliders`` and flatten them into arrays."""
    rows = []
    meshes = []
    for k, col in enumerate(colliders):
        name = f"collider {k}"
        restitution = _coefficient(f"{name} restitution", col.restitution)
        friction = _coefficient(f"{name} friction", col.friction)
        size = np.zeros(3)
        if isinstance(col, ColliderPlane):
            kind = ColliderKind.PLANE
            center = _vec3(f"{name} point", col.point)
            n = _vec3(f"{name} normal", col.normal)
            if np.linalg.norm(n) == 0:
                raise ValueError(f"{name} normal must not be zero")
            n = n / np.linalg.norm(n)
            # a rotation taking local +y to n
            axis = np.cross([0.0, 1.0, 0.0], n)
            angle = np.arctan2(np.linalg.norm(axis), n[1])
            rotation = rotation_about(axis if np.linalg.norm(axis) > 0 else [1.0, 0, 0], angle)
        elif isinstance(col, ColliderBox):
            kind = ColliderKind.BOX_CONTAINER if col.container else ColliderKind.BOX
            center = _vec3(f"{name} center", col.center)
            size = _vec3(f"{name} half_extents", col.half_extents)
            if np.any(size <= 0):
                raise ValueError(f"{name} half_extents must be > 0, got {col.half_extents!r}")
            rotation = _rotation(col.rotation)
        elif isinstance(col, ColliderSphere):
            kind = ColliderKind.SPHERE
            center = _vec3(f"{name} center", col.center)
            r = float(col.radius)
            if not (np.isfinite(r) and r > 0):
                raise ValueError(f"{name} radius must be finite and > 0, got {col.radius!r}")
            size = np.array([r, r, r])
            rotation = np.eye(3)
        elif isinstance(col, ColliderMesh):
            kind = ColliderKind.MESH
            data = col.data
            center = data.center if col.center is None else _vec3(f"{name} center", col.center)
            size = data.half_extents.copy()
            rotation = _rotation(col.rotation)
            margin = (
                1e-4 * 2.0 * float(np.linalg.norm(data.half_extents))
                if col.margin is None
                else float(col.margin)
            )
            if not (np.isfinite(margin) and margin > 0):
                raise ValueError(f"{name} margin must be finite and > 0, got {col.margin!r}")
            meshes.append((k, data, margin))
        else:
            raise TypeError(f"{name}: not a collider: {type(col).__name__}")
        motion, vector, pivot, freq = MotionKind.STATIC, np.zeros(3), center.copy(), 0.0
        m = col.motion
        if isinstance(m, MotionRotation):
            motion, vector = (
                MotionKind.ROTATION,
                _vec3(f"{name} angular_velocity", m.angular_velocity),
            )
            pivot = center.copy() if m.pivot is None else _vec3(f"{name} pivot", m.pivot)
        elif isinstance(m, MotionTranslation):
            motion, vector = MotionKind.TRANSLATION, _vec3(f"{name} velocity", m.velocity)
        elif isinstance(m, MotionOscillation):
            motion, vector = MotionKind.OSCILLATION, _vec3(f"{name} amplitude", m.amplitude)
            freq = float(m.frequency)
            if not (np.isfinite(freq) and freq >= 0):
                raise ValueError(f"{name} frequency must be finite and >= 0")
        elif m is not None:
            raise TypeError(f"{name}: unknown motion {type(m).__name__}")
        rows.append(
            (kind, center, rotation, size, restitution, friction, motion, vector, pivot, freq)
        )
    if not rows:
        return ColliderArrays()
    cols = list(zip(*rows, strict=True))
    count = len(rows)
    mesh_range = np.zeros((count, 2), np.int64)
    mesh_root = np.full(count, -1, np.int64)
    mesh_margin = np.zeros(count)
    parts: dict[str, list[np.ndarray]] = {key: [] for key in (
        "vertices", "triangles", "vertex_normals", "edge_normals", "node_children",
        "node_tris", "node_bounds", "sharp_edges", "node_sharp")}  # fmt: skip
    nv = nt = nn = 0
    for k, data, margin in meshes:
        inner = data.node_tris[:, 1] == data.node_tris[:, 0]
        mesh_range[k] = (nt, nt + len(data.triangles))
        mesh_root[k] = nn
        mesh_margin[k] = margin
        parts["vertices"].append(data.vertices)
        parts["triangles"].append(data.triangles + nv)
        parts["vertex_normals"].append(data.vertex_normals)
        parts["edge_normals"].append(data.edge_normals)
        parts["sharp_edges"].append(np.where(data.sharp_edges >= 0, data.sharp_edges + nt,
                                              data.sharp_edges))  # fmt: skip
        parts["node_children"].append(np.where(inner[:, None], data.node_children + nn, 0))
        parts["node_tris"].append(np.where(inner[:, None], 0, data.node_tris + nt))
        parts["node_bounds"].append(data.node_bounds)
        parts["node_sharp"].append(data.node_sharp)
        nv, nt, nn = nv + len(data.vertices), nt + len(data.triangles), nn + len(data.node_tris)
    empty = ColliderArrays()

    def joined(key: str) -> np.ndarray:
        if not parts[key]:
            return getattr(empty, f"mesh_{key}")
        return np.ascontiguousarray(np.concatenate(parts[key]))

    return ColliderArrays(
        kind=np.array(cols[0], dtype=np.int64),
        center=np.array(cols[1]),
        rotation=np.array(cols[2]),
        size=np.array(cols[3]),
        restitution=np.array(cols[4]),
        friction=np.array(cols[5]),
        motion=np.array(cols[6], dtype=np.int64),
        motion_vector=np.array(cols[7]),
        motion_pivot=np.array(cols[8]),
        motion_frequency=np.array(cols[9], dtype=np.float64),
        mesh_range=mesh_range,
        mesh_root=mesh_root,
        mesh_margin=mesh_margin,
        mesh_vertices=joined("vertices"),
        mesh_triangles=joined("triangles"),
        mesh_vertex_normals=joined("vertex_normals"),
        mesh_edge_normals=joined("edge_normals"),
        mesh_sharp_edges=joined("sharp_edges"),
        mesh_node_sharp=joined("node_sharp"),
        mesh_node_children=joined("node_children"),
        mesh_node_tris=joined("node_tris"),
        mesh_node_bounds=joined("node_bounds"),
    )
