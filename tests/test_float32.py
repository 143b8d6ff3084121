"""The explicit schemes' float32 force pass (``force_precision="float32"``) and the fused
symplectic Euler step: what each changes, held to bounds derived from float32's rounding
or to the bits of the general path."""

from __future__ import annotations

import numpy as np
import pytest

import softbody as sb
from softbody import core

EPS32 = 2.0**-24  # float32's unit round-off
#: Roundings one spring or face of the float32 pass chains (two subtractions for d, the
#: length's three products and two sums, 1/sqrt by the estimate and one Newton step,
#: the force's products and sums): a generous count, each at most EPS32 relative.
ROUNDINGS = 16


def ball(subdivisions: int = 2, *, ground: bool = True, gravity=(0.0, -9.81, 0.0)) -> sb.Model:
    builder = sb.ModelBuilder(gravity=gravity)
    builder.add_soft_body(
        sb.icosphere(subdivisions, radius=0.5, center=(0.0, 0.6, 0.0)),
        mass=1.0,
        stiffness=400.0,
        damping=0.5,
        gas=sb.Gas.isothermal(80.0),
    )
    if ground:
        builder.add_collider(sb.ColliderPlane(restitution=0.5, friction=0.1))
    return builder.finalize()


def deformed_state(model: sb.Model, seed: int = 0) -> sb.State:
    """The rest state with every particle moved by up to 2% of the radius and given a
    velocity of up to 1 m/s (fixed seed): every spring stretched and damped."""
    rng = np.random.default_rng(seed)
    state = model.state()
    state.particle_q[:] += rng.uniform(-0.01, 0.01, state.particle_q.shape)
    state.particle_qd[:] = rng.uniform(-1.0, 1.0, state.particle_qd.shape)
    return state


def one_step_forces(model: sb.Model, state: sb.State, precision: str, dt: float) -> np.ndarray:
    """The forces (N, 3) [N] at ``state`` as symplectic Euler applies them: f = m (v1 - v0)
    / dt (dt small enough that no particle reaches the ground)."""
    sim = sb.Simulator(
        model, integrator="symplectic_euler", dt=dt, force_precision=precision
    )
    after = state.copy()
    sim.run(after, 1)
    return model.particle_mass[:, None] * (after.particle_qd - state.particle_qd) / dt


