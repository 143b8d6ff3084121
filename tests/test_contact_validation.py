"""Issue 32's validations of surfaces with a thickness (core/collision/thick.hpp): cloth
dropped into a pile, two balloons pressed together, the contact force of a body resting on
a soft body, self-contact in every solver; and the independent checks they use
(softbody.collision.crossings)."""

from __future__ import annotations

import numpy as np
import pytest
from trimesh.triangles import closest_point

from softbody.collision.crossings import candidate_pairs, vertex_triangle_gaps


# -- the checks' own references ------------------------------------------------------------
def test_candidate_pairs_of_two_sets_of_boxes_of_different_extents():
    """candidate_pairs against a test of every pair: two seeded sets of boxes that do not
    start at the same grid cell (small boxes scattered over a wide range, large ones over a
    narrow one) give exactly the meeting pairs (their grid keys share one origin; each set
    shifted to its own first cell would miss pairs)."""
    rng = np.random.default_rng(11)
    a = rng.uniform(-3.0, 3.0, size=(300, 3))
    b = rng.uniform(0.5, 2.0, size=(80, 3))
    alo, ahi = a, a + rng.uniform(0.0, 0.3, size=a.shape)
    blo, bhi = b, b + rng.uniform(0.2, 1.0, size=b.shape)
    meet = np.all((alo[:, None] <= bhi[None]) & (blo[None] <= ahi[:, None]), axis=2)
    brute = set(zip(*np.nonzero(meet), strict=True))
    found = set(zip(*(x.tolist() for x in candidate_pairs(alo, ahi, blo, bhi)), strict=True))
    assert len(brute) > 20
    assert found == brute


def test_vertex_triangle_gaps_against_trimesh():
    """vertex_triangle_gaps against trimesh's closest point on a triangle, taken over every
    triangle (no grid): on a seeded random soup, each vertex's distance to the nearest
    triangle not touching it, within the radius, agrees to round-off (inf where none is
    that near), for all vertices and for a subset measured against part of the soup."""
    rng = np.random.default_rng(3)
    q = rng.normal(size=(200, 3))
    tri = rng.integers(0, 200, size=(150, 3))
    tri = tri[(tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])]
    radius = 0.8
    for vertices, part in ((np.arange(200), tri), (np.arange(50, 120), tri[:60])):
        expected = np.full(len(vertices), np.inf)
        for k, v in enumerate(vertices):
            others = part[~np.any(part == v, axis=1)]
            d = np.linalg.norm(closest_point(q[others], np.repeat(q[v][None], len(others), 0))
                               - q[v], axis=1)  # fmt: skip
            d = d[d <= radius]
            expected[k] = d.min() if len(d) else np.inf
        got = vertex_triangle_gaps(q, part, vertices, radius=radius)
        assert np.isfinite(expected).sum() > 0.5 * len(vertices)
        assert np.array_equal(np.isfinite(got), np.isfinite(expected))
        assert np.allclose(got[np.isfinite(got)], expected[np.isfinite(expected)], atol=1e-12)
