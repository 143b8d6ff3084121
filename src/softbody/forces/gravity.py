"""Uniform gravity."""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def eval_gravity(particle_mass, gravity, f):
    """Set f_i = m_i g: the first term of the force accumulator (it overwrites ``f``).

    particle_mass : (N,) [kg]; gravity : (3,) [m/s^2]; f : (N, 3) output [N].
    """
    gx, gy, gz = gravity[0], gravity[1], gravity[2]
    for i in range(particle_mass.shape[0]):
        m = particle_mass[i]
        f[i, 0] = m * gx
        f[i, 1] = m * gy
        f[i, 2] = m * gz
