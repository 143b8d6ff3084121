"""One step of each scheme for y' = (qd, f(q, qd, t) / m).

Every scheme receives the forces at the start of the step already in ``w.f`` (the loop
evaluates them first so it can check the state), and the start state saved in ``w.q0``,
``w.v0``. Pinned particles have inverse mass 0 and so no acceleration.
"""

from __future__ import annotations

from numba import njit

from softbody.forces.evaluate import eval_forces


@njit(cache=True)
def _stage(q0, v0, h, slope_q, f, inv_mass, q_out, v_out):
    """q_out = q0 + h slope_q; v_out = v0 + h f / m (element-wise safe if slope_q is v_out)."""
    for i in range(q0.shape[0]):
        w = h * inv_mass[i]
        for k in range(3):
            sq = slope_q[i, k]
            q_out[i, k] = q0[i, k] + h * sq
            v_out[i, k] = v0[i, k] + w * f[i, k]


@njit(cache=True)
def step_euler(m, c, t, dt, q, qd, w):
    """Explicit Euler: q += dt v, v += dt a (first order)."""
    _stage(w.q0, w.v0, dt, w.v0, w.f, m.particle_inv_mass, q, qd)


@njit(cache=True)
def step_midpoint(m, c, t, dt, q, qd, w):
    """Explicit midpoint (RK2, the paper's choice): slopes at the half step (second order)."""
    _stage(w.q0, w.v0, 0.5 * dt, w.v0, w.f, m.particle_inv_mass, w.qs, w.vs)
    eval_forces(m, c, t + 0.5 * dt, w.qs, w.vs, w, w.f)
    _stage(w.q0, w.v0, dt, w.vs, w.f, m.particle_inv_mass, q, qd)


@njit(cache=True)
def _accumulate(weight, vs, f, inv_mass, acc_q, acc_v):
    for i in range(vs.shape[0]):
        wm = weight * inv_mass[i]
        for k in range(3):
            acc_q[i, k] += weight * vs[i, k]
            acc_v[i, k] += wm * f[i, k]


@njit(cache=True)
def step_rk4(m, c, t, dt, q, qd, w):
    """Classical fourth-order Runge-Kutta."""
    inv_mass = m.particle_inv_mass
    acc_q, acc_v = w.acc_q, w.acc_v
    acc_q[:] = 0.0
    acc_v[:] = 0.0
    _accumulate(1.0, w.v0, w.f, inv_mass, acc_q, acc_v)
    _stage(w.q0, w.v0, 0.5 * dt, w.v0, w.f, inv_mass, w.qs, w.vs)
    eval_forces(m, c, t + 0.5 * dt, w.qs, w.vs, w, w.f)
    _accumulate(2.0, w.vs, w.f, inv_mass, acc_q, acc_v)
    _stage(w.q0, w.v0, 0.5 * dt, w.vs, w.f, inv_mass, w.qs, w.vs)
    eval_forces(m, c, t + 0.5 * dt, w.qs, w.vs, w, w.f)
    _accumulate(2.0, w.vs, w.f, inv_mass, acc_q, acc_v)
    _stage(w.q0, w.v0, dt, w.vs, w.f, inv_mass, w.qs, w.vs)
    eval_forces(m, c, t + dt, w.qs, w.vs, w, w.f)
    _accumulate(1.0, w.vs, w.f, inv_mass, acc_q, acc_v)
    h = dt / 6.0
    for i in range(q.shape[0]):
        for k in range(3):
            q[i, k] = w.q0[i, k] + h * acc_q[i, k]
            qd[i, k] = w.v0[i, k] + h * acc_v[i, k]


@njit(cache=True)
def step_symplectic_euler(m, c, t, dt, q, qd, w):
    """Semi-implicit (symplectic) Euler: v += dt a(q, v), then q += dt v_new."""
    inv_mass = m.particle_inv_mass
    for i in range(q.shape[0]):
        h = dt * inv_mass[i]
        for k in range(3):
            v = w.v0[i, k] + h * w.f[i, k]
            qd[i, k] = v
            q[i, k] = w.q0[i, k] + dt * v


@njit(cache=True)
def step_velocity_verlet(m, c, t, dt, q, qd, w):
    """Velocity Verlet: half kick, drift, forces at the new positions, half kick.

    The closing force evaluation uses the half-step velocity for damping terms, so the
    scheme is exactly symplectic only without velocity-dependent forces.
    """
    inv_mass = m.particle_inv_mass
    for i in range(q.shape[0]):
        h = 0.5 * dt * inv_mass[i]
        for k in range(3):
            v = w.v0[i, k] + h * w.f[i, k]
            w.vs[i, k] = v
            q[i, k] = w.q0[i, k] + dt * v
    eval_forces(m, c, t + dt, q, w.vs, w, w.f)
    for i in range(q.shape[0]):
        h = 0.5 * dt * inv_mass[i]
        for k in range(3):
            qd[i, k] = w.vs[i, k] + h * w.f[i, k]
