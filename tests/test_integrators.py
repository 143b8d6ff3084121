"""Integrators: convergence order, free fall, momentum, energy behaviour, pins."""

from __future__ import annotations

import numpy as np
import pytest

import softbody as sb
from conftest import ball_model, settle, simulator_past_estimate

ALL = ["euler", "midpoint", "rk4", "symplectic_euler", "velocity_verlet"]


def two_mass_oscillator(m1=1.0, m2=2.0, k=100.0, stretch=0.1):
    """Two particles on x joined by a spring of rest length 1, released stretched."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    i = builder.add_particle((0.0, 0.0, 0.0), mass=m1)
    j = builder.add_particle((1.0 + stretch, 0.0, 0.0), mass=m2)
    builder.add_spring(i, j, stiffness=k, rest_length=1.0)
    return builder.finalize()


def oscillator_error(integrator, dt, t_end=1.0):
    """|x1(T) - exact|: relative coordinate r = 1 + 0.1 cos(w t), w = sqrt(k (1/m1 + 1/m2)),
    centre of mass fixed at x = 2 (1.1) / 3, so x1 = x_cm - m2 / (m1 + m2) r."""
    model = two_mass_oscillator()
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)  # undamped Euler/midpoint
        sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    sim.run(state, round(t_end / dt))
    w = np.sqrt(100.0 * (1 / 1.0 + 1 / 2.0))
    x_cm = 2.0 * 1.1 / 3.0
    x1 = x_cm - 2.0 / 3.0 * (1.0 + 0.1 * np.cos(w * t_end))
    return abs(state.particle_q[0, 0] - x1)


@pytest.mark.parametrize(
    "integrator,order",
    [("euler", 1), ("midpoint", 2), ("rk4", 4), ("symplectic_euler", 1), ("velocity_verlet", 2)],
)
def test_convergence_order_on_two_mass_oscillator(integrator, order):
    """Global error ~ C dt^p: halving dt (w dt = 0.061 -> 0.015, the asymptotic range)
    divides the error by 2^p; the measured p must be within 0.15 of the scheme's order."""
    dts = [1 / 200, 1 / 400, 1 / 800]
    errors = [oscillator_error(integrator, dt) for dt in dts]
    slopes = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(slopes - order) < 0.15), (errors, slopes)


@pytest.mark.parametrize("integrator", ALL)
def test_free_fall_of_centre_of_mass(integrator):
    """Internal forces cancel, so the centre of mass falls as under gravity alone; each
    scheme's closed form for constant acceleration g over n steps of dt:
    exact (midpoint, RK4, Verlet): y = y0 + v0 t + g t^2 / 2;
    explicit Euler: g t^2 / 2 - g t dt / 2; symplectic Euler: g t^2 / 2 + g t dt / 2."""
    g = -9.81
    model = ball_model(gravity=(0, g, 0), damping=0.5, velocity=(0.0, 2.0, 0.0))
    dt, n = 5e-4, 600
    sim = simulator_past_estimate(model, integrator, dt)  # holds at any dt
    state = model.state()
    y0 = sb.body_center_of_mass(model, state)[0, 1]
    sim.run(state, n)
    t = n * dt
    offset = {"euler": -0.5 * g * t * dt, "symplectic_euler": 0.5 * g * t * dt}.get(integrator, 0.0)
    expected = y0 + 2.0 * t + 0.5 * g * t**2 + offset
    got = sb.body_center_of_mass(model, state)[0, 1]
    # round-off of n steps of sums over N particles
    assert got == pytest.approx(expected, abs=1e-11)


@pytest.mark.parametrize("integrator", ALL)
def test_linear_momentum_is_conserved_without_gravity(integrator):
    """No external force: total momentum stays at its initial value (each force evaluation
    sums to zero, and every scheme combines whole evaluations)."""
    model = ball_model(damping=0.5)
    state = model.state()
    rng = np.random.default_rng(5)
    state.particle_qd[:] = rng.normal(scale=0.3, size=state.particle_qd.shape)
    p0 = (model.particle_mass[:, None] * state.particle_qd).sum(axis=0)
    simulator_past_estimate(model, integrator, 5e-4).run(state, 400)  # holds at any dt
    p1 = (model.particle_mass[:, None] * state.particle_qd).sum(axis=0)
    assert np.allclose(p1, p0, rtol=0, atol=1e-13)


