"""Implicit (backward) Euler and BDF2: stability at large steps, and the same physics
tests as the explicit integrators."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import softbody as sb
from conftest import ball_model, uniform_scaling_stationary


def dropped_stiff_ball():
    builder = sb.ModelBuilder()
    builder.add_soft_body(
        sb.icosphere(2, center=(0.0, 1.2, 0.0)), mass=1.0, stiffness=5000.0, damping=0.5, gas=300.0
    )
    builder.add_collider(sb.ColliderPlane(restitution=0.3))
    return builder.finalize()


def assert_explicit_euler_blows_up(model) -> None:
    """Explicit Euler at 1/60 s on ``model`` stops with a blow-up error within 2 s."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        explicit = sb.Simulator(model, integrator="euler", dt=1 / 60)
    with pytest.raises(sb.SimulationError, match="body 0 blew up at step"):
        explicit.run(model.state(), 120)


def centre_heights(model, sim, state, steps: int = 120) -> tuple[float, list[float]]:
    """Body 0's centre-of-mass height [m] before and after each of ``steps`` steps."""
    start = sb.body_center_of_mass(model, state)[0, 1]
    heights = []
    for _ in range(steps):
        sim.run(state, 1)
        heights.append(sb.body_center_of_mass(model, state)[0, 1])
    return start, heights


IMPLICIT = ["implicit_euler", "bdf2"]
#: the schemes that solve for backward Euler's (or BDF2's) end state, with projective
#: dynamics (default two local-global iterations), for the tests that hold for all three
SOLVED = [*IMPLICIT, "projective"]


@pytest.mark.parametrize("integrator", IMPLICIT)
def test_stable_at_a_sixtieth_of_a_second_where_explicit_euler_blows_up(integrator):
    """A stiff ball (k = 5000 N/m, stiffest mode ~ 3,100 rad/s: w dt ~ 52 at dt = 1/60 s)
    dropped on the ground. Explicit Euler blows up within a few steps; backward Euler and
    BDF2 run 2 s with the ball never rising above its drop height (restitution 0.3: no
    energy may appear) and its volume within 5% of the gas-spring equilibrium at the end;
    backward Euler's damping has it resting (centre of mass one radius up, within 2%)."""
    model = dropped_stiff_ball()
    assert_explicit_euler_blows_up(model)
    sim = sb.Simulator(model, integrator=integrator, dt=1 / 60)
    assert sim.stable_dt == float("inf")
    state = model.state()
    start, heights = centre_heights(model, sim, state)
    assert max(heights) <= start
    if integrator == "implicit_euler":
        assert heights[-1] == pytest.approx(1.0, rel=0.02)
    ratio = sb.body_volume(model, state)[0] / model.body_rest_volume[0]
    s = uniform_scaling_stationary(5000.0, model.spring_rest_length, 300.0)
    assert ratio == pytest.approx(s**3, rel=0.05)
    assert state.particle_q[:, 1].min() >= 0.0


@pytest.mark.parametrize("integrator", IMPLICIT)
def test_icosahedron_settles_at_uniform_scaling_equilibrium(integrator):
    """Equilibrium is a fixed point of backward Euler and BDF2 at any dt: even at dt =
    50 ms the icosahedron settles exactly where 1/2 k (s-1)^2 sum L0^2 - nRT ln(s^3 V0)
    is stationary (to the CG tolerance, 1e-10)."""
    k, nrt = 200.0, 150.0
    model = ball_model(subdivisions=0, stiffness=k, damping=4.0, gas=nrt)
    sim = sb.Simulator(model, integrator=integrator, dt=0.05, implicit_tolerance=1e-12)
    state = model.state()
    sim.run(state, 400)
    s = uniform_scaling_stationary(k, model.spring_rest_length, nrt)
    scale = (sb.body_volume(model, state)[0] / model.body_rest_volume[0]) ** (1 / 3)
    assert scale == pytest.approx(s, rel=1e-9)


