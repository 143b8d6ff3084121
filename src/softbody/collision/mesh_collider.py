"""What a mesh collider holds for the core (``core/collision/mesh.hpp``): its closed
triangle mesh in the collider's local frame, the angle-weighted pseudo-normals of its
vertices and edges (Baerentzen & Aanaes 2005, the inside test at the closest feature), and
a bounding-volume tree over its triangles, built once here.

The tree is a binary tree of axis-aligned boxes: a node's triangles are split at the
median of their centroids along the longest axis of the centroids' box, down to leaves of
at most ``LEAF_SIZE`` triangles. Nodes are numbered in depth-first order (a node's children
come after it) and each leaf's triangles are contiguous rows of the reordered triangles.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from softbody.mesh.topology import half_edges
from softbody.mesh.tri_mesh import TriMesh

#: Most triangles in one leaf of the tree.
LEAF_SIZE = 4

#: Default angle [deg] between the normals of an edge's two faces above which a convex mesh
#: edge is sharp: it takes part in edge contacts (a 12-triangle box's edges: 90; a 5,000-
#: triangle sphere's: about 4).
SHARP_ANGLE = 30.0

#: ``sharp_edges``' mark of an edge that is bent but not sharp: it takes part in the edge
#: contacts' test of collider edges through soft triangles, not in the edge-edge push.
BENT = -2

#: Smallest angle [rad] between an edge's two faces' normals for which it is bent: flatter
#: edges (a flat face's tessellation, to round-off) cannot reach through a soft triangle.
BENT_ANGLE = 1e-6

#: Default margin [m] as a fraction of the mesh's bounding-box diagonal: how far outside
#: the surface a caught particle is put, so that its next path starts strictly outside.
MARGIN_FRACTION = 1e-4


@dataclass(frozen=True, eq=False)
class MeshColliderData:
    """A mesh collider's arrays, in its local frame (origin at ``center``).

    V vertices, T triangles, K tree nodes; node 0 is the root."""

    center: np.ndarray
    """Centre of the mesh's bounding box in the input's coordinates [m], (3,)."""
    half_extents: np.ndarray
    """Half-extents of the mesh's bounding box [m], (3,)."""
    vertices: np.ndarray
    """Vertex positions relative to ``center`` [m], (V, 3)."""
    triangles: np.ndarray
    """Outward-wound vertex indices, in the order of the tree's leaves, (T, 3) int64."""
    vertex_normals: np.ndarray
    """Angle-weighted unit pseudo-normals of the vertices, (V, 3)."""
    edge_normals: np.ndarray
    """Unit pseudo-normal of edge k (corner k to k + 1) of each triangle, (T, 3, 3)."""
    sharp_edges: np.ndarray
    """How edge k of each triangle takes part in edge contacts, listed by the triangle that
    owns it (its first vertex index below its second; see :func:`sharp_edges`): the triangle
    across it where the edge is sharp (convex, its faces' normals more than ``sharp_angle``
    apart), BENT (-2) where it is bent (not flat) but not sharp, else -1; (T, 3) int64."""
    node_children: np.ndarray
    """Child nodes of each inner node, (K, 2) int64; (0, 0) for a leaf."""
    node_tris: np.ndarray
    """[begin, end) triangles of each leaf, (K, 2) int64; empty for an inner node."""
    node_bounds: np.ndarray
    """Lower and upper corner of each node's box [m], (K, 2, 3)."""
    node_sharp: np.ndarray
    """1 where a node's triangles hold an edge that takes part in edge contacts (sharp or
    bent: ``sharp_edges`` != -1), else 0; (K,) int64: the edge contacts do not enter a
    subtree without one, and do nothing on a mesh whose root is 0 (edge contacts off)."""


def _source_name(mesh: Any) -> str:
    return str(mesh) if isinstance(mesh, str | os.PathLike) else "mesh"


def checked_mesh(mesh: Any) -> tuple[TriMesh, str]:
    """The closed, outward-wound, non-self-intersecting TriMesh of ``mesh`` (a TriMesh, a
    ``trimesh.Trimesh`` or a path the project's loader reads) and the name it goes by (the
    path, or "mesh"). Raises ValueError (a one-line message naming it) otherwise."""
    from softbody.errors import MeshError
    from softbody.mesh.io import read_mesh
    from softbody.mesh.validate import inspect_mesh

    name = _source_name(mesh)
    if isinstance(mesh, str | os.PathLike):
        tri = read_mesh(mesh)  # a MeshError (ValueError) naming the file
    elif isinstance(mesh, TriMesh):
        tri = mesh
    elif hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
        try:
            tri = TriMesh(np.asarray(mesh.vertices), np.asarray(mesh.faces))
        except MeshError as exc:
            raise MeshError(f"{name}: {exc}") from None
    else:
        raise TypeError(
            f"ColliderMesh needs a TriMesh, a trimesh.Trimesh or a mesh file path, "
            f"got {type(mesh).__name__}"
        )
    report = inspect_mesh(tri, self_intersections=True)
    problems = report.problems
    if problems:
        reasons = "; ".join(p.replace("; add each closed piece as its own body", "; use one "
                                      "collider per closed piece") for p in problems)  # fmt: skip
        raise MeshError(f"{name}: a mesh collider must be one closed surface: {reasons}")
    if report.self_intersection_count:
        a, b = report.intersecting_pairs[0]
        raise MeshError(
            f"{name}: a mesh collider must not cross itself: {report.self_intersection_count} "
            f"pairs of triangles cross (e.g. triangles {a} and {b})"
        )
    return report.mesh, name


