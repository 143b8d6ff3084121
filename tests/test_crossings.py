"""softbody.collision.crossings: the independent edge-through-triangle check."""

from __future__ import annotations

import numpy as np

from softbody.collision.crossings import edge_crossings


def test_a_crossing_is_found_when_edges_reach_lower_grid_cells_than_the_triangles():
    """An edge through a triangle is found whatever else is in the check: here a second,
    short edge 6 m below makes the edges' grid start 30 cells below the triangles' (the
    grid must be one for both; each set's cells were once counted from its own lowest,
    so the pair fell in different cells and the crossing was missed). Reference: the edge
    (0.2, 0.9..1.1, 0.2) passes through the inside of the triangle in the plane y = 1."""
    q = np.array([
        [0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 1.0],  # the triangle, y = 1
        [0.2, 0.9, 0.2], [0.2, 1.1, 0.2],                   # through it
        [0.2, -5.0, 0.2], [0.2, -4.8, 0.2],                 # far below
    ])  # fmt: skip
    tri = np.array([[0, 1, 2]])
    edges = np.array([[3, 4], [5, 6]])
    np.testing.assert_array_equal(edge_crossings(q, tri, edges), [[0, 0]])
    # the far edge alone shares no grid cell with the triangle: no candidate pair, no
    # crossing (an empty candidate list once failed on indexing)
    assert edge_crossings(q, tri, edges[1:]).shape == (0, 2)
