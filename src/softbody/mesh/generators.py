"""Closed mesh generators. All return outward-wound :class:`TriMesh` objects, y up."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from softbody import limits
from softbody.mesh.tri_mesh import TriMesh

# trimesh builds capsules and cylinders along z; turn them to stand along y (our "up")
_Z_TO_Y = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def _positive(name: str, value: float) -> float:
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return value


def _count(name: str, value: int, minimum: int) -> int:
    try:  # int(inf) raises OverflowError, int(nan) and int("x") ValueError
        whole = int(value)
        ok = whole == value and whole >= minimum
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return whole


def _f(n: int) -> float:
    """A count as a float, inf when too large for one (a huge Python int)."""
    return float(n) if n < 1e300 else math.inf


def _arg(n: int) -> str:
    """A count for a message: digits, or a power of ten when it has too many."""
    return str(n) if n < 10**15 else f"about 10^{math.log10(n):.0f}"


def _power(base: float, exponent: int) -> float:
    """``base ** exponent`` as a float, inf where it overflows (never a huge Python int)."""
    try:
        return float(base) ** exponent
    except OverflowError:
        return math.inf


def _guard_size(call: str, vertices: float, faces: float) -> None:
    """Refuse, before allocating, a mesh of ``vertices`` vertices and ``faces`` triangles
    that would not fit in memory (:func:`softbody.limits.check_mesh_size`); ``call`` names
    the generator and the arguments that set the size, e.g. ``icosphere(subdivisions=12)``."""
    vertices, faces = float(vertices), float(faces)
    if vertices < 1e15:
        limits.check_mesh_size(call, vertices, faces)
        return
    # astronomically many: say so in powers of ten rather than with hundreds of digits
    estimate = limits.BYTES_PER_PARTICLE * vertices + limits.BYTES_PER_FACE * faces
    size = f"about 10^{math.log10(vertices):.0f}" if math.isfinite(vertices) else "over 10^300"
    limits.check_memory(call, estimate, f"a mesh of {size} vertices")


def _center(center: ArrayLike) -> np.ndarray:
    c = np.asarray(center, dtype=np.float64)
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        raise ValueError(f"center must be 3 finite numbers, got {center!r}")
    return c


def icosphere(subdivisions: int, radius: float = 1.0, center: ArrayLike = (0, 0, 0)) -> TriMesh:
    """Geodesic sphere: an icosahedron split ``subdivisions`` times, vertices on the sphere.

    Vertex counts are 10 * 4**s + 2 (12, 42, 162, 642, 2562, 10242, 40962, 163842, ...);
    ``subdivisions=2`` gives the paper's ball (162 vertices, 320 faces). Vertices are
    numbered along a space-filling curve (:meth:`TriMesh.reordered`) for fast kernels.

    Parameters
    ----------
    subdivisions : int
        Number of 1-to-4 triangle splits, >= 0.
    radius : float
        Circumradius [m]: every vertex lies at this distance from ``center``.
    center : (3,) array of float
        Center [m].
    """
    s = _count("subdivisions", subdivisions, 0)
    r = _positive("radius", radius)
    split = _power(4.0, s)  # each subdivision splits every triangle in four
    _guard_size(f"icosphere(subdivisions={_arg(s)})", 10.0 * split + 2.0, 20.0 * split)
    import trimesh.creation  # after the guard: importing it is 15 MB

    m = trimesh.creation.icosphere(subdivisions=s, radius=1.0)
    v = np.asarray(m.vertices, dtype=np.float64)
    v /= np.linalg.norm(v, axis=1, keepdims=True)  # exactly on the sphere
    return TriMesh(v, m.faces).reordered().scaled(r).translated(_center(center))


def uv_sphere(
    rings: int = 16, segments: int = 32, radius: float = 1.0, center: ArrayLike = (0, 0, 0)
) -> TriMesh:
    """Latitude-longitude sphere with one vertex at each pole (on the y axis).

    Parameters
    ----------
    rings : int
        Number of latitude bands, >= 2.
    segments : int
        Number of longitude segments, >= 3. A multiple of 4 puts vertices on the x and z axes.
    radius : float
        Radius [m]; every vertex lies on the sphere.
    center : (3,) array of float
        Center [m].
    """
    n_r = _count("rings", rings, 2)
    n_s = _count("segments", segments, 3)
    r = _positive("radius", radius)
    _guard_size(
        f"uv_sphere(rings={_arg(n_r)}, segments={_arg(n_s)})",
        _f(n_r - 1) * _f(n_s) + 2.0,
        2.0 * _f(n_r - 1) * _f(n_s),
    )
    theta = np.linspace(0.0, np.pi, n_r + 1)[1:-1]  # polar angle of the inner rings
    phi = np.linspace(0.0, 2.0 * np.pi, n_s, endpoint=False)
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    ring = np.stack(
        [st * np.cos(phi), np.broadcast_to(ct, (n_r - 1, n_s)), -st * np.sin(phi)], axis=2
    ).reshape(-1, 3)
    v = np.vstack([[0.0, 1.0, 0.0], ring, [0.0, -1.0, 0.0]])
    north, south = 0, len(v) - 1

    def idx(i, j):  # ring i (0 = nearest north), segment j
        return 1 + i * n_s + (j % n_s)

    j = np.arange(n_s)
    faces = [np.stack([np.full(n_s, north), idx(0, j), idx(0, j + 1)], axis=1)]
    for i in range(n_r - 2):
        a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
        faces += [np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)]
    faces.append(np.stack([idx(n_r - 2, j + 1), idx(n_r - 2, j), np.full(n_s, south)], axis=1))
    return TriMesh(v * r + _center(center), np.vstack(faces))


def box(
    extents: ArrayLike = (1.0, 1.0, 1.0), center: ArrayLike = (0, 0, 0), subdivisions: int = 0
) -> TriMesh:
    """Axis-aligned box, each side split into a grid of ``2**subdivisions`` squares per edge.

    Parameters
    ----------
    extents : (3,) array of float
        Side lengths along x, y, z [m].
    center : (3,) array of float
        Center [m].
    subdivisions : int
        Grid refinement level, >= 0 (0 gives 8 vertices and 12 triangles).
    """
    ext = np.asarray(extents, dtype=np.float64)
    if ext.shape != (3,) or not np.all(np.isfinite(ext)) or np.any(ext <= 0):
        raise ValueError(f"extents must be 3 finite numbers > 0, got {extents!r}")
    s = _count("subdivisions", subdivisions, 0)
    side = _power(2.0, s)  # squares per box edge
    # six grids of (n + 1)^2 vertices each before the shared edges are welded
    _guard_size(f"box(subdivisions={_arg(s)})", 6.0 * (side + 1) * (side + 1), 12.0 * side * side)
    n = 2**s
    t = np.linspace(-0.5, 0.5, n + 1)
    u, w = np.meshgrid(t, t, indexing="ij")
    u, w = u.reshape(-1), w.reshape(-1)
    grid_faces = []
    k = np.arange(n)
    ii, jj = np.meshgrid(k, k, indexing="ij")
    ii, jj = ii.reshape(-1), jj.reshape(-1)
    a = ii * (n + 1) + jj
    b, c, d = a + (n + 1), a + (n + 1) + 1, a + 1
    quad = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    verts = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            p = np.zeros((len(u), 3))
            p1, p2 = (axis + 1) % 3, (axis + 2) % 3
            p[:, axis], p[:, p1], p[:, p2] = 0.5 * sign, u, w
            # (p1, p2) grid with normal +axis is counter-clockwise; flip for the -axis side
            f = quad if sign > 0 else quad[:, ::-1]
            grid_faces.append(f + sum(len(x) for x in verts))
            verts.append(p)
    mesh = TriMesh(np.vstack(verts) * ext + _center(center), np.vstack(grid_faces))
    from softbody.mesh.validate import inspect_mesh

    # weld the shared edges of the six sides
    return inspect_mesh(mesh, self_intersections=False).mesh


def capsule(
    radius: float = 0.5,
    length: float = 1.0,
    rings: int = 8,
    segments: int = 16,
    center: ArrayLike = (0, 0, 0),
) -> TriMesh:
    """Capsule along y: a cylinder of ``length`` [m] capped by two hemispheres of ``radius`` [m].

    ``rings`` latitude bands per hemisphere and ``segments`` around the axis.
    """
    r = _positive("radius", radius)
    h = _positive("length", length)
    n_r = _count("rings", rings, 2)
    n_s = _count("segments", segments, 3)
    vertex_count = 2.0 * _f(n_r) * _f(n_s) + 2.0  # trimesh's capsule with count=[n_s, 2 n_r]
    _guard_size(
        f"capsule(rings={_arg(n_r)}, segments={_arg(n_s)})", vertex_count, 2.0 * vertex_count - 4.0
    )
    import trimesh.creation

    m = trimesh.creation.capsule(height=h, radius=r, count=[n_s, 2 * n_r])
    return TriMesh(np.asarray(m.vertices) @ _Z_TO_Y.T + _center(center), m.faces)


def cylinder(
    radius: float = 0.5, height: float = 1.0, segments: int = 32, center: ArrayLike = (0, 0, 0)
) -> TriMesh:
    """Closed cylinder along y with flat caps: ``segments`` sides, ``radius`` and ``height`` [m]."""
    r = _positive("radius", radius)
    h = _positive("height", height)
    n_s = _count("segments", segments, 3)
    _guard_size(f"cylinder(segments={_arg(n_s)})", 2.0 * _f(n_s) + 2.0, 4.0 * _f(n_s))
    import trimesh.creation

    m = trimesh.creation.cylinder(radius=r, height=h, sections=n_s)
    return TriMesh(np.asarray(m.vertices) @ _Z_TO_Y.T + _center(center), m.faces)


def rectangle(
    size: ArrayLike = (1.0, 1.0), resolution: ArrayLike = (16, 16), center: ArrayLike = (0, 0, 0)
) -> TriMesh:
    """Open rectangle in the xy plane facing +z (a cloth): ``size`` (width, height) [m],
    ``resolution`` (nx, ny) squares, each split into two triangles."""
    sx, sy = (float(v) for v in size)
    _positive("width", sx)
    _positive("height", sy)
    res = tuple(resolution) if np.ndim(resolution) == 1 else ()
    if len(res) != 2:
        raise ValueError(f"resolution must be two integers (nx, ny), got {resolution!r}")
    nx, ny = (_count("resolution", v, 1) for v in res)
    _guard_size(
        f"rectangle(resolution=({_arg(nx)}, {_arg(ny)}))",
        (_f(nx) + 1) * (_f(ny) + 1),
        2.0 * _f(nx) * _f(ny),
    )
    x, y = np.meshgrid(
        np.linspace(-sx / 2, sx / 2, nx + 1), np.linspace(-sy / 2, sy / 2, ny + 1), indexing="ij"
    )
    v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    a = (i * (ny + 1) + j).ravel()
    b, c, d = a + (ny + 1), a + (ny + 1) + 1, a + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return TriMesh(v + _center(center), faces)