def test_float32_forces_within_the_rounding_bound():
    """Forces of the float32 pass against float64 at a deformed, moving state. Reference:
    float32 rounds each row (x - x_ref, v) by at most EPS32 of its size (R, the body's
    extent, and V, the largest speed), so each of a particle's springs s feels its edge
    and relative velocity off by at most 2 EPS32 R and 2 EPS32 V per component, plus
    ROUNDINGS EPS32 of its own terms; each face's dV/dx share likewise, times the
    pressure. The bound per particle is their sum; float64's own error is 1e-16 of it."""
    model = ball(3)
    state = deformed_state(model)
    dt = 1e-7
    f64 = one_step_forces(model, state, "float64", dt)
    f32 = one_step_forces(model, state, "float32", dt)
    q, v = state.particle_q, state.particle_qd
    r_body = np.abs(q - q[0]).max()
    v_max = np.abs(v).max()
    ends = model.spring_indices.reshape(-1, 2)
    d = q[ends[:, 1]] - q[ends[:, 0]]
    length = np.linalg.norm(d, axis=1)
    vrel = np.linalg.norm(v[ends[:, 1]] - v[ends[:, 0]], axis=1)
    k, c, rest = model.spring_stiffness, model.spring_damping, model.spring_rest_length
    per_spring = (
        k * (4 * np.sqrt(3) * EPS32 * r_body + ROUNDINGS * EPS32 * (length + rest))
        + c * (4 * np.sqrt(3) * EPS32 * v_max + ROUNDINGS * EPS32 * vrel)
        + ROUNDINGS * EPS32 * np.abs(k * (length - rest) + c * vrel)
    )
    bound = np.zeros(model.particle_count)
    np.add.at(bound, ends[:, 0], per_spring)
    np.add.at(bound, ends[:, 1], per_spring)
    tri = model.tri_indices.reshape(-1, 3)
    x = q[tri]
    edge = np.maximum(
        np.linalg.norm(x[:, 1] - x[:, 0], axis=1), np.linalg.norm(x[:, 2] - x[:, 0], axis=1)
    )
    pressure = 80.0 / sb.body_volume(model, state)[0]
    # a face's n / 6 from float edges: |dn| <= 2 (4 EPS32 R) |e| + ROUNDINGS EPS32 |e|^2
    per_face = pressure / 6.0 * (8 * np.sqrt(3) * EPS32 * r_body * edge
                                 + ROUNDINGS * EPS32 * edge**2)  # fmt: skip
    # the volume's relative error moves P: each face's share of 6 V, rounded likewise
    volume_error = np.sum(ROUNDINGS * EPS32 * edge**2 * 3 * r_body) / 6.0
    gradient = np.linalg.norm(np.zeros_like(q), axis=1)
    for corner in range(3):
        np.add.at(bound, tri[:, corner], per_face)
        np.add.at(gradient, tri[:, corner], np.linalg.norm(np.cross(
            x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1) / 6.0)  # fmt: skip
    bound += pressure * volume_error / sb.body_volume(model, state)[0] * gradient
    error = np.linalg.norm(f32 - f64, axis=1)
    assert error.max() > 0.0  # the float32 pass ran
    assert np.all(error <= bound), (error / bound).max()
    # and the bound is no blanket: the errors reach a visible part of it
    assert (error / bound).max() > 1e-3


def test_float32_keeps_momentum_in_free_flight():
    """A spinning, deformed ball with no gravity and no ground: its momentum stays its
    start value. Reference: each spring's two float32 forces are exact negatives (both
    ends round the same negated edge), so springs add nothing; the pressure's dV/dx, each
    face's n / 6 rounded at each corner apart, sums to zero within 3 ROUNDINGS EPS32 |n|
    / 6 per face, so the momentum drifts at most T |P| sum_f 3 ROUNDINGS EPS32 |n_f| / 6
    over T seconds, on top of float64's sums."""
    model = ball(2, ground=False, gravity=(0.0, 0.0, 0.0))
    state = deformed_state(model, seed=1)
    state.particle_qd[:] += np.cross([0.0, 0.0, 3.0], state.particle_q - [0.0, 0.6, 0.0])
    momentum0 = (model.particle_mass[:, None] * state.particle_qd).sum(axis=0)
    dt, steps = 2e-5, 2000
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=dt, force_precision="float32")
    sim.run(state, steps)
    momentum = (model.particle_mass[:, None] * state.particle_qd).sum(axis=0)
    tri = model.tri_indices.reshape(-1, 3)
    x = state.particle_q[tri]
    n_sum = np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1).sum()
    pressure = 80.0 / sb.body_volume(model, state)[0]
    bound = steps * dt * 1.5 * pressure * 3 * ROUNDINGS * EPS32 * n_sum / 6.0 + 1e-12
    assert np.abs(momentum - momentum0).max() <= bound
    assert np.abs(momentum0).max() > 0.01  # a momentum worth keeping


@pytest.mark.parametrize("subdivisions", [2, 3])
def test_float32_paths_agree(subdivisions):
    """The float32 pass on every instruction set: AVX2 and AVX-512 run the same 8-float
    code with the same 1/sqrt estimate, so the same bits; the scalar path rounds 1/sqrt
    once instead, so it agrees to float32 round-off grown over 50 steps (1e-6 of the
    motion, against motion of order 1e-2 m)."""
    model = ball(subdivisions)
    results = {}
    for simd in core.simd_paths():
        core.use_simd(simd)
        try:
            sim = sb.Simulator(
                model, integrator="symplectic_euler", dt=1e-5, force_precision="float32"
            )
            state = deformed_state(model)
            sim.run(state, 50)
            results[simd] = state.particle_q.copy()
        finally:
            core.use_simd("auto")
    if "avx2" in results and "avx512" in results:
        assert np.array_equal(results["avx2"], results["avx512"])
    start = deformed_state(model).particle_q
    scale = np.abs(results["scalar"] - start).max()
    for simd, q in results.items():
        assert np.abs(q - results["scalar"]).max() <= 1e-6 * max(scale, 1e-2), simd


