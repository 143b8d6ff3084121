"""Connectivity derived from triangles: edges, half-edges, adjacent-triangle pairs."""

from __future__ import annotations

import numpy as np


def half_edges(faces: np.ndarray) -> np.ndarray:
    """Directed edges of every triangle, (3F, 2): row ``3f + k`` is corner k -> corner k+1."""
    f = np.asarray(faces, dtype=np.int64)
    return np.stack([f, np.roll(f, -1, axis=1)], axis=2).reshape(-1, 2)


def unique_edges(faces: np.ndarray) -> np.ndarray:
    """Undirected edges used by the triangles, (E, 2) int64, each row sorted, rows sorted."""
    he = np.sort(half_edges(faces), axis=1)
    return np.unique(he, axis=0)


def edge_half_edge_groups(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Group half-edges by undirected edge.

    Returns
    -------
    edges : (E, 2) int64
        Unique undirected edges, rows sorted.
    counts : (E,) int64
        How many half-edges (triangle sides) use each edge: 2 on a closed manifold.
    order : (3F,) int64
        Half-edge indices sorted by edge; edge e owns ``order[start[e]:start[e] + counts[e]]``
        with ``start = cumsum(counts) - counts``.
    """
    key = np.sort(half_edges(faces), axis=1)
    edges, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    order = np.argsort(inverse.reshape(-1), kind="stable")
    return edges, counts, order


def bending_pairs(faces: np.ndarray) -> np.ndarray:
    """Vertex pairs opposite each interior edge, (B, 2) int64.

    For an edge shared by triangles (a, b, c) and (b, a, d), the pair is (c, d): a spring
    between them resists folding the two triangles about the edge. Edges not shared by
    exactly two triangles give no pair. Pairs that coincide with a mesh edge (as in a
    tetrahedron) or repeat are dropped.
    """
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    edges, counts, order = edge_half_edge_groups(f)
    opposite = np.roll(f, -2, axis=1).reshape(-1)  # the corner opposite each half-edge
    start = np.cumsum(counts) - counts
    two = start[counts == 2]
    pairs = np.sort(np.stack([opposite[order[two]], opposite[order[two + 1]]], axis=1), axis=1)
    pairs = np.unique(pairs[pairs[:, 0] != pairs[:, 1]], axis=0)
    n = int(f.max()) + 1
    is_edge = np.isin(pairs[:, 0] * n + pairs[:, 1], edges[:, 0] * n + edges[:, 1])
    return pairs[~is_edge]


def vertex_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Barycentric vertex areas (a third of each adjacent triangle), (V,) [m^2]."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    out = np.zeros(len(v))
    np.add.at(out, f.reshape(-1), np.repeat(area / 3.0, 3))
    return out
