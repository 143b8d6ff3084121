"""Forces given from outside the simulation, per particle and per step (``Control``)."""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def eval_external_forces(particle_f, f):
    """Add ``particle_f`` (N, 3) [N] to the accumulator ``f`` (N, 3)."""
    for i in range(f.shape[0]):
        f[i, 0] += particle_f[i, 0]
        f[i, 1] += particle_f[i, 1]
        f[i, 2] += particle_f[i, 2]