@pytest.mark.parametrize("integrator", SOLVED)
def test_energy_never_grows(integrator):
    """No damping, no gravity, closed gas: backward Euler is dissipative (|1/(1 - h l)| < 1
    for every mode) and BDF2 A-stable, damping the modes with w dt >> 1 (projective
    dynamics, at its default two iterations: its local and global steps each lower the
    springs' incremental potential, and its explicit gas term is far inside its limit,
    1 / omega_gas = 19 ms), so the total energy of a ball kicked into vibration never
    rises above its start (beyond CG round-off, 1e-9 of it) and falls measurably over
    200 steps of 5 ms."""
    model = ball_model(stiffness=500.0, damping=0.0, gas=300.0)
    state = model.state()
    rng = np.random.default_rng(3)
    v = rng.normal(scale=0.2, size=state.particle_qd.shape)
    state.particle_qd[:] = v - v.mean(axis=0)
    sim = sb.Simulator(model, integrator=integrator, dt=5e-3, implicit_tolerance=1e-10)
    e0 = sb.energies(model, state).total
    totals = []
    for _ in range(40):
        sim.run(state, 5)
        totals.append(sb.energies(model, state).total)
    totals = np.array(totals)
    assert np.all(totals <= e0 + 1e-9 * abs(e0))
    assert totals[-1] < e0 - 1e-3 * sb.energies(model, model.state()).kinetic - 1e-12


@pytest.mark.parametrize("integrator", SOLVED)
def test_momentum_is_conserved_without_gravity(integrator):
    """Internal forces and their Jacobians have zero column sums (translation invariance),
    so with the linear solve converged (tolerance 1e-12) total momentum stays put.
    Projective dynamics at any iteration count: its spring projections enter as equal and
    opposite pairs and its matrix's spring part has zero column sums."""
    model = ball_model(damping=1.0)
    state = model.state()
    state.particle_qd[:] = np.random.default_rng(5).normal(scale=0.3, size=state.particle_qd.shape)
    p0 = (model.particle_mass[:, None] * state.particle_qd).sum(axis=0)
    sb.Simulator(
        model,
        integrator=integrator,
        dt=1e-2,
        implicit_tolerance=1e-12,
        implicit_max_iterations=1000,
    ).run(state, 50)
    p1 = (model.particle_mass[:, None] * state.particle_qd).sum(axis=0)
    assert np.allclose(p1, p0, rtol=0, atol=1e-9)


def test_first_order_convergence_on_two_mass_oscillator():
    """Backward Euler is first order: halving dt halves the error (slope within 0.15)."""
    from test_integrators import oscillator_error

    errors = [oscillator_error("implicit_euler", dt) for dt in (1 / 200, 1 / 400, 1 / 800)]
    slopes = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(slopes - 1) < 0.15), (errors, slopes)


def test_bdf2_is_second_order_on_two_mass_oscillator():
    """BDF2 is second order (its first step is backward Euler, whose O(dt^2) local error
    keeps the global order): halving dt quarters the error (slope within 0.15 of 2)."""
    from test_integrators import oscillator_error

    errors = [oscillator_error("bdf2", dt) for dt in (1 / 200, 1 / 400, 1 / 800)]
    slopes = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(slopes - 2) < 0.15), (errors, slopes)


def test_bdf2_history_follows_the_state():
    """BDF2 uses the previous step, which the state carries (State.history): two calls of
    one step each equal one call of two (the history carries over), and a simulator reused
    on a fresh state, on a state whose positions were assigned, or on one edited in place
    and marked (State.mark_edited), restarts with a backward Euler step exactly as a new
    simulator does (bitwise)."""
    model = ball_model(subdivisions=1, stiffness=300.0, damping=0.5, gravity=(0.0, -9.81, 0.0))
    sim = sb.Simulator(model, integrator="bdf2", dt=1 / 60, implicit_tolerance=1e-12)
    a, b = model.state(), model.state()
    sim.run(a, 2)
    split = sb.Simulator(model, integrator="bdf2", dt=1 / 60, implicit_tolerance=1e-12)
    split.run(b, 1)
    split.run(b, 1)
    assert np.allclose(a.particle_q, b.particle_q, rtol=0, atol=1e-12)
    fresh = model.state()
    sim.run(fresh, 3)  # sim last stepped `a`: this state starts anew
    reference = model.state()
    sb.Simulator(model, integrator="bdf2", dt=1 / 60, implicit_tolerance=1e-12).run(reference, 3)
    assert np.array_equal(fresh.particle_q, reference.particle_q)
    for edit in ("assigned", "in place"):
        if edit == "in place":  # the same history again, from a simulator as before
            sim = sb.Simulator(model, integrator="bdf2", dt=1 / 60, implicit_tolerance=1e-12)
            fresh = model.state()
            sim.run(fresh, 3)
        if edit == "assigned":
            fresh.particle_q = fresh.particle_q + np.array([0.0, 0.01, 0.0])
        else:
            fresh.particle_q[:, 1] += 0.01  # no assignment: the state cannot see it
            fresh.mark_edited()
        copy = sb.State(fresh.particle_q.copy(), fresh.particle_qd.copy())
        sim.run(fresh, 1)
        sb.Simulator(model, integrator="bdf2", dt=1 / 60, implicit_tolerance=1e-12).run(copy, 1)
        assert np.array_equal(fresh.particle_q, copy.particle_q), edit