def test_fused_symplectic_euler_gives_the_general_steps_bits():
    """Symplectic Euler ends a step in one fused pass when nothing but the body's forces,
    Control forces and colliders act. A grab spring of zero stiffness and damping adds
    exactly 0 N but sends the run through the general step: both must give the same
    bits over a drop with ground contacts (2,500 steps), with a Control force on."""
    model = ball(2)
    force = np.zeros((model.particle_count, 3))
    force[5] = [0.3, 0.0, -0.2]
    plain, grab = sb.Control.neutral(model), sb.Control.neutral(model)
    plain.particle_f[:] = grab.particle_f[:] = force
    grab.grab_particle, grab.grab_target = 0, np.zeros(3)
    runs = []
    for control in (plain, grab):
        sim = sb.Simulator(model, integrator="symplectic_euler", dt=2e-4)
        state = model.state()
        sim.run(state, 2500, control=control)
        runs.append(state)
    assert np.abs(runs[0].collider_impulse).sum() > 0.1  # it touched down [N s]
    assert np.array_equal(runs[0].particle_q, runs[1].particle_q)
    assert np.array_equal(runs[0].particle_qd, runs[1].particle_qd)


def test_fused_symplectic_euler_blows_up_where_the_general_step_does():
    """A too-long step blows up the same way on both paths (as above): the same step,
    particle and message, with the state left at the last good step, bit for bit."""
    model = ball(2)
    errors, states = [], []
    grab = sb.Control.neutral(model)
    grab.grab_particle, grab.grab_target = 0, np.zeros(3)
    for control in (sb.Control.neutral(model), grab):
        with pytest.warns(sb.StabilityWarning):
            sim = sb.Simulator(model, integrator="symplectic_euler", dt=5e-3)
        state = model.state()
        with pytest.raises(sb.SimulationError) as info:
            sim.run(state, 400, control=control)
        errors.append(str(info.value))
        states.append(state)
    assert errors[0] == errors[1]
    assert np.array_equal(states[0].particle_q, states[1].particle_q)


def test_force_precision_is_checked():
    """A precision other than float64 or float32 and float32 for a solver without a
    float32 pass are errors that name the option; the option travels in
    Simulator.options."""
    model = ball(1)
    with pytest.raises(ValueError, match="force_precision"):
        sb.Simulator(model, integrator="symplectic_euler", dt=1e-4, force_precision="half")
    with pytest.raises(ValueError, match="force_precision"):
        sb.Simulator(model, integrator="implicit_euler", dt=1e-3, force_precision="float32")
    sim = sb.Simulator(model, integrator="midpoint", dt=1e-4, force_precision="float32")
    assert sim.options["force_precision"] == "float32"
    assert sim.solver._core.float32


@pytest.mark.skipif(core.available_threads() < 2, reason="needs two cores")
def test_float32_on_threads_repeats_and_matches_serial():
    """The float32 pass on two threads (each packing and passing its own run of groups):
    the same bits on a second run, and the serial run's trajectory up to the round-off of
    the chunks' volume sums grown over 3,000 steps with ground contacts (1e-9 m)."""
    model = ball(3)
    runs = {}
    for threads in (1, 2, 2):
        sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-4, threads=threads,
                           force_precision="float32")  # fmt: skip
        state = deformed_state(model)
        sim.run(state, 3000)
        if threads in runs:
            assert np.array_equal(state.particle_q, runs[threads])
        runs[threads] = state.particle_q.copy()
    assert np.abs(state.collider_impulse).sum() > 0.1  # it touched down [N s]
    assert np.abs(runs[2] - runs[1]).max() <= 1e-9
