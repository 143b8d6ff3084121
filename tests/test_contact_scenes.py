"""The contact scenes of issue 32 (``softbody run vacuum-gripper``, ``balloon-ring``,
``cloth-stair``) against what they claim, and the independent crossing check they use."""

from __future__ import annotations

import numpy as np

from softbody.collision.crossings import edge_crossings


def test_crossing_check_finds_an_edge_far_from_the_first_triangle():
    """Reference: a segment through the inside of a triangle crosses it (edge_crossings'
    contract), wherever the edges lie relative to the other triangles. The edges and the
    triangles were put on grids of their own, each shifted to its own lowest cell, so an
    edge set that did not start where the triangles did (here one edge at (5.2, y, 5.2),
    the triangles from the origin) was looked up in the wrong cells and its crossing
    missed."""
    q = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0, 0.1], [5, 0, 5], [6, 0, 5], [5, 0, 6],
                  [5.2, -0.5, 5.2], [5.2, 0.5, 5.2]], float)  # fmt: skip
    found = edge_crossings(q, np.array([[0, 1, 2], [3, 4, 5]]), np.array([[6, 7]]))
    assert found.tolist() == [[0, 1]]
