"""Checks that a mesh can hold gas, and the repairs that are safe to make automatically.

A body's pressure force is only exact, and its volume only meaningful, on a closed,
edge-manifold, consistently wound surface. :func:`inspect_mesh` measures every way a
mesh can fail that; :func:`validate_mesh` repairs what is safe (welds duplicate seam
vertices, drops triangles that welding collapsed, flips an inward-wound mesh) and refuses
the rest with a :class:`~softbody.errors.MeshError` that names each problem and its count.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from softbody.errors import MeshError, MeshWarning
from softbody.mesh.intersect import outward_by_rays
from softbody.mesh.intersect import self_intersections as self_intersections_of
from softbody.mesh.topology import edge_half_edge_groups, half_edges, unique_rows
from softbody.mesh.tri_mesh import TriMesh

#: Vertices closer than this fraction of the bounding-box diagonal are welded.
WELD_TOLERANCE = 1e-8
#: A triangle whose height is below this fraction of its longest edge is degenerate.
DEGENERATE_TOLERANCE = 1e-10
#: Meshes up to this many triangles are searched for self-intersections whenever they are
#: inspected or loaded (about 0.6 s of CPU at this size, 5 s at 327,680 triangles);
#: larger ones only on request (``inspect_mesh(..., self_intersections=True)``, as
#: ``softbody info`` does).
SELF_INTERSECTION_AUTO_FACES = 50_000


@dataclass(frozen=True)
class MeshReport:
    """What :func:`inspect_mesh` found. Counts refer to the mesh after welding."""

    input_vertex_count: int
    input_face_count: int
    welded_vertex_count: int
    """Vertices merged into another at the same position (UV seams, STL triangle soup)."""
    collapsed_face_count: int
    """Triangles that welding reduced to a line (two corners merged); they are dropped."""
    unreferenced_vertex_count: int
    """Vertices no triangle uses; they are dropped."""
    boundary_edge_count: int
    """Edges used by one triangle only: holes in the surface."""
    nonmanifold_edge_count: int
    """Edges used by three or more triangles."""
    inconsistent_edge_count: int
    """Edges whose two triangles run the same way along them (winding flips across them)."""
    degenerate_face_count: int
    """Triangles with (numerically) zero area."""
    nonmanifold_vertex_count: int
    """Vertices where two separate fans of triangles touch (pinched points)."""
    shell_count: int
    """Separate connected pieces of surface."""
    signed_volume: float
    """Enclosed volume [m^3] by the divergence theorem; negative for an inward-wound mesh
    (when the surface does not cross itself)."""
    mesh: TriMesh = field(repr=False)
    """The welded mesh with collapsed faces and unreferenced vertices dropped, wound outward
    when it is closed (a repair candidate; use it only when :attr:`problems` is empty)."""
    intersecting_pairs: np.ndarray | None = field(default=None, repr=False)
    """Pairs of triangles of :attr:`mesh` that cross each other, (K, 2) face indices;
    None when the search was not made (large mesh, see ``SELF_INTERSECTION_AUTO_FACES``)."""
    outward_by_rays: int = 0
    """Winding judged from outside by rays (+1 outward, -1 inward, 0 not judged), before
    any flip; made only for self-intersecting closed meshes, whose signed volume can lie."""
    flipped: bool = False
    """Whether :attr:`mesh` had its winding reversed to face outward."""
    vertex_source: np.ndarray | None = field(default=None, repr=False)
    """For each vertex of :attr:`mesh`, the input vertex it keeps the position of (the
    first of the input vertices welded into it), shape (V,) int64."""
    corner_source: np.ndarray | None = field(default=None, repr=False)
    """For each corner of each triangle of :attr:`mesh`, the input vertex at that corner,
    shape (F, 3) int64: input seam duplicates stay apart here, so per-vertex data of the
    input (UVs) maps onto :attr:`mesh`'s corners as ``data[corner_source]``."""

    @property
    def self_intersection_count(self) -> int | None:
        """How many pairs of triangles cross each other (None: not searched)."""
        return None if self.intersecting_pairs is None else len(self.intersecting_pairs)

    @property
    def warnings(self) -> list[str]:
        """Facts a user should know that do not stop the mesh holding gas."""
        out = []
        if self.self_intersection_count:
            a, b = self.intersecting_pairs[0]
            out.append(
                f"self-intersecting: {self.self_intersection_count} pairs of triangles cross "
                f"each other (e.g. triangles {a} and {b}); it can still hold gas, but its "
                "volume and pressure count the crossed part twice or not at all"
            )
        if self.self_intersection_count and self.outward_by_rays * self.signed_volume < 0:
            seen = "outward" if self.outward_by_rays > 0 else "inward"
            out.append(
                f"winding: the outer surface faces {seen} but the signed volume is "
                f"{self.signed_volume:.6g} m^3, because the surface crosses itself; the "
                "winding follows the outer surface"
            )
        return out

    @property
    def problems(self) -> list[str]:
        """Human-readable reasons the mesh cannot hold gas; empty when it can."""
        out = []
        if self.input_face_count < 4:
            out.append(f"only {self.input_face_count} triangles; a closed surface needs >= 4")
        if self.boundary_edge_count:
            out.append(
                f"open: {self.boundary_edge_count} boundary edges (used by only one triangle)"
            )
        if self.nonmanifold_edge_count:
            out.append(
                f"non-manifold: {self.nonmanifold_edge_count} edges shared by 3 or more triangles"
            )
        if self.inconsistent_edge_count:
            out.append(
                f"inconsistent winding: {self.inconsistent_edge_count} edges where neighbouring "
                "triangles face opposite ways"
            )
        if self.degenerate_face_count:
            out.append(f"degenerate: {self.degenerate_face_count} triangles with zero area")
        if self.nonmanifold_vertex_count:
            out.append(
                f"non-manifold: {self.nonmanifold_vertex_count} vertices where separate "
                "surface sheets touch"
            )
        if self.shell_count > 1:
            out.append(f"{self.shell_count} separate shells; add each closed piece as its own body")
        if not out and not abs(self.signed_volume) > 0:
            out.append("encloses zero volume")
        return out

    @property
    def is_closed(self) -> bool:
        """True when the mesh can hold gas (after the safe repairs)."""
        return not self.problems

    @property
    def repairs(self) -> list[str]:
        """Safe repairs :func:`validate_mesh` makes, as human-readable lines."""
        out = []
        if self.welded_vertex_count:
            out.append(f"welded {self.welded_vertex_count} duplicate vertices")
        if self.collapsed_face_count:
            out.append(f"dropped {self.collapsed_face_count} triangles collapsed by welding")
        if self.unreferenced_vertex_count:
            out.append(f"dropped {self.unreferenced_vertex_count} unreferenced vertices")
        if self.flipped:
            out.append("flipped inward-facing winding")
        return out


