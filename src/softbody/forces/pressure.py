"""The pressure force (paper, section 2.2): F = (P - P_ambient) A n on every face.

Each face's force is shared equally by its three corners: f = (P - P_a) n_t / 6 with
n_t = (b - a) x (c - a) the outward normal times twice the area. On a closed mesh the sum
over the faces around a vertex equals (P - P_a) dV/dx_i exactly, so with the exact volume
the pressure force is the gradient of the gas energy (conservative), and it has zero net
force and zero net torque.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def eval_pressure_forces(
    tri_indices, body_tri_range, body_pressure, body_ambient_pressure, tri_normal, f
):
    """Accumulate pressure forces into ``f`` (N, 3) [N].

    tri_indices (T, 3); body_tri_range (B, 2); body_pressure, body_ambient_pressure (B,) [Pa];
    tri_normal (T, 3) scaled normals [m^2] from the volume pass.
    """
    for b in range(body_tri_range.shape[0]):
        p = (body_pressure[b] - body_ambient_pressure[b]) / 6.0
        for t in range(body_tri_range[b, 0], body_tri_range[b, 1]):
            fx, fy, fz = p * tri_normal[t, 0], p * tri_normal[t, 1], p * tri_normal[t, 2]
            for c in range(3):
                i = tri_indices[t, c]
                f[i, 0] += fx
                f[i, 1] += fy
                f[i, 2] += fz


def pressure_forces_reference(q: np.ndarray, faces: np.ndarray, pressure: float) -> np.ndarray:
    """Readable NumPy version for one body: P * area * unit normal / 3 per corner, (N, 3) [N]."""
    a, b, c = q[faces[:, 0]], q[faces[:, 1]], q[faces[:, 2]]
    n = np.cross(b - a, c - a)
    area = 0.5 * np.linalg.norm(n, axis=1, keepdims=True)
    face_force = pressure * area * n / np.maximum(2.0 * area, 1e-300)
    f = np.zeros_like(q)
    for k in range(3):
        np.add.at(f, faces[:, k], face_force / 3.0)
    return f
