"""Edges that pass through triangles: an independent NumPy check of a surface (brute force
over every edge-triangle pair whose boxes meet), for tests and benchmarks of the
self-contact stage (core/collision/thick.hpp), which must never let one happen."""

from __future__ import annotations

import numpy as np


def edge_crossings(q: np.ndarray, tri: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Pairs (edge, triangle) of non-adjacent elements (no shared vertex) where the segment
    q[e0]-q[e1] passes through the inside of the triangle: the ends strictly on opposite
    sides of the triangle's plane and the crossing point strictly inside (signed sub-areas
    along the normal all > 0), over every edge-triangle pair whose boxes meet (brute force
    in NumPy, in chunks of edges). Shape (K, 2)."""
    a, b = q[edges[:, 0]], q[edges[:, 1]]
    p0, p1, p2 = q[tri[:, 0]], q[tri[:, 1]], q[tri[:, 2]]
    elo, ehi = np.minimum(a, b), np.maximum(a, b)
    tlo, thi = np.minimum(np.minimum(p0, p1), p2), np.maximum(np.maximum(p0, p1), p2)
    normal = np.cross(p1 - p0, p2 - p0)
    found = []
    for c in range(0, len(edges), 64):
        e = np.arange(c, min(c + 64, len(edges)))
        near = np.all((elo[e, None] <= thi[None]) & (tlo[None] <= ehi[e, None]), axis=2)
        near &= ~np.any(tri[None, :, :, None] == edges[e][:, None, None, :], axis=(2, 3))
        ei, ti = np.nonzero(near)
        ei = e[ei]
        n = normal[ti]
        da = np.einsum("ij,ij->i", a[ei] - p0[ti], n)
        db = np.einsum("ij,ij->i", b[ei] - p0[ti], n)
        straddle = da * db < 0
        s = da / np.where(straddle, da - db, 1.0)
        x = a[ei] + s[:, None] * (b[ei] - a[ei])
        w0 = np.einsum("ij,ij->i", np.cross(p1[ti] - x, p2[ti] - x), n)
        w1 = np.einsum("ij,ij->i", np.cross(p2[ti] - x, p0[ti] - x), n)
        w2 = np.einsum("ij,ij->i", np.cross(p0[ti] - x, p1[ti] - x), n)
        inside = straddle & (w0 > 0) & (w1 > 0) & (w2 > 0)
        found.append(np.stack([ei[inside], ti[inside]], axis=1))
    return np.concatenate(found).astype(np.int64) if found else np.zeros((0, 2), np.int64)
