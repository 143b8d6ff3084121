"""Edges that pass through triangles: an independent NumPy check of a surface (every
edge-triangle pair whose boxes meet, found through a uniform grid, tested exactly), for
tests and benchmarks of the self-contact stage (core/collision/thick.hpp), which must
never let one happen."""

from __future__ import annotations

import numpy as np


def _cells(lo: np.ndarray, hi: np.ndarray, size: float) -> tuple[np.ndarray, np.ndarray]:
    """(owner, cell key) of every grid cell each box [lo, hi] (K, 3) covers; the boxes are
    given from one lower corner common to the edges and the triangles (one grid for both)."""
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
    pairs = pairs[np.concatenate([[True], pairs[1:] != pairs[:-1]])]
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
