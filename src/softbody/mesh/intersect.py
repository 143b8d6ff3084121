"""Self-intersections of a triangle mesh: pairs of triangles whose surfaces cross.

A closed mesh whose triangles cross each other still passes every topological check
(closed, manifold, consistently wound), but its "inside" is ambiguous: the divergence
theorem counts the overlapping part twice or with the wrong sign, so its volume, its
pressure and even the sign used to decide its winding cannot be trusted.

The search is vectorised NumPy throughout (no Python loop over triangles):

* broad phase: a uniform grid whose cells are about one triangle across; each triangle
  is entered in every cell its bounding box touches, and the triangles sharing a cell are
  paired. A pair is kept only in the cell holding the lower corner of the overlap of the
  two boxes, so no pair is tested twice, and only when the boxes really overlap.
* narrow phase, by how many vertices the two triangles share:

  - none: the separating axis theorem with 20 candidate axes (both normals, the 9
    cross products of edge pairs, and the in-plane edge normals that decide coplanar
    pairs: each triangle's edges across the other's normal, and the second's edges across
    its own, which a segment given as a flat first triangle needs), so crossing,
    coplanar-overlapping and contained triangles are all found;
  - one (a fan around a vertex): they overlap beyond that vertex exactly when the edge
    opposite the shared vertex of one triangle meets the other triangle (the two pieces
    of the planes' common line start at the shared vertex; the shorter one ends on its
    triangle's opposite edge inside the other triangle). That covers crossing and
    coplanar folded fans alike;
  - two (neighbours across an edge): they overlap only when folded flat onto each other
    (coplanar, third vertices on the same side of the shared edge);
  - three: the same triangle twice.

Triangles that only *touch* (a vertex on a face, edges meeting at a point) are not
counted: a pair must overlap by more than ``TOUCH_TOLERANCE`` times the mesh's size.
"""

from __future__ import annotations

import numpy as np

from softbody.mesh.topology import unique_rows

#: Overlaps smaller than this fraction of the bounding-box diagonal count as touching.
TOUCH_TOLERANCE = 1e-9
#: Candidate pairs tested at once: bounds the narrow phase's temporary arrays (~1 kB each).
PAIR_CHUNK = 65_536
#: The broad-phase grid enters each triangle in at most about this many cells on average.
CELLS_PER_TRIANGLE = 8