def _weld(vertices: np.ndarray, faces: np.ndarray, tolerance: float):
    """Merge vertices within ``tolerance`` [m] (grid snapping), keeping first-seen order:
    (vertices, faces, merged count, index of each kept vertex in the input)."""
    if len(vertices) == 0 or not tolerance > 0:
        return vertices, faces, 0, np.arange(len(vertices), dtype=np.int64)
    lo = vertices.min(axis=0)
    keys = np.round((vertices - lo) / tolerance).astype(np.int64)
    _, first, inverse = unique_rows(keys, return_index=True, return_inverse=True)
    # renumber groups by the position of their first vertex so unwelded meshes keep order
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    keep = np.sort(first)
    return vertices[keep], rank[inverse][faces], len(vertices) - len(keep), keep


def _nonmanifold_vertex_count(faces: np.ndarray, vertex_count: int) -> int:
    """Vertices whose corners form more than one fan (valid only on an edge-manifold mesh)."""
    face_count = len(faces)
    he = half_edges(faces)
    corner_vertex = faces.reshape(-1)  # corner 3f+k sits at vertex faces[f, k] = he[3f+k, 0]
    # half-edge b->a in face g is the twin of a->b in face f; rotating around a, corner
    # (f, a) connects to the corner of g at a, which starts g's half-edge a->x
    directed = he[:, 0] * vertex_count + he[:, 1]
    twin_key = he[:, 1] * vertex_count + he[:, 0]
    order = np.argsort(directed)
    pos = np.searchsorted(directed[order], twin_key)
    pos = np.minimum(pos, len(order) - 1)
    twin = order[pos]
    ok = directed[twin] == twin_key
    src = np.flatnonzero(ok)
    # the twin half-edge b->a of face g ends at a; the corner of g at a is the next one
    g = twin[src] // 3
    k = (twin[src] % 3 + 1) % 3
    dst = 3 * g + k
    n = 3 * face_count
    graph = coo_matrix((np.ones(len(src)), (src, dst)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    fans = unique_rows(np.stack([corner_vertex, label], axis=1))
    fan_count = np.bincount(fans[:, 0], minlength=vertex_count)
    return int(np.count_nonzero(fan_count > 1))


def inspect_mesh(
    mesh: TriMesh,
    *,
    weld_tolerance: float = WELD_TOLERANCE,
    self_intersections: bool | None = None,
) -> MeshReport:
    """Measure everything that would stop ``mesh`` from holding gas. Never raises for
    topology problems (only for malformed arrays, which :class:`TriMesh` already refuses).

    Parameters
    ----------
    mesh : TriMesh
        The mesh to inspect.
    weld_tolerance : float
        Vertices closer than this fraction of the bounding-box diagonal are merged.
    self_intersections : bool or None
        Search for triangles crossing each other: always (True), never (False), or
        when the mesh has at most ``SELF_INTERSECTION_AUTO_FACES`` triangles (None).
    """
    v_in, f_in = mesh.vertices, mesh.faces
    diag = float(np.linalg.norm(np.ptp(v_in, axis=0))) if len(v_in) else 0.0
    v, f, welded, kept = _weld(v_in, f_in, max(diag, 1e-300) * weld_tolerance)
    collapsed = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])
    f = f[~collapsed]
    corners = f_in[~collapsed]
    used = np.zeros(len(v), dtype=bool)
    used[f.reshape(-1)] = True
    remap = np.cumsum(used) - 1
    v, f, kept = v[used], remap[f], kept[used]
    vertex_count = len(v)

    if len(f):
        _, counts, order = edge_half_edge_groups(f)
    else:
        counts = order = np.zeros(0, dtype=np.int64)
    boundary = int(np.count_nonzero(counts == 1))
    nonmanifold = int(np.count_nonzero(counts > 2))
    inconsistent = 0
    if len(f):
        he = half_edges(f)
        start = np.cumsum(counts) - counts
        two = start[counts == 2]
        first, second = he[order[two]], he[order[two + 1]]
        inconsistent = int(np.count_nonzero(first[:, 0] == second[:, 0]))

    if len(f):
        a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
        cross_len = np.linalg.norm(np.cross(b - a, c - a), axis=1)
        longest = np.max(
            np.stack(
                [
                    np.linalg.norm(b - a, axis=1),
                    np.linalg.norm(c - b, axis=1),
                    np.linalg.norm(a - c, axis=1),
                ]
            ),
            axis=0,
        )
        degenerate = int(np.count_nonzero(cross_len <= DEGENERATE_TOLERANCE * longest**2))
    else:
        degenerate = 0

    shells = 0
    if len(f):
        # triangles are connected when they share an edge
        he_face = np.arange(3 * len(f)) // 3
        start = np.cumsum(counts) - counts
        multi = np.flatnonzero(counts >= 2)
        src = he_face[order[start[multi]]]
        rows, cols = [], []
        for j in range(1, int(counts.max()) if len(counts) else 1):
            sel = counts[multi] > j
            rows.append(src[sel])
            cols.append(he_face[order[start[multi][sel] + j]])
        rows = np.concatenate(rows) if rows else np.zeros(0, dtype=np.int64)
        cols = np.concatenate(cols) if cols else np.zeros(0, dtype=np.int64)
        graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(f), len(f)))
        shells, _ = connected_components(graph, directed=False)

    pinched = 0
    if len(f) and boundary == 0 and nonmanifold == 0 and inconsistent == 0:
        pinched = _nonmanifold_vertex_count(f, vertex_count)

    volume = TriMesh(v, f).volume if len(f) else 0.0
    closed = len(f) >= 4 and boundary == nonmanifold == inconsistent == 0
    if self_intersections is None:
        self_intersections = len(f) <= SELF_INTERSECTION_AUTO_FACES
    crossing = self_intersections_of(v, f) if self_intersections else None
    # a surface that crosses itself can have a negative signed volume while wound
    # outward: judge its winding from outside instead
    rays = outward_by_rays(v, f) if closed and crossing is not None and len(crossing) else 0
    inward = rays < 0 if rays else volume < 0
    if closed and inward:
        f = f[:, ::-1]
        corners = corners[:, ::-1]
    return MeshReport(
        input_vertex_count=len(v_in),
        input_face_count=len(f_in),
        welded_vertex_count=welded,
        collapsed_face_count=int(np.count_nonzero(collapsed)),
        unreferenced_vertex_count=int(np.count_nonzero(~used)),
        boundary_edge_count=boundary,
        nonmanifold_edge_count=nonmanifold,
        inconsistent_edge_count=inconsistent,
        degenerate_face_count=degenerate,
        nonmanifold_vertex_count=pinched,
        shell_count=int(shells),
        signed_volume=float(volume),
        mesh=TriMesh(v, f),
        intersecting_pairs=crossing,
        outward_by_rays=rays,
        flipped=bool(closed and inward),
        vertex_source=np.ascontiguousarray(kept, dtype=np.int64),
        corner_source=np.ascontiguousarray(corners, dtype=np.int64),
    )