def _unit(a: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(a, axis=-1, keepdims=True)
    return a / np.where(n > 0, n, 1.0)


def pseudo_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Angle-weighted vertex normals (V, 3) and edge normals (T, 3, 3) of a closed,
    consistently wound mesh: edge k of triangle t (corner k to k + 1) has the unit mean of
    its two triangles' normals."""
    p = vertices[faces]  # (T, 3, 3)
    face_n = _unit(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]))
    vertex_n = np.zeros_like(vertices)
    for k in range(3):
        e1 = _unit(p[:, (k + 1) % 3] - p[:, k])
        e2 = _unit(p[:, (k + 2) % 3] - p[:, k])
        angle = np.arccos(np.clip(np.einsum("ij,ij->i", e1, e2), -1.0, 1.0))
        np.add.at(vertex_n, faces[:, k], angle[:, None] * face_n)
    he = half_edges(faces)  # row 3 t + k: corner k -> k + 1
    count = len(vertices)
    key = he[:, 0] * count + he[:, 1]
    twin_key = he[:, 1] * count + he[:, 0]
    order = np.argsort(key)
    twin = order[np.searchsorted(key[order], twin_key)]
    edge_n = _unit(face_n[np.arange(len(he)) // 3] + face_n[twin // 3]).reshape(-1, 3, 3)
    return _unit(vertex_n), edge_n


def sharp_edges(vertices: np.ndarray, faces: np.ndarray, angle: float | None) -> np.ndarray:
    """How the edges of a closed, outward-wound mesh take part in edge contacts: (T, 3)
    int64, for edge k (corner k to k + 1) of triangle t where t owns it (its first vertex
    index is below its second, so that each edge is listed once): the triangle across it
    where the edge is sharp (convex and its two faces' normals differ by more than ``angle``
    [deg]: the edge-edge push), :data:`BENT` where it is otherwise bent (its normals differ
    by more than :data:`BENT_ANGLE`: only the test of collider edges through soft
    triangles), else -1. ``angle`` None or 180 and above: the edge contacts off (-1
    everywhere)."""
    out = np.full((len(faces), 3), -1, np.int64)
    if angle is None or float(angle) >= 180.0 or len(faces) == 0:
        return out
    p = vertices[faces]
    face_n = _unit(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]))
    he = half_edges(faces)  # row 3 t + k: corner k -> k + 1
    count = len(vertices)
    key = he[:, 0] * count + he[:, 1]
    twin_key = he[:, 1] * count + he[:, 0]
    order = np.argsort(key)
    twin = order[np.searchsorted(key[order], twin_key)] // 3
    own = np.arange(len(he)) // 3
    n1, n2 = face_n[own], face_n[twin]
    cos = np.einsum("ij,ij->i", n1, n2)
    # convex: the edge runs along n1 x n2 (outward winding), i.e. the twin's far side is
    # behind this face
    direction = vertices[he[:, 1]] - vertices[he[:, 0]]
    convex = np.einsum("ij,ij->i", np.cross(n1, n2), direction) > 0.0
    owned = he[:, 0] < he[:, 1]
    bent = (cos < np.cos(BENT_ANGLE)) & owned
    sharp = (cos < np.cos(np.radians(float(angle)))) & convex & owned
    flat = out.reshape(-1)
    flat[bent] = BENT
    flat[sharp] = twin[sharp]
    return out


def sharp_nodes(children: np.ndarray, tris: np.ndarray, sharp: np.ndarray) -> np.ndarray:
    """(K,) int64: 1 where the triangles below tree node k (``build_tree``'s children and
    tris) hold an edge that takes part in edge contacts (``sharp`` (T, 3) != -1)."""
    has = np.zeros(len(children), np.int64)
    any_sharp = np.any(sharp != -1, axis=1)
    for node in range(len(children) - 1, -1, -1):  # children come after their parent
        b, e = tris[node]
        if e > b:
            has[node] = int(any_sharp[b:e].any())
        else:
            has[node] = has[children[node, 0]] | has[children[node, 1]]
    return has


