"""Forces given from outside the simulation, per particle and per step (``Control``)."""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def eval_grab_force(q, qd, particle, target, stiffness, damping, f):
    """A damped spring pulling one ``particle`` toward ``target`` (3,) [m] (a mouse
    grab): f += stiffness (target - x) - damping v. ``particle`` < 0 means none."""
    if particle < 0:
        return
    for k in range(3):
        f[particle, k] += stiffness * (target[k] - q[particle, k]) - damping * qd[particle, k]


@njit(cache=True)
def eval_external_forces(particle_f, f):
    """Add ``particle_f`` (N, 3) [N] to the accumulator ``f`` (N, 3)."""
    for i in range(f.shape[0]):
        f[i, 0] += particle_f[i, 0]
        f[i, 1] += particle_f[i, 1]
        f[i, 2] += particle_f[i, 2]
