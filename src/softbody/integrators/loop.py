"""The compiled time loop: many steps in one call, with blow-up detection after each."""

from __future__ import annotations

import numpy as np
from numba import njit

from softbody.collision.pose import eval_collider_poses
from softbody.collision.response import eval_collider_contacts
from softbody.collision.soft import eval_soft_contacts_bounding, eval_soft_contacts_surface
from softbody.forces.evaluate import eval_forces
from softbody.integrators.implicit import step_implicit
from softbody.integrators.projective import step_projective
from softbody.integrators.schemes import (
    step_euler,
    step_midpoint,
    step_rk4,
    step_symplectic_euler,
    step_velocity_verlet,
)
from softbody.volume import eval_model_volume_only

#: Status codes returned by :func:`simulate`.
OK = 0
NONFINITE = 1  # a particle position or velocity became NaN or infinite
RUNAWAY = 2  # a particle moved faster than the speed limit
BAD_VOLUME = 3  # a body volume became NaN, zero or negative (inverted)
SHRUNK = 4  # a body volume fell below the lower limit times its rest volume
EXPLODED = 5  # a body volume grew past the upper limit times its rest volume
NEED_HASH = 6  # the spatial hash needs more room (value: entries); the step was undone


@njit(cache=True)
def _check_volumes(body_volume, body_rest_volume, body_closed, ratio_min, ratio_max):
    for b in range(body_volume.shape[0]):
        if body_closed[b] == 0:
            continue  # an open surface encloses no volume
        v = body_volume[b]
        if not (np.isfinite(v) and v > 0.0):
            return BAD_VOLUME, b, v
        r = v / body_rest_volume[b]
        if r < ratio_min:
            return SHRUNK, b, r
        if r > ratio_max:
            return EXPLODED, b, r
    return OK, -1, 0.0


@njit(cache=True)
def _check_particles(q, qd, max_speed):
    limit = max_speed * max_speed
    for i in range(q.shape[0]):
        s = 0.0
        bad = False
        for k in range(3):
            if not (np.isfinite(q[i, k]) and np.isfinite(qd[i, k])):
                bad = True
            s += qd[i, k] * qd[i, k]
        if bad:
            return NONFINITE, i, np.nan
        if s > limit:
            return RUNAWAY, i, np.sqrt(s)
    return OK, -1, 0.0


@njit(cache=True)
def _copy_state(q, qd, q_out, qd_out):
    """q_out, qd_out = q, qd for (N, 3) arrays. An explicit loop: Numba's ``a[:] = b`` took
    2-4x longer for these at 40k particles."""
    for i in range(q.shape[0]):
        for k in range(3):
            q_out[i, k] = q[i, k]
            qd_out[i, k] = qd[i, k]


@njit(cache=True)
def same_values(a, b):
    """Whether two (N, 3) arrays hold the same values (no temporary arrays)."""
    for i in range(a.shape[0]):
        for k in range(3):
            if a[i, k] != b[i, k]:
                return False
    return True


@njit(cache=True)
def _contacts_acted(q, qd, q_before, qd_before):
    """Whether contacts moved a particle or changed its velocity this step. BDF2 then
    takes its next step as backward Euler. BDF2 reads x_n - x_n-1 and v_n - v_n-1 as
    motion, so it would carry a projection and a reflection on into the next step: a
    stiff ball dropped at 1/60 s bounced higher each time (1.2 m -> 2.5 m in 4 s). Giving
    only the touched particles a fresh history did not cure it (tried: uniform motion
    kept the gain, constant acceleration from the contact force made it explode)."""
    for i in range(q.shape[0]):
        for k in range(3):
            if q[i, k] != q_before[i, k] or qd[i, k] != qd_before[i, k]:
                return True
    return False