def test_bdf2_history_travels_with_the_state():
    """The history is the state's, not the solver's: a simulator that stepped another state
    in between, a copy of the state (State.copy), and a new simulator all go on from it
    as one run of all the steps does (to 1e-12 m: CG's tolerance, its warm start being the
    solver's; a backward Euler step instead is off by about 1e-4 m), and another scheme's
    step or another dt ends it."""
    model = ball_model(subdivisions=1, stiffness=300.0, damping=0.5, gravity=(0.0, -9.81, 0.0))
    options = dict(integrator="bdf2", dt=1 / 60, implicit_tolerance=1e-12)
    whole = model.state()
    sb.Simulator(model, **options).run(whole, 4)
    sim, other = sb.Simulator(model, **options), model.state()
    a = model.state()
    sim.run(a, 2)
    sim.run(other, 1)  # the solver's core now holds `other`'s step
    c = a.copy()
    sim.run(a, 2)
    sb.Simulator(model, **options).run(c, 2)
    assert np.allclose(a.particle_q, whole.particle_q, rtol=0, atol=1e-12)
    assert np.allclose(c.particle_q, whole.particle_q, rtol=0, atol=1e-12)
    # the same steps, with another scheme's step or another dt before the last: no history
    for interrupt in ("implicit_euler", "dt"):
        s = model.state()
        sim.run(s, 1)
        if interrupt == "dt":
            sb.Simulator(model, integrator="bdf2", dt=1 / 120, implicit_tolerance=1e-12).run(s, 1)
        else:
            sb.Simulator(model, integrator=interrupt, dt=1 / 60).run(s, 1)
        assert s.history is None or not s.history.belongs_to(s, 1 / 60)


@pytest.mark.parametrize("integrator", IMPLICIT)
def test_numerical_damping_matches_the_amplification_factor(integrator):
    """Undamped two-mass oscillator (w = sqrt(150) rad/s) at dt = 1/60 s (w dt = 0.2) for
    120 steps: the amplitude sqrt(x^2 + (v / w)^2) of the relative motion falls by the
    scheme's spectral radius per step, rho^N (backward Euler: 1 / sqrt(1 + (w dt)^2),
    to 0.086; BDF2, whose first step is backward Euler: to 0.93), within 3%. This is the
    damping the README reports: BDF2 keeps 93% where backward Euler keeps 9%."""
    from softbody.integrators import Integrator
    from softbody.stability import amplification_matrix
    from test_integrators import two_mass_oscillator

    w, dt, steps = np.sqrt(150.0), 1 / 60, 120
    model = two_mass_oscillator()
    state = model.state()
    sb.Simulator(model, integrator=integrator, dt=dt, implicit_tolerance=1e-12).run(state, steps)
    x = state.particle_q[1, 0] - state.particle_q[0, 0] - 1.0
    v = state.particle_qd[1, 0] - state.particle_qd[0, 0]
    amplitude = np.hypot(x, v / w) / 0.1

    def rho(name):
        g = amplification_matrix(Integrator.parse(name), dt, w, 0.0)
        return np.abs(np.linalg.eigvals(g)).max()

    expected = rho("implicit_euler") * rho(integrator) ** (steps - 1)
    assert amplitude == pytest.approx(expected, rel=0.03)