def _cross_axes(p1: np.ndarray, p2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 20 candidate separating axes of triangles ``p1``, ``p2`` (P, 3, 3), unit length,
    and whether each is usable (a cross product of parallel or zero vectors is not).

    The in-plane normals of the second triangle's edges are taken across both normals:
    across ``n1`` they are lost when the first "triangle" is a segment (a, b, b), whose
    normal is 0, and a coplanar segment beside the triangle is then separated by no axis.
    """
    e1 = np.roll(p1, -1, axis=1) - p1  # (P, 3, 3): edges k -> k+1
    e2 = np.roll(p2, -1, axis=1) - p2
    n1 = np.cross(e1[:, 0], e1[:, 1])
    n2 = np.cross(e2[:, 0], e2[:, 1])
    i, j = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    i, j = i.reshape(-1), j.reshape(-1)
    u = np.concatenate(
        [
            e1[:, :1],
            e2[:, :1],
            e1[:, i],
            np.repeat(n2[:, None], 3, axis=1),
            np.repeat(n1[:, None], 3, axis=1),
            np.repeat(n2[:, None], 3, axis=1),
        ],
        axis=1,
    )
    v = np.concatenate([e1[:, 1:2], e2[:, 1:2], e2[:, j], e1, e2, e2], axis=1)
    axes = np.cross(u, v)
    length = np.linalg.norm(axes, axis=2)
    # an axis from (nearly) parallel factors has no direction: it separates nothing
    usable = length > 1e-9 * np.linalg.norm(u, axis=2) * np.linalg.norm(v, axis=2)
    axes = axes / np.where(usable, length, 1.0)[..., None]
    return axes, usable


def triangles_intersect(p1: np.ndarray, p2: np.ndarray, tolerance: float = 0.0) -> np.ndarray:
    """Whether triangles ``p1[k]`` and ``p2[k]`` overlap by more than ``tolerance`` [m].

    Parameters
    ----------
    p1, p2 : (P, 3, 3) array of float
        Corner positions [m] of P triangle pairs. A segment (a, b) may be given as the
        degenerate triangle (a, b, b): the test is then segment against triangle.
    tolerance : float
        Overlaps along some axis no larger than this [m] count as touching, not crossing.

    Returns
    -------
    (P,) array of bool
        True where no separating axis exists (the closed triangles share more than a
        touching point or edge).
    """
    p1 = np.asarray(p1, dtype=np.float64).reshape(-1, 3, 3)
    p2 = np.asarray(p2, dtype=np.float64).reshape(-1, 3, 3)
    out = np.zeros(len(p1), dtype=bool)
    for begin in range(0, len(p1), PAIR_CHUNK):
        a, b = p1[begin : begin + PAIR_CHUNK], p2[begin : begin + PAIR_CHUNK]
        axes, usable = _cross_axes(a, b)
        s1 = np.einsum("pkd,pvd->pkv", axes, a)
        s2 = np.einsum("pkd,pvd->pkv", axes, b)
        lo1, hi1, lo2, hi2 = s1.min(axis=2), s1.max(axis=2), s2.min(axis=2), s2.max(axis=2)
        # intervals meeting only at an end (within tolerance) touch: apart
        apart = (hi1 <= lo2 + tolerance) | (hi2 <= lo1 + tolerance)
        # but two flat projections (the common normal of coplanar triangles, or of a
        # segment in a triangle's plane) are apart only when the planes are
        flat = (hi1 - lo1 <= tolerance) & (hi2 - lo2 <= tolerance)
        apart = np.where(flat, (hi1 < lo2 - tolerance) | (hi2 < lo1 - tolerance), apart)
        out[begin : begin + len(a)] = ~np.any(apart & usable, axis=1)
    return out


def _candidate_pairs(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Triangle pairs (C, 2), ``a < b``, whose bounding boxes ``lo``, ``hi`` (F, 3) overlap,
    each once (uniform-grid broad phase)."""
    count = len(lo)
    if count < 2:
        return np.zeros((0, 2), dtype=np.int64)
    origin = lo.min(axis=0)
    extent = float(np.max(hi.max(axis=0) - origin))
    size = float(np.median(np.max(hi - lo, axis=1)))
    if not size > 0:
        size = max(extent, 1e-300) / np.cbrt(count)
    while True:  # grow the cells until triangles sit in a bounded number of them
        c_lo = np.floor((lo - origin) / size).astype(np.int64)
        c_hi = np.floor((hi - origin) / size).astype(np.int64)
        span = c_hi - c_lo + 1
        cells = np.prod(span, axis=1)
        if cells.sum() <= CELLS_PER_TRIANGLE * count or size >= extent:
            break
        size *= 2.0
    total = int(cells.sum())
    tri = np.repeat(np.arange(count), cells)
    k = np.arange(total) - np.repeat(np.cumsum(cells) - cells, cells)
    sy, sz = span[tri, 1], span[tri, 2]
    coord = c_lo[tri] + np.stack([k // (sy * sz), (k // sz) % sy, k % sz], axis=1)
    dims = c_hi.max(axis=0) + 1
    if float(np.prod(dims.astype(float))) < 2.0**62:  # one integer key per cell
        cell_key = (coord[:, 0] * dims[1] + coord[:, 1]) * dims[2] + coord[:, 2]
    else:  # a grid too fine for one int64: number the occupied cells instead
        _, cell_key = unique_rows(coord, return_inverse=True)
        dims = None
    order = np.argsort(cell_key, kind="stable")
    tri, coord, cell_key = tri[order], coord[order], cell_key[order]
    group_end = np.searchsorted(cell_key, cell_key, side="right")
    rest = group_end - np.arange(total) - 1  # later entries of the same cell
    pairs = []
    bounds = np.searchsorted(np.cumsum(rest), np.arange(0, int(rest.sum()), 4 * PAIR_CHUNK))
    for begin, end in zip(bounds, [*bounds[1:].tolist(), total], strict=True):
        r = rest[begin:end]
        first = np.repeat(np.arange(begin, end), r)
        second = first + 1 + np.arange(len(first)) - np.repeat(np.cumsum(r) - r, r)
        a, b = tri[first], tri[second]
        keep = np.all((lo[a] <= hi[b]) & (lo[b] <= hi[a]), axis=1)
        first, a, b = first[keep], a[keep], b[keep]
        # the overlap's lower corner lies in exactly one cell: test the pair only there
        corner = np.floor((np.maximum(lo[a], lo[b]) - origin) / size).astype(np.int64)
        corner = np.clip(corner, c_lo[a], c_hi[a])
        if dims is not None:
            mine = (corner[:, 0] * dims[1] + corner[:, 1]) * dims[2] + corner[:, 2]
            keep = mine == cell_key[first]
        else:
            keep = np.all(corner == coord[first], axis=1)
        pairs.append(np.sort(np.stack([a[keep], b[keep]], axis=1), axis=1))
    return np.concatenate(pairs) if pairs else np.zeros((0, 2), dtype=np.int64)


def self_intersections(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Pairs of triangles that cross each other, (K, 2) int64 face indices, ``a < b``,
    sorted. Touching pairs and neighbours that merely share a vertex or an edge are not
    listed; see the module notes for what is covered.

    Parameters
    ----------
    vertices : (V, 3) array of float
        Positions [m].
    faces : (F, 3) array of int
        Triangles.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    corners = v[f]  # (F, 3, 3)
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    tol = TOUCH_TOLERANCE * float(np.linalg.norm(np.ptp(v[np.unique(f)], axis=0)))
    pairs = _candidate_pairs(lo - tol, hi + tol)
    fa, fb = f[pairs[:, 0]], f[pairs[:, 1]]
    same = fa[:, :, None] == fb[:, None, :]  # (C, 3, 3): corner i of a is corner j of b
    shared = same.sum(axis=(1, 2))
    hit = np.zeros(len(pairs), dtype=bool)

    sel = np.flatnonzero(shared == 0)
    if len(sel):
        pa, pb = corners[pairs[sel, 0]], corners[pairs[sel, 1]]
        hit[sel] = _planes_straddle(pa, pb, tol) & _planes_straddle(pb, pa, tol)
        sel = sel[hit[sel]]
        hit[sel] = triangles_intersect(corners[pairs[sel, 0]], corners[pairs[sel, 1]], tol)

    sel = np.flatnonzero(shared == 1)
    if len(sel):
        ia = np.argmax(same[sel].any(axis=2), axis=1)  # shared corner's index in a
        ib = np.argmax(same[sel].any(axis=1), axis=1)
        pa, pb = corners[pairs[sel, 0]], corners[pairs[sel, 1]]
        hit[sel] = _edge_meets(_opposite_edge(pa, ia), pb, tol) | _edge_meets(
            _opposite_edge(pb, ib), pa, tol
        )

    sel = np.flatnonzero(shared == 2)
    if len(sel):
        ia = np.argmin(same[sel].any(axis=2), axis=1)  # the corner of a not in b
        ib = np.argmin(same[sel].any(axis=1), axis=1)
        pa, pb = corners[pairs[sel, 0]], corners[pairs[sel, 1]]
        rows = np.arange(len(sel))
        c, d = pa[rows, ia], pb[rows, ib]
        p, q = pa[rows, (ia + 1) % 3], pa[rows, (ia + 2) % 3]  # the shared edge
        n = np.cross(q - p, c - p)
        n_len = np.linalg.norm(n, axis=1)
        flat = np.abs(np.einsum("ij,ij->i", n, d - p)) <= tol * n_len
        same_side = np.einsum("ij,ij->i", n, np.cross(q - p, d - p)) > 0
        hit[sel] = flat & same_side & (n_len > 0)

    hit[shared == 3] = True
    found = pairs[hit]
    return found[np.lexsort((found[:, 1], found[:, 0]))]


def _planes_straddle(p: np.ndarray, q: np.ndarray, tol: float) -> np.ndarray:
    """Whether triangle ``q`` reaches both sides of (or into) the plane of ``p`` (P, 3, 3),
    beyond ``tol`` [m]: the cheap rejection before the full separating-axis test."""
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n_len = np.linalg.norm(n, axis=1)
    d = np.einsum("pd,pvd->pv", n, q - p[:, :1]) / np.where(n_len > 0, n_len, 1.0)[:, None]
    return (d.min(axis=1) <= tol) & (d.max(axis=1) >= -tol)


def _edge_meets(edge: np.ndarray, p: np.ndarray, tol: float) -> np.ndarray:
    """Whether segments ``edge`` (P, 3, 3) as (a, b, b) meet triangles ``p`` (P, 3, 3);
    the plane test first, since on a smooth surface most fans' edges lie off it."""
    out = _planes_straddle(p, edge, tol)
    sel = np.flatnonzero(out)
    out[sel] = triangles_intersect(edge[sel], p[sel], tol)
    return out


def _opposite_edge(p: np.ndarray, corner: np.ndarray) -> np.ndarray:
    """The edge of each triangle ``p`` (P, 3, 3) opposite ``corner`` (P,), as the
    degenerate triangle (a, b, b) that :func:`triangles_intersect` takes for a segment."""
    rows = np.arange(len(p))
    a, b = p[rows, (corner + 1) % 3], p[rows, (corner + 2) % 3]
    return np.stack([a, b, b], axis=1)


def outward_by_rays(vertices: np.ndarray, faces: np.ndarray, rays: int = 15) -> int:
    """Winding seen from outside: +1 outward, -1 inward, 0 undecided.

    Rays come in from far along +x, aimed at the centroids of ``rays`` evenly spread
    triangles; the first triangle each ray hits is on the outer surface, so its normal
    must face the ray's origin on an outward-wound mesh. Unlike the sign of the signed
    volume, this stays right when the surface crosses itself (the crossed part is then
    counted twice or with the wrong sign by the divergence theorem). Majority vote.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return 0
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    e1, e2 = b - a, c - a
    normal = np.cross(e1, e2)
    aim = (a + b + c)[np.linspace(0, len(f) - 1, rays).astype(np.int64)] / 3.0
    votes = 0
    d = np.array([-1.0, 0.0, 0.0])  # rays travel along -x from beyond the mesh
    start_x = v[:, 0].max() + 1.0 + np.ptp(v[:, 0])
    for target in aim:  # a loop over a few rays; each is vectorised over the triangles
        o = np.array([start_x, target[1], target[2]])
        # Moller-Trumbore: o + t d = a + u e1 + w e2
        p = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, p)
        ok = np.abs(det) > 1e-300
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = o - a
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1)
        w = (q @ d) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
        inside = ok & (u > 0) & (w > 0) & (u + w < 1) & (t > 0)
        if not inside.any():
            continue
        first = np.flatnonzero(inside)[np.argmin(t[inside])]
        votes += 1 if normal[first] @ d < 0 else -1
    return int(np.sign(votes))