@njit(cache=True)
def eval_contacts(
    m, c, t, fraction, duration, q, qd, w, collider_q, collider_rot, collider_impulse
):
    """Collisions at the end of a step (paper step 5): soft-soft, then rigid colliders
    (last, so no particle ends a step inside a collider). Returns 0, or the spatial-hash
    capacity surface contacts need."""
    if m.collider_kind.shape[0] > 0:
        eval_collider_poses(
            m.collider_motion,
            m.collider_center,
            m.collider_rotation,
            m.collider_motion_vector,
            m.collider_motion_pivot,
            m.collider_motion_frequency,
            c.collider_target,
            fraction,
            duration,
            t,
            w.collider_q_start,
            collider_q,
            collider_rot,
            w.collider_v,
            w.collider_w,
            w.scratch,
        )
    if m.soft_contact_mode == 1:
        eval_soft_contacts_bounding(
            m.particle_mass,
            m.particle_inv_mass,
            m.body_particle_range,
            m.body_contact_shape,
            m.soft_contact_restitution,
            m.soft_contact_friction,
            q,
            qd,
            w.body_lo,
            w.body_hi,
            w.body_velocity,
            w.body_mass,
            w.body_center,
            w.body_axes,
            w.body_dv,
        )
    elif m.soft_contact_mode == 2:
        needed = eval_soft_contacts_surface(
            m.particle_mass,
            m.particle_inv_mass,
            m.particle_body,
            m.body_particle_range,
            m.tri_indices,
            m.tri_body,
            m.soft_contact_restitution,
            m.soft_contact_friction,
            m.contact_cell_size,
            m.contact_margin,
            q,
            qd,
            w.body_lo,
            w.body_hi,
            w.body_velocity,
            w.body_mass,
            w.hash_start,
            w.hash_count,
            w.hash_entries,
        )
        if needed > 0:
            return needed
    if m.collider_kind.shape[0] > 0:
        eval_collider_contacts(
            m.particle_mass,
            m.particle_inv_mass,
            m.collider_kind,
            m.collider_size,
            m.collider_restitution,
            m.collider_friction,
            collider_q,
            collider_rot,
            w.collider_v,
            w.collider_w,
            w.q0,
            q,
            qd,
            collider_impulse,
        )
    return 0


def simulate(
    integrator: int,
    steps: int,
    t0: float,
    dt: float,
    m,
    c,
    q,
    qd,
    w,
    max_speed: float,
    ratio_min: float,
    ratio_max: float,
    collider_q,
    collider_rot,
    collider_impulse,
    mg,
    cg_tolerance: float,
    cg_max_iterations: int,
    history: bool,
    pd,
    pd_iterations: int,
) -> tuple[int, int, int, float]:
    """Advance ``q``, ``qd`` (N, 3) in place by ``steps`` steps of ``dt`` [s] from ``t0``.

    integrator : int (``Integrator`` value). Returns (status, steps_done, index, value):
    status 0 when all steps ran; otherwise ``steps_done`` steps completed, ``index`` is
    the body or particle at fault and ``value`` the offending quantity. On a particle
    failure the state is restored to the start of the failing step; on a volume failure
    the state is the one whose volume failed (found before stepping from it).
    collider_q (C, 3), collider_rot (C, 3, 3) are the colliders' poses (updated each
    step); collider_impulse (C, 3) accumulates the impulse they receive. ``mg`` is implicit
    Euler's and BDF2's preconditioner (``integrators.multigrid``; an empty one means
    Jacobi); ``history`` is True when w.q_prev, w.v_prev hold the step before ``q``, ``qd``
    (BDF2). ``pd`` is projective dynamics' factored matrix (``integrators.projective``)
    and ``pd_iterations`` its local-global iterations per step.

    Each family of schemes has its own compiled loop (``simulate_explicit``,
    ``simulate_implicit``, ``simulate_projective``), so a run compiles only its own
    family's kernels: one loop over every scheme took 92 s to compile on an empty cache
    here, 23 s of it the implicit solver's (``benchmarks/startup.py``).
    """
    common = (steps, t0, dt, m, c, q, qd, w, max_speed, ratio_min, ratio_max)
    colliders = (collider_q, collider_rot, collider_impulse)
    if integrator <= 4:
        return simulate_explicit(integrator, *common, *colliders)
    if integrator == 7:
        return simulate_projective(*common, *colliders, pd, pd_iterations)
    return simulate_implicit(
        integrator == 6, *common, *colliders, mg, cg_tolerance, cg_max_iterations, history
    )


@njit(cache=True)
def _begin_run(steps, dt, m, c, q, qd, w, collider_q):
    """Before the first step: the colliders' start poses, and pinned particles' velocity
    to reach their targets at the end of the run."""
    for k in range(collider_q.shape[0]):
        for d in range(3):
            w.collider_q_start[k, d] = collider_q[k, d]
    if c.pin_active:
        inv = 1.0 / (steps * dt)
        for p in range(m.pin_particle.shape[0]):
            i = m.pin_particle[p]
            for k in range(3):
                qd[i, k] = (c.pin_target[p, k] - q[i, k]) * inv


@njit(cache=True)
def _start_step(m, c, t, q, qd, w, ratio_min, ratio_max):
    """At a step's start: the state kept in w.q0, w.v0, the forces at it into w.f (with
    the body volumes) and the volumes checked. Returns (status, index, value)."""
    _copy_state(q, qd, w.q0, w.v0)
    eval_forces(m, c, t, q, qd, w, w.f)
    return _check_volumes(w.body_volume, m.body_rest_volume, m.body_closed, ratio_min, ratio_max)


