"""The pressure force (paper, section 2.2): F = (P - P_ambient) A n on every face.

Each face's force is shared equally by its three corners: (P - P_a) n_t / 6 with
n_t = (b - a) x (c - a) the outward normal times twice the area. Summed over the faces
around a vertex this is exactly (P - P_a) dV/dx_i, so the volume pass accumulates dV/dx
once and this kernel only scales it: with the exact volume the pressure force is the
gradient of the gas energy (conservative), with zero net force and zero net torque. With
a bounding volume, P comes from that volume but the force still acts through the faces,
as in the paper.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def eval_pressure_forces(
    body_particle_range, body_pressure, body_ambient_pressure, volume_gradient, f
):
    """Accumulate f_i += (P_b - P_ambient,b) dV/dx_i into ``f`` (N, 3) [N].

    body_particle_range (B, 2); body_pressure, body_ambient_pressure (B,) [Pa];
    volume_gradient (N, 3) [m^2] from the volume pass.
    """
    for b in range(body_particle_range.shape[0]):
        p = body_pressure[b] - body_ambient_pressure[b]
        for i in range(body_particle_range[b, 0], body_particle_range[b, 1]):
            f[i, 0] += p * volume_gradient[i, 0]
            f[i, 1] += p * volume_gradient[i, 1]
            f[i, 2] += p * volume_gradient[i, 2]


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