def test_pressure_jacobian_matches_finite_differences():
    """The matrix-free K p (springs, rank-one P'(V) g g^T and (P - Pa) d2V/dx2) equals the
    directional derivative of the force, (f(x + h p) - f(x - h p)) / 2h (h = 1e-6:
    truncation ~h^2, round-off ~eps/h relative), to 1e-6 of its largest entry, for
    stretched springs (for compressed ones the solver drops the negative geometric
    stiffness on purpose)."""
    from conftest import deformed, forces
    from softbody import _core
    from softbody.core import core_model
    from softbody.sim.control import control_data

    model = ball_model(
        subdivisions=1,
        stiffness=300.0,
        damping=0.0,
        gas=sb.Gas.adiabatic(200.0, ambient_pressure=20.0),
    )
    state = deformed(model, 7, 0.01)
    state.particle_q *= 1.3  # every spring stretched: the compressive clamp is inactive
    q = state.particle_q
    d = q[model.spring_indices[:, 1]] - q[model.spring_indices[:, 0]]
    lengths = np.linalg.norm(d, axis=1)
    assert np.all(lengths > model.spring_rest_length)
    # the spring blocks (a - b) u u^T + b I: a = k along the spring, b = k (1 - L0 / L)
    # across it; the gas's P - P_a and dP/dV = -gamma P / V (adiabatic)
    u = d / lengths[:, None]
    a = model.spring_stiffness.copy()
    b = model.spring_stiffness * (1.0 - model.spring_rest_length / lengths)
    c = control_data(model)
    volume, pressure, gradient = _core.eval_volumes(core_model(model), c, 0.0, q)
    pnet = pressure - model.body_ambient_pressure
    dpdv = -model.body_gas_gamma * pressure / volume
    p = np.random.default_rng(1).normal(size=q.shape)
    kp = np.zeros_like(q)
    # in the springs' and the gas's layouts (core/terms/springs.hpp, gas.hpp)
    linearization = {"springs": np.concatenate([u.ravel(), a, b]),
                     "gas": np.concatenate([dpdv, pnet])}  # fmt: skip
    _core.apply_jacobians(core_model(model), c, q, p, 0.0, 0.0, 1.0, kp,
                          linearization=linearization, volume_gradient=gradient)  # fmt: skip
    h = 1e-6
    plus = forces(model, sb.State(q + h * p, state.particle_qd))
    minus = forces(model, sb.State(q - h * p, state.particle_qd))
    assert np.allclose(kp, (plus - minus) / (2 * h), rtol=0, atol=1e-6 * np.abs(kp).max())


def test_bad_solver_settings():
    """A CG tolerance outside (0, 1) or an iteration limit below 1 is a ValueError naming
    the option."""
    model = ball_model()
    with pytest.raises(ValueError, match="implicit_tolerance must lie in"):
        sb.Simulator(model, integrator="implicit_euler", dt=1e-2, implicit_tolerance=0.0)
    with pytest.raises(ValueError, match="implicit_max_iterations must be an integer"):
        sb.Simulator(model, integrator="implicit", dt=1e-2, implicit_max_iterations=0)


@pytest.mark.parametrize("integrator", SOLVED)
@pytest.mark.parametrize(
    "name", ["bouncing-balls", "hanging-ball", "hand-punch", "cloth-wind", "bounding-volumes"]
)
def test_built_in_scenes_are_stable_at_a_sixtieth_of_a_second(name, integrator):
    """Every built-in scene runs 2 s at dt = 1/60 s (4 to 80 times its explicit step)
    without blowing up, every closed body's volume within [0.5, 3] of its rest volume.
    Projective dynamics warns on three of them (its estimate, 1 / omega_gas, counts only
    the masses against the gas, 4.3-14 ms here) and runs them all: its matrix's springs
    resist the volume mode too."""
    from softbody.scenes import load_scene

    model = load_scene(name).model
    state = model.state()
    with warnings.catch_warnings():
        if integrator == "projective":
            warnings.simplefilter("ignore", sb.StabilityWarning)
        sb.Simulator(model, integrator=integrator, dt=1 / 60).run(state, 120)
    ratio = sb.body_volume(model, state) / model.body_rest_volume
    closed = model.body_closed == 1
    assert np.all((ratio[closed] > 0.5) & (ratio[closed] < 3.0))