@njit(cache=True)
def _end_step(m, c, t, dt, s, steps, q, qd, w, max_speed, collider_q, collider_rot, impulse):
    """After a step from t to t + dt: contacts, then the particle checks; on a failure
    the state goes back to the step's start. Returns (status, index, value)."""
    needed = eval_contacts(
        m, c, t + dt, (s + 1.0) / steps, steps * dt, q, qd, w, collider_q, collider_rot, impulse
    )
    if needed > 0:
        _copy_state(w.q0, w.v0, q, qd)
        return NEED_HASH, -1, float(needed)
    status, index, value = _check_particles(q, qd, max_speed)
    if status != OK:
        _copy_state(w.q0, w.v0, q, qd)
    return status, index, value


@njit(cache=True)
def simulate_explicit(
    integrator, steps, t0, dt, m, c, q, qd, w, max_speed, ratio_min, ratio_max, cq, crot, ci
):
    """``simulate`` for the explicit schemes (``integrator`` 0-4)."""
    _begin_run(steps, dt, m, c, q, qd, w, cq)
    for s in range(steps):
        t = t0 + s * dt
        status, index, value = _start_step(m, c, t, q, qd, w, ratio_min, ratio_max)
        if status != OK:
            return status, s, index, value
        if integrator == 0:
            step_euler(m, c, t, dt, q, qd, w)
        elif integrator == 1:
            step_midpoint(m, c, t, dt, q, qd, w)
        elif integrator == 2:
            step_rk4(m, c, t, dt, q, qd, w)
        elif integrator == 3:
            step_symplectic_euler(m, c, t, dt, q, qd, w)
        else:
            step_velocity_verlet(m, c, t, dt, q, qd, w)
        status, index, value = _end_step(m, c, t, dt, s, steps, q, qd, w, max_speed, cq, crot, ci)
        if status != OK:
            return status, s, index, value
    return OK, steps, -1, 0.0


@njit(cache=True)
def simulate_implicit(
    bdf2,
    steps,
    t0,
    dt,
    m,
    c,
    q,
    qd,
    w,
    max_speed,
    ratio_min,
    ratio_max,
    cq,
    crot,
    ci,
    mg,
    cg_tolerance,
    cg_max_iterations,
    history,
):
    """``simulate`` for backward Euler and (``bdf2``) BDF2."""
    _begin_run(steps, dt, m, c, q, qd, w, cq)
    for s in range(steps):
        t = t0 + s * dt
        status, index, value = _start_step(m, c, t, q, qd, w, ratio_min, ratio_max)
        if status != OK:
            return status, s, index, value
        # BDF2 needs the previous step: from this call, or ``history`` says the workspace
        # holds it from the call before; else (and after contacts acted) backward Euler
        two_step = bdf2 and (s > 0 or history) and w.contacts_acted[0] == 0
        its = step_implicit(m, c, t, dt, q, qd, w, mg, cg_tolerance, cg_max_iterations, two_step)
        w.cg_stats[0] += 1
        w.cg_stats[1] += its
        w.cg_stats[2] = max(w.cg_stats[2], its)
        if bdf2:
            _copy_state(q, qd, w.qs, w.vs)  # contacts may move particles
        status, index, value = _end_step(m, c, t, dt, s, steps, q, qd, w, max_speed, cq, crot, ci)
        if status != OK:
            return status, s, index, value
        if bdf2:
            w.contacts_acted[0] = 1 if _contacts_acted(q, qd, w.qs, w.vs) else 0
    return OK, steps, -1, 0.0


@njit(cache=True)
def simulate_projective(
    steps, t0, dt, m, c, q, qd, w, max_speed, ratio_min, ratio_max, cq, crot, ci, pd, iterations
):
    """``simulate`` for projective dynamics, ``iterations`` local-global iterations per
    step."""
    _begin_run(steps, dt, m, c, q, qd, w, cq)
    for s in range(steps):
        t = t0 + s * dt
        _copy_state(q, qd, w.q0, w.v0)
        # projective dynamics evaluates its forces at its iterates: the checks below need
        # only the volumes (not their gradient: half the time)
        eval_model_volume_only(m, q, w)
        status, index, value = _check_volumes(
            w.body_volume, m.body_rest_volume, m.body_closed, ratio_min, ratio_max
        )
        if status != OK:
            return status, s, index, value
        step_projective(m, c, t, dt, q, qd, w, pd, iterations)
        status, index, value = _end_step(m, c, t, dt, s, steps, q, qd, w, max_speed, cq, crot, ci)
        if status != OK:
            return status, s, index, value
    return OK, steps, -1, 0.0
