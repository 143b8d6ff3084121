"""Body volume: exact (divergence theorem), the paper's bounding objects, and Monte Carlo.

The methods are computed by the compiled core (core/terms/volume.hpp); a NumPy version
of each is in :mod:`softbody.reference.volume`.

* ``exact``: V = 1/6 sum_t (a_t - r) . ((b_t - a_t) x (c_t - a_t)) over the body's
  triangles, relative to a point r of the body (its first vertex), so the terms are of
  the body's size and round-off stays small far from the origin (a sum about the origin
  loses digits in proportion to distance / size). Its gradient is exactly the sum of
  n_t / 6 over the faces at a vertex, the area-weighted normals the pressure force uses,
  which is what makes the pressure force conservative.
* ``bounding_box``: volume of the axis-aligned bounding box (paper, section 3.1).
* ``bounding_sphere``: sphere centred on the bounding-box centre, radius the largest vertex
  distance from it.
* ``bounding_ellipsoid``: axis-aligned ellipsoid centred on the bounding-box centre with the
  box's aspect ratio, scaled just enough to contain every vertex: V = 4/3 pi rx ry rz
  (the paper's equation 6). For a sphere mesh it is the sphere.
* ``monte_carlo``: the paper's future work. A fixed, seeded set of vertical lines through
  the bounding box's xz rectangle; along each, the length inside the body is the sum over
  crossed triangles of sign(n_y) * y (exits minus entries, no sorting needed), and
  V = area_xz * mean length. Unbiased, repeatable, O(samples x triangles).
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np


class VolumeMethod(IntEnum):
    """How a body's volume is measured each step."""

    EXACT = 0
    BOUNDING_BOX = 1
    BOUNDING_SPHERE = 2
    BOUNDING_ELLIPSOID = 3
    MONTE_CARLO = 4

    @classmethod
    def parse(cls, value: str | int | VolumeMethod) -> VolumeMethod:
        """Accept an enum, its int value or its lowercase name (``"bounding_sphere"``)."""
        if isinstance(value, cls):
            return value
        if isinstance(value, str):
            key = value.strip().lower().replace("-", "_")
            for member in cls:
                if member.name.lower() == key:
                    return member
        elif isinstance(value, int | np.integer) and int(value) in {m.value for m in cls}:
            return cls(int(value))
        names = ", ".join(m.name.lower() for m in cls)
        raise ValueError(f"unknown volume method {value!r}; choose one of: {names}")