def build_tree(vertices: np.ndarray, faces: np.ndarray):
    """Bounding-volume tree over ``faces``: (order (T,), children (K, 2), tris (K, 2),
    bounds (K, 2, 3)); ``faces[order]`` are the triangles in leaf order."""
    p = vertices[faces]
    lo_t, hi_t = p.min(axis=1), p.max(axis=1)
    centroid = p.mean(axis=1)
    children: list[list[int]] = []
    tris: list[list[int]] = []
    bounds: list[np.ndarray] = []
    order: list[np.ndarray] = []
    placed = 0
    stack: list[tuple[np.ndarray, int, int]] = [(np.arange(len(faces)), -1, 0)]
    while stack:
        ids, parent, side = stack.pop()
        node = len(children)
        children.append([0, 0])
        tris.append([0, 0])
        bounds.append(np.stack([lo_t[ids].min(axis=0), hi_t[ids].max(axis=0)]))
        if parent >= 0:
            children[parent][side] = node
        if len(ids) <= LEAF_SIZE:
            tris[node] = [placed, placed + len(ids)]
            order.append(ids)
            placed += len(ids)
            continue
        c = centroid[ids]
        axis = int(np.argmax(np.ptp(c, axis=0)))
        half = len(ids) // 2
        split = np.argpartition(c[:, axis], half)
        # the right child is pushed first: the left is built next, depth first
        stack.append((ids[split[half:]], node, 1))
        stack.append((ids[split[:half]], node, 0))
    return (
        np.concatenate(order).astype(np.int64),
        np.array(children, dtype=np.int64).reshape(-1, 2),
        np.array(tris, dtype=np.int64).reshape(-1, 2),
        np.array(bounds, dtype=np.float64).reshape(-1, 2, 3),
    )


def mesh_collider_data(mesh: TriMesh, sharp_angle: float | None = SHARP_ANGLE) -> MeshColliderData:
    """The arrays of a checked closed ``mesh`` (see :func:`checked_mesh`), in the local
    frame centred on its bounding box; edges sharper than ``sharp_angle`` [deg] take part in
    the edge-edge push of edge contacts, every bent edge in their test of collider edges
    through soft triangles (:func:`sharp_edges`; None: the edge contacts off)."""
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    center = 0.5 * (lo + hi)
    vertices = np.ascontiguousarray(mesh.vertices - center)
    order, children, tris, bounds = build_tree(vertices, mesh.faces)
    faces = np.ascontiguousarray(mesh.faces[order])
    vertex_n, edge_n = pseudo_normals(vertices, faces)
    sharp = sharp_edges(vertices, faces, sharp_angle)
    return MeshColliderData(
        center=center,
        half_extents=0.5 * (hi - lo),
        vertices=vertices,
        triangles=faces,
        vertex_normals=np.ascontiguousarray(vertex_n),
        edge_normals=np.ascontiguousarray(edge_n),
        sharp_edges=sharp,
        node_children=children,
        node_tris=tris,
        node_bounds=bounds,
        node_sharp=sharp_nodes(children, tris, sharp),
    )


def collider_mesh(model: Any, c: int) -> tuple[np.ndarray, np.ndarray]:
    """Mesh collider ``c`` of ``model`` in its local frame: vertices (V, 3) [m] and
    triangles (T, 3) indexing them (world = centre + vertices @ rotation.T)."""
    b, e = model.collider_mesh_range[c]
    tris = model.collider_mesh_triangles[b:e]
    lo, hi = int(tris.min()), int(tris.max()) + 1
    return model.collider_mesh_vertices[lo:hi], tris - lo


def inside_mesh(data: MeshColliderData, points: np.ndarray) -> np.ndarray:
    """Which of ``points`` (P, 3) [m, local frame] lie strictly inside the mesh, (P,) bool:
    by the parity of crossings of a ray from each point (an independent test of the core's
    pseudo-normal one; a ray through an edge or vertex is retried in another direction)."""
    p = data.vertices[data.triangles]
    a, e1, e2 = p[:, 0], p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    out = np.zeros(len(points), dtype=bool)
    rng = np.random.default_rng(7)
    for k, x in enumerate(np.asarray(points, dtype=np.float64)):
        for _ in range(8):
            d = _unit(rng.normal(size=3))
            h = np.cross(d, e2)
            det = np.einsum("ij,ij->i", e1, h)
            ok = np.abs(det) > 1e-14
            inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
            s = x - a
            u = inv * np.einsum("ij,ij->i", s, h)
            q = np.cross(s, e1)
            v = inv * (q @ d)
            t = inv * np.einsum("ij,ij->i", e2, q)
            near_edge = (
                ok
                & (t > 0)
                & ((np.abs(u) < 1e-9) | (np.abs(v) < 1e-9) | (np.abs(1 - u - v) < 1e-9))
            )
            if near_edge.any():
                continue  # ambiguous: another direction
            hits = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
            out[k] = bool(np.count_nonzero(hits) % 2)
            break
    return out
