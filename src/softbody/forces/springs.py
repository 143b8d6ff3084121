"""Damped Hooke springs between particles, and from particles to fixed anchor points.

For a spring from i to j with direction u = (x_j - x_i) / L, the force on i is
    f_i = [k (L - L0) + c (v_j - v_i) . u] u,   f_j = -f_i,
the elastic part of which is -dE/dx_i for E = 1/2 k (L - L0)^2. Equal and opposite forces
along the line of centres conserve linear and angular momentum.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, inline="always")
def _spring_force(
    q, qd, s, spring_indices, spring_rest_length, spring_stiffness, spring_damping, f
):
    """Add spring ``s``'s damped force to the rows of its two ends in ``f``."""
    i, j = spring_indices[s, 0], spring_indices[s, 1]
    dx, dy, dz = q[j, 0] - q[i, 0], q[j, 1] - q[i, 1], q[j, 2] - q[i, 2]
    length = np.sqrt(dx * dx + dy * dy + dz * dz)
    if length == 0.0:
        return  # direction undefined; the force is a saddle point here
    inv = 1.0 / length
    ux, uy, uz = dx * inv, dy * inv, dz * inv
    rel = (qd[j, 0] - qd[i, 0]) * ux + (qd[j, 1] - qd[i, 1]) * uy + (qd[j, 2] - qd[i, 2]) * uz
    mag = spring_stiffness[s] * (length - spring_rest_length[s]) + spring_damping[s] * rel
    f[i, 0] += mag * ux
    f[i, 1] += mag * uy
    f[i, 2] += mag * uz
    f[j, 0] -= mag * ux
    f[j, 1] -= mag * uy
    f[j, 2] -= mag * uz


@njit(cache=True)
def eval_spring_forces(
    q, qd, spring_indices, spring_rest_length, spring_stiffness, spring_damping, f
):
    """Accumulate damped spring forces into ``f``.

    q, qd : (N, 3) positions [m] and velocities [m/s]; spring_indices : (S, 2);
    spring_rest_length (S,) [m], spring_stiffness (S,) [N/m], spring_damping (S,) [N s/m];
    f : (N, 3) accumulated [N].
    """
    for s in range(spring_indices.shape[0]):
        _spring_force(
            q, qd, s, spring_indices, spring_rest_length, spring_stiffness, spring_damping, f
        )


@njit(cache=True, parallel=True)
def eval_spring_forces_threaded(
    q,
    qd,
    spring_start,
    spring_indices,
    spring_rest_length,
    spring_stiffness,
    spring_damping,
    f,
):
    """``eval_spring_forces`` on threads, for springs in chunk order
    (``softbody.partition``; spring_start (T + 2,)): one chunk per thread, then the
    springs that cross chunks serially. No two threads write the same row of ``f``, so
    the sum is the same in every run."""
    chunk_count = spring_start.shape[0] - 2
    for c in prange(chunk_count):
        for s in range(spring_start[c], spring_start[c + 1]):
            _spring_force(
                q, qd, s, spring_indices, spring_rest_length, spring_stiffness, spring_damping, f
            )
    for s in range(spring_start[chunk_count], spring_start[chunk_count + 1]):
        _spring_force(
            q, qd, s, spring_indices, spring_rest_length, spring_stiffness, spring_damping, f
        )


@njit(cache=True)
def eval_attachment_forces(
    q,
    qd,
    attachment_particle,
    attachment_anchor,
    attachment_rest_length,
    attachment_stiffness,
    attachment_damping,
    f,
):
    """Accumulate forces of damped springs tying particles to fixed anchor points.

    attachment_particle (A,); attachment_anchor (A, 3) [m]; rest length (A,) [m];
    stiffness (A,) [N/m]; damping (A,) [N s/m]. The anchor does not move during a step.
    """
    for a in range(attachment_particle.shape[0]):
        i = attachment_particle[a]
        dx = attachment_anchor[a, 0] - q[i, 0]
        dy = attachment_anchor[a, 1] - q[i, 1]
        dz = attachment_anchor[a, 2] - q[i, 2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        if length == 0.0:
            continue
        inv = 1.0 / length
        ux, uy, uz = dx * inv, dy * inv, dz * inv
        rel = -(qd[i, 0] * ux + qd[i, 1] * uy + qd[i, 2] * uz)
        mag = (
            attachment_stiffness[a] * (length - attachment_rest_length[a])
            + attachment_damping[a] * rel
        )
        f[i, 0] += mag * ux
        f[i, 1] += mag * uy
        f[i, 2] += mag * uz


def spring_energy(
    q: np.ndarray, indices: np.ndarray, rest_length: np.ndarray, stiffness: np.ndarray
) -> np.ndarray:
    """Elastic energy 1/2 k (L - L0)^2 of each spring [J], shape (S,). NumPy reference."""
    length = np.linalg.norm(q[indices[:, 1]] - q[indices[:, 0]], axis=1)
    return 0.5 * stiffness * (length - rest_length) ** 2


def attachment_energy(
    q: np.ndarray,
    particle: np.ndarray,
    anchor: np.ndarray,
    rest_length: np.ndarray,
    stiffness: np.ndarray,
) -> np.ndarray:
    """Elastic energy of each attachment spring [J], shape (A,)."""
    length = np.linalg.norm(anchor - q[particle], axis=1)
    return 0.5 * stiffness * (length - rest_length) ** 2
