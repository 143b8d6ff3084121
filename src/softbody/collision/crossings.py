"""Edges that pass through triangles: an independent NumPy check of a surface (every
edge-triangle pair whose boxes meet, found through a uniform grid, tested exactly), for
tests and benchmarks of the self-contact stage (core/collision/thick.hpp), which must
never let one happen; and the distances from vertices to the triangles not touching them,
which that stage keeps at least its thickness."""

from __future__ import annotations

import numpy as np


def _cells(lo: np.ndarray, hi: np.ndarray, size: float) -> tuple[np.ndarray, np.ndarray]:
    """(owner, cell key) of every grid cell each box [lo, hi] (K, 3) covers; the boxes are
    given from a common origin (lo >= 0), so that every caller's keys name the same cells."""
    a = np.floor(lo / size).astype(np.int64)
    b = np.floor(hi / size).astype(np.int64)
    span = b - a + 1
    count = span.prod(axis=1)
    owner = np.repeat(np.arange(len(lo)), count)
    k = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    sy, sz = span[owner, 1], span[owner, 2]
    cell = a[owner] + np.stack([k // (sy * sz), (k // sz) % sy, k % sz], axis=1)
    key = (cell[:, 0] * (1 << 21) + cell[:, 1]) * (1 << 21) + cell[:, 2]
    return owner, key


def candidate_pairs(elo, ehi, tlo, thi) -> tuple[np.ndarray, np.ndarray]:
    """Every (edge, triangle) pair whose boxes meet, once (shapes (K,), (K,))."""
    size = max(float(np.median(np.max(ehi - elo, axis=1))), 1e-300)
    lo = np.minimum(elo.min(axis=0), tlo.min(axis=0))
    e_owner, e_key = _cells(elo - lo, ehi - lo, size)
    t_owner, t_key = _cells(tlo - lo, thi - lo, size)
    # join on the cell key: each edge cell against the triangle cells of the same key
    order = np.argsort(t_key, kind="stable")
    t_key, t_owner = t_key[order], t_owner[order]
    first = np.searchsorted(t_key, e_key, side="left")
    last = np.searchsorted(t_key, e_key, side="right")
    n = last - first
    e = np.repeat(e_owner, n)
    t = t_owner[np.repeat(first, n) + np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)]
    pairs = np.sort(e * len(tlo) + t)  # each pair once (a sort: no hash table)
    pairs = pairs[np.concatenate([[True], pairs[1:] != pairs[:-1]])[: len(pairs)]]
    e, t = pairs // len(tlo), pairs % len(tlo)
    meet = np.all((elo[e] <= thi[t]) & (tlo[t] <= ehi[e]), axis=1)
    return e[meet], t[meet]


def edge_crossings(q: np.ndarray, tri: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Pairs (edge, triangle) of non-adjacent elements (no shared vertex) where the segment
    q[e0]-q[e1] passes through the inside of the triangle: the ends strictly on opposite
    sides of the triangle's plane and the crossing point strictly inside (signed sub-areas
    along the normal all > 0), over every edge-triangle pair whose boxes meet. Shape (K, 2)."""
    if not len(edges) or not len(tri):
        return np.zeros((0, 2), np.int64)
    a, b = q[edges[:, 0]], q[edges[:, 1]]
    p0, p1, p2 = q[tri[:, 0]], q[tri[:, 1]], q[tri[:, 2]]
    elo, ehi = np.minimum(a, b), np.maximum(a, b)
    tlo, thi = np.minimum(np.minimum(p0, p1), p2), np.maximum(np.maximum(p0, p1), p2)
    ei, ti = candidate_pairs(elo, ehi, tlo, thi)
    apart = ~np.any(tri[ti][:, :, None] == edges[ei][:, None, :], axis=(1, 2))
    ei, ti = ei[apart], ti[apart]
    n = np.cross(p1[ti] - p0[ti], p2[ti] - p0[ti])
    da = np.einsum("ij,ij->i", a[ei] - p0[ti], n)
    db = np.einsum("ij,ij->i", b[ei] - p0[ti], n)
    straddle = da * db < 0
    s = da / np.where(straddle, da - db, 1.0)
    x = a[ei] + s[:, None] * (b[ei] - a[ei])
    w0 = np.einsum("ij,ij->i", np.cross(p1[ti] - x, p2[ti] - x), n)
    w1 = np.einsum("ij,ij->i", np.cross(p2[ti] - x, p0[ti] - x), n)
    w2 = np.einsum("ij,ij->i", np.cross(p0[ti] - x, p1[ti] - x), n)
    inside = straddle & (w0 > 0) & (w1 > 0) & (w2 > 0)
    return np.stack([ei[inside], ti[inside]], axis=1).astype(np.int64)


def _segment_distances(x: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from each point x (K, 3) to the segment a-b (K, 3 each), shape (K,)."""
    d = b - a
    dd = np.einsum("ij,ij->i", d, d)
    t = np.clip(np.einsum("ij,ij->i", x - a, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    return np.linalg.norm(x - (a + t[:, None] * d), axis=1)


def point_triangle_distances(
    x: np.ndarray, p0: np.ndarray, p1: np.ndarray, p2: np.ndarray
) -> np.ndarray:
    """Distance [m] from each point x (K, 3) to the triangle (p0, p1, p2) (K, 3 each):
    to its plane where the point's projection falls inside it (barycentric weights all
    >= 0), else to the nearest of its three edges. Shape (K,)."""
    n = np.cross(p1 - p0, p2 - p0)
    nn = np.einsum("ij,ij->i", n, n)
    flat = nn > 0
    h = np.einsum("ij,ij->i", x - p0, n) / np.where(flat, nn, 1.0)
    y = x - h[:, None] * n  # the projection on the plane
    sides = ((p1, p2), (p2, p0), (p0, p1))
    w = [np.einsum("ij,ij->i", np.cross(u - y, v - y), n) for u, v in sides]
    inside = flat & (w[0] >= 0) & (w[1] >= 0) & (w[2] >= 0)
    edges = np.minimum(
        np.minimum(_segment_distances(x, p0, p1), _segment_distances(x, p1, p2)),
        _segment_distances(x, p2, p0),
    )
    return np.where(inside, np.abs(h) * np.sqrt(nn), edges)


def vertex_triangle_gaps(
    q: np.ndarray, tri: np.ndarray, vertices: np.ndarray | None = None, *, radius: float
) -> np.ndarray:
    """For each vertex, the distance [m] to the nearest triangle of ``tri`` (M, 3) that does
    not have it as a corner, among the triangles within ``radius`` [m] of it (np.inf where
    none is): how far a surface with a thickness holds its sheets apart (the contact stage
    keeps every such pair at least its thickness h apart). q (N, 3) the positions;
    ``vertices`` (K,) the vertices to measure (default all N). Shape (K,)."""
    vertices = np.arange(len(q)) if vertices is None else np.asarray(vertices, dtype=np.int64)
    out = np.full(len(vertices), np.inf)
    if not len(vertices) or not len(tri):
        return out
    x = q[vertices]
    p0, p1, p2 = q[tri[:, 0]], q[tri[:, 1]], q[tri[:, 2]]
    tlo, thi = np.minimum(np.minimum(p0, p1), p2), np.maximum(np.maximum(p0, p1), p2)
    vi, ti = candidate_pairs(x - radius, x + radius, tlo, thi)
    apart = ~np.any(tri[ti] == vertices[vi][:, None], axis=1)
    vi, ti = vi[apart], ti[apart]
    d = point_triangle_distances(x[vi], p0[ti], p1[ti], p2[ti])
    near = d <= radius
    np.minimum.at(out, vi[near], d[near])
    return out