def validate_mesh(
    mesh: TriMesh,
    *,
    name: str = "mesh",
    weld_tolerance: float = WELD_TOLERANCE,
    closed: bool = True,
) -> TriMesh:
    """Return a closed, outward-wound copy of ``mesh`` or raise :class:`MeshError`.

    Safe repairs (welding duplicate vertices, dropping collapsed triangles and unused
    vertices, flipping an inward-wound mesh) are made with a :class:`MeshWarning`;
    open, non-manifold, inconsistently wound, degenerate or multi-shell meshes are refused
    with every problem and its count in the message. With ``closed=False`` (cloth) a
    boundary is allowed and the winding is kept as given.
    """
    return validate_mesh_report(
        mesh, name=name, weld_tolerance=weld_tolerance, closed=closed, stacklevel=3
    ).mesh


def validate_mesh_report(
    mesh: TriMesh,
    *,
    name: str = "mesh",
    weld_tolerance: float = WELD_TOLERANCE,
    closed: bool = True,
    stacklevel: int = 2,
) -> MeshReport:
    """:func:`validate_mesh`, returning the whole :class:`MeshReport`: the repaired mesh
    (``.mesh``) with its map back to the input's vertices (``.vertex_source``,
    ``.corner_source``). Warnings point ``stacklevel`` frames up (2: this call's caller)."""
    report = inspect_mesh(mesh, weld_tolerance=weld_tolerance)
    if not closed:
        problems = [
            p for p in report.problems if not p.startswith(("open:", "encloses zero volume"))
        ]
        if problems:
            raise MeshError(f"{name} is not a usable surface: " + "; ".join(problems))
        if report.welded_vertex_count or report.collapsed_face_count:
            warnings.warn(
                f"{name}: " + "; ".join(report.repairs[:2]), MeshWarning, stacklevel=stacklevel
            )
        return report
    if report.problems:
        raise MeshError(f"{name} cannot hold gas: " + "; ".join(report.problems))
    if report.repairs:
        warnings.warn(f"{name}: " + "; ".join(report.repairs), MeshWarning, stacklevel=stacklevel)
    for line in report.warnings:
        warnings.warn(f"{name}: {line}", MeshWarning, stacklevel=stacklevel)
    return report