def _energy_run(dt, steps):
    """Undamped ball vibrating about its equilibrium (found by settling a damped copy)."""
    rest = settle(ball_model(stiffness=500.0, damping=1.0, gas=sb.Gas.isothermal(300.0)))
    model = ball_model(stiffness=500.0, damping=0.0, gas=sb.Gas.isothermal(300.0))
    state = sb.State(rest.particle_q.copy(), np.zeros_like(rest.particle_q))
    rng = np.random.default_rng(2)
    v = rng.normal(scale=0.05, size=state.particle_qd.shape)
    state.particle_qd[:] = v - v.mean(axis=0)  # no drift of the whole ball
    sim = sb.Simulator(model, integrator="velocity_verlet", dt=dt)
    e0 = sb.energies(model, state)
    totals = [e0.total]
    chunk = steps // 100
    for _ in range(100):
        sim.run(state, chunk)
        totals.append(sb.energies(model, state).total)
    return sim, e0, np.array(totals) - e0.total


def test_energy_is_bounded_with_velocity_verlet():
    """No damping, no gravity, closed isothermal gas, exact volume: Verlet conserves a
    modified energy H + O(dt^2). Started at equilibrium with kinetic energy K0, each mode
    of frequency w keeps |E - E0| <= (w dt)^2 / 4 of its energy, so over 10,000 steps the
    error stays below (w_max dt)^2 / 4 K0 with no secular drift, and halving dt divides the
    error by 4 (second order)."""
    dt = 1e-3
    sim, e0, err = _energy_run(dt, 10_000)
    bound = 0.25 * (sim.stiffest_mode.omega * dt) ** 2 * e0.kinetic
    assert np.max(np.abs(err)) <= bound
    # no drift: the error's trend over the run is a small part of its fluctuation
    slope = np.polyfit(np.linspace(0, 1, len(err)), err, 1)[0]
    assert abs(slope) <= 0.1 * bound
    _, _, err_half = _energy_run(dt / 2, 20_000)
    ratio = np.max(np.abs(err)) / np.max(np.abs(err_half))
    assert 3.0 <= ratio <= 5.0


def test_pinned_particles_stay_and_follow_targets():
    """Pinned vertices ignore forces; Control.pin_target moves them at constant velocity
    to the target by the end of the call."""
    builder = sb.ModelBuilder()
    builder.add_soft_body(
        sb.icosphere(2), mass=1.0, stiffness=800.0, damping=1.0, gas=300.0, pinned=[0, 1]
    )
    model = builder.finalize()
    sim = sb.Simulator(model, integrator="rk4", dt=5e-4)
    state = model.state()
    start = state.particle_q[:2].copy()
    sim.run(state, 400)
    assert np.array_equal(state.particle_q[:2], start)
    assert state.particle_q[2:, 1].mean() < model.particle_q[2:, 1].mean()  # rest sags
    control = model.control()
    control.pin_target = start + np.array([0.0, 0.5, 0.0])
    sim.run(state, 200, control)  # 0.1 s
    assert np.allclose(state.particle_q[:2], start + np.array([0.0, 0.5, 0.0]), atol=1e-12)
    assert np.allclose(state.particle_qd[:2], [0.0, 5.0, 0.0], atol=1e-9)


def test_external_force_from_control():
    """A constant external force F on a free particle: x = F t^2 / (2 m) (exact for RK4)."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.add_particle((0, 0, 0), mass=2.0)
    model = builder.finalize()
    control = model.control()
    control.particle_f[0] = [4.0, 0.0, -2.0]
    state = model.state()
    sb.Simulator(model, integrator="rk4", dt=0.01).run(state, 100, control)
    assert np.allclose(state.particle_q[0], [1.0, 0.0, -0.5], atol=1e-12)
