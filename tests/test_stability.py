"""Stable time-step estimate and blow-up detection."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import softbody as sb
from conftest import ball_model, settle
from softbody.integrators import Integrator
from softbody.stability import (
    SPECTRAL_MARGIN,
    amplification_matrix,
    largest_stable_step,
    step_radius,
)


def two_masses(m1=1.0, m2=3.0, k=400.0, rest_length=0.0):
    """Two particles on a spring; with rest length 0 the force k (x_j - x_i) is linear, so
    an unstable step grows without bound instead of saturating."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    i = builder.add_particle((0, 0, 0), mass=m1)
    j = builder.add_particle((1.05, 0, 0), mass=m2)
    builder.add_spring(i, j, stiffness=k, rest_length=rest_length)
    return builder.finalize()


def test_two_mass_frequency_bounds_are_exact():
    """For one spring the Gershgorin bounds are the true frequencies: axial (damped)
    w^2 = k (1/m1 + 1/m2), transverse (undamped) w^2 = k (1 - L0/L) (1/m1 + 1/m2), with
    L = 1.05, L0 = 1; and the whole spring's block has norm k max(1, |1 - L0/L|), so the
    total bound is the axial one."""
    mode = sb.Simulator(two_masses(rest_length=1.0), integrator="rk4", dt=1e-4).stiffest_mode
    assert mode.omega_damped == pytest.approx(np.sqrt(400.0 * (1 + 1 / 3)), rel=1e-14)
    transverse = 400.0 * (1 - 1 / 1.05) * (1 + 1 / 3)
    assert mode.omega_undamped == pytest.approx(np.sqrt(transverse), rel=1e-14)
    assert mode.omega == pytest.approx(np.sqrt(400.0 * (1 + 1 / 3)), rel=1e-14)


@pytest.mark.parametrize(
    "integrator,limit",
    [("symplectic_euler", 2.0), ("velocity_verlet", 2.0), ("rk4", 2.0 * np.sqrt(2.0))],
)
def test_undamped_limits_match_theory(integrator, limit):
    """Known stability limits on an undamped oscillator: w dt <= 2 for symplectic Euler and
    Verlet, w dt <= 2 sqrt(2) for RK4."""
    h = largest_stable_step(Integrator.parse(integrator), 1.0, 0.0)
    assert h == pytest.approx(limit, rel=1e-6)


def test_euler_needs_damping():
    """Explicit Euler on x'' = -w^2 x - 2 z w x': |1 + h lambda| <= 1 needs w h <= 2 z for
    light damping, and no step is stable without damping."""
    assert largest_stable_step(Integrator.EULER, 1.0, 0.0) < 1e-5
    assert largest_stable_step(Integrator.EULER, 1.0, 0.05) == pytest.approx(0.1, rel=1e-6)
    g = amplification_matrix(Integrator.EULER, 0.05, 1.0, 0.0)
    assert np.max(np.abs(np.linalg.eigvals(g))) > 1


@pytest.mark.parametrize("integrator", ["implicit_euler", "bdf2"])
def test_implicit_schemes_are_a_stable(integrator):
    """Backward Euler and BDF2 are A-stable: on the undamped oscillator the spectral radius
    of one step is below 1 for every w dt from 0.01 to 1e4 (BDF2's (4, 4) companion
    matrix included), tends to 0 as w dt grows (L-stable), and no step limit exists."""
    scheme = Integrator.parse(integrator)
    radii = [
        np.abs(np.linalg.eigvals(amplification_matrix(scheme, h, 1.0, 0.0))).max()
        for h in np.logspace(-2, 4, 61)
    ]
    assert max(radii) < 1.0
    assert radii[-1] < 0.02
    assert largest_stable_step(scheme, 1.0, 0.0) == float("inf")


@pytest.mark.parametrize("integrator", ["symplectic_euler", "velocity_verlet", "rk4"])
def test_estimate_separates_stable_from_unstable(integrator):
    """Just below the estimate the linear oscillator stays bounded for 20,000 steps (near
    the limit a symplectic scheme's orbit is an ellipse stretched by up to
    1 / sqrt(1 - (w dt / 2)^2) = 7 for w dt = 1.98: allow 10x the initial separation);
    5% above it the run blows up, and the error names the particle and the step."""
    model = two_masses()
    sim = sb.Simulator(model, integrator=integrator, dt=1e-3)
    dt = sim.stable_dt
    state = model.state()
    slow = sb.Simulator(model, integrator=integrator, dt=0.99 * dt)
    for _ in range(100):
        slow.run(state, 200)
        separation = np.linalg.norm(state.particle_q[1] - state.particle_q[0])
        assert separation < 10 * 1.05
    with pytest.warns(sb.StabilityWarning, match="exceeds the stable estimate"):
        fast = sb.Simulator(model, integrator=integrator, dt=1.05 * dt)
    state = model.state()
    with pytest.raises(sb.SimulationError, match=r"free particle blew up at step \d+") as info:
        fast.run(state, 20_000)
    assert info.value.particle in (0, 1)
    assert np.all(np.isfinite(state.particle_q))  # left at the last good step


def test_ball_estimate_is_conservative():
    """For the paper's ball the estimate is an upper bound on the frequency, so the
    estimated step is safe: 2,000 steps at it stay round (volume within 10% of start)."""
    model = ball_model(damping=0.5)
    sim = sb.Simulator(model, integrator="midpoint", dt=1e-4)
    state = model.state()
    sb.Simulator(model, integrator="midpoint", dt=sim.stable_dt).run(state, 2000)
    ratio = sb.body_volume(model, state)[0] / model.body_rest_volume[0]
    assert 0.9 < ratio < 1.3


def test_blow_up_names_body_and_step():
    """Explicit Euler far above its limit on a stiff ball: SimulationError names body 0,
    the step and the time, and mentions the stability estimate."""
    model = ball_model(stiffness=5e4, damping=0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator="euler", dt=5e-3)
    state = model.state()
    with pytest.raises(
        sb.SimulationError,
        match=r"body 0 blew up at step \d+ \(t = .* s\).*"
        r"exceeds the stable estimate",
    ) as info:
        sim.run(state, 10_000)
    assert info.value.body == 0 and info.value.step > 0
    assert np.all(np.isfinite(state.particle_q)) and np.all(np.isfinite(state.particle_qd))


def test_collapse_is_detected():
    """A ball with no gas and a strong inward pull collapses: the volume check stops it
    when V falls below 1e-3 of its rest volume and names the body."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.add_soft_body(
        sb.icosphere(1),
        mass=1.0,
        stiffness=0.0,
        damping=0.0,
        gas=sb.Gas.fixed_pressure(0.0, ambient_pressure=1e4),
    )
    model = builder.finalize()
    sim = sb.Simulator(model, integrator="rk4", dt=1e-4, max_speed=1e9)
    with pytest.raises(sb.SimulationError, match="body 0 blew up .*volume"):
        sim.run(model.state(), 100_000)


@pytest.mark.parametrize("integrator", ["midpoint", "symplectic_euler", "rk4", "implicit_euler"])
def test_auto_step_is_stable_and_lands_on_time(integrator):
    """dt="auto": the substep is 0.8 of the stability estimate at the current state (1/60 s
    at most, and for implicit Euler), so a user asking for a duration gets a stable run:
    30 frames of 1/30 s of the paper's bouncing balls end at t = 1 s exactly, round."""
    from softbody.scenes import load_scene
    from softbody.sim.simulator import AUTO_SAFETY, MAX_AUTO_DT

    model = load_scene("bouncing-balls").model
    sim = sb.Simulator(model, integrator=integrator, dt="auto")
    assert sim.dt == pytest.approx(min(MAX_AUTO_DT, AUTO_SAFETY * sim.stable_dt))
    state = model.state()
    for _ in range(30):
        sim.advance(state, 1 / 30)
        assert sim.dt <= AUTO_SAFETY * sim.stable_dt * 1.5 or integrator == "implicit_euler"
    assert state.time == pytest.approx(1.0, abs=1e-12)
    ratio = sb.body_volume(model, state) / model.body_rest_volume
    assert np.all((ratio > 0.8) & (ratio < 2.0))


def test_advance_with_fixed_dt_uses_no_longer_steps():
    """With a fixed dt, advance(duration) takes ceil(duration / dt) equal substeps."""
    model = two_masses()
    sim = sb.Simulator(model, integrator="rk4", dt=1e-3)
    state = model.state()
    sim.advance(state, 0.0105)
    assert state.step_count == 11 and state.time == pytest.approx(0.0105, abs=1e-15)
    assert sim.dt == 1e-3


@pytest.mark.parametrize(
    "integrator", ["euler", "midpoint", "rk4", "symplectic_euler", "velocity_verlet"]
)
def test_closed_form_radii_match_amplification_matrices(integrator):
    """step_radius (closed form over arrays) equals the largest |eigenvalue| of
    amplification_matrix on x'' = -w^2 x - 2 z w x', for random w h and z (seed 3)."""
    from softbody.stability import step_radius

    scheme = Integrator.parse(integrator)
    rng = np.random.default_rng(3)
    omega, zeta, h = rng.uniform(0.1, 3.0, 50), rng.uniform(0.0, 2.0, 50), 0.7
    radii = step_radius(scheme, h, omega**2, 2 * zeta * omega)
    expected = [
        np.abs(np.linalg.eigvals(amplification_matrix(scheme, h, w, z))).max()
        for w, z in zip(omega, zeta, strict=True)
    ]
    assert np.allclose(radii, expected, rtol=1e-12, atol=0)


@pytest.mark.parametrize(
    "integrator,growth",
    [
        ("euler", lambda z: np.sqrt(1 + z**2)),  # |1 + i z|
        ("midpoint", lambda z: np.sqrt(1 + z**4 / 4)),  # |1 + i z - z^2 / 2|
    ],
)
def test_euler_and_midpoint_estimates_bound_the_growth_of_undamped_modes(integrator, growth):
    """Euler and Midpoint amplify an undamped oscillation at any step, by |1 + i z| and
    |1 + i z - z^2 / 2| (z = w h); the estimate is the h where that equals
    exp(growth_rate h), found here by bisection on the closed form."""
    omega, rate = 100.0, 0.1
    h = largest_stable_step(
        Integrator.parse(integrator), 0.0, 0.0, omega_undamped=omega, growth_rate=rate
    )
    lo, hi = 1e-9, 1.0 / omega
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if growth(omega * mid) <= np.exp(rate * mid) else (lo, mid)
    assert h == pytest.approx(lo, rel=1e-6)


def _force_jacobians(model: sb.Model, q: np.ndarray, eps: float = 1e-6):
    """K = df/dx (central differences) and C = df/dv (exact: forces are linear in v),
    both (3N, 3N), at positions q and zero velocity."""
    from softbody import _core
    from softbody.core import core_model
    from softbody.sim.control import control_data

    core, c = core_model(model), control_data(model)
    n = 3 * model.particle_count

    def force(x, v):
        return _core.eval_forces(core, c, 0.0, x.reshape(-1, 3), v.reshape(-1, 3))[0].ravel()

    x0, v0 = q.ravel().copy(), np.zeros(n)
    base = force(x0, v0)
    stiffness, damping = np.zeros((n, n)), np.zeros((n, n))
    for a in range(n):
        e = np.zeros(n)
        e[a] = eps
        stiffness[:, a] = (force(x0 + e, v0) - force(x0 - e, v0)) / (2 * eps)
        e[a] = 1.0
        damping[:, a] = force(x0, v0 + e) - base
    return stiffness, damping


def _linear_step(integrator: str, h: float, accel_x: np.ndarray, accel_v: np.ndarray):
    """One step of ``integrator`` on x'' = A_x x + A_v x' as a (6N, 6N) matrix on (x, v)."""
    n = accel_x.shape[0]
    eye, zero = np.eye(n), np.zeros((n, n))
    if integrator in ("euler", "midpoint", "rk4"):
        a = np.block([[zero, eye], [accel_x, accel_v]])
        order = {"euler": 1, "midpoint": 2, "rk4": 4}[integrator]
        g, term = np.eye(2 * n), np.eye(2 * n)
        for p in range(1, order + 1):
            term = term @ (h * a) / p
            g = g + term
        return g
    if integrator == "symplectic_euler":
        v_x, v_v = h * accel_x, eye + h * accel_v
        return np.block([[eye + h * v_x, h * v_v], [v_x, v_v]])
    vh_x, vh_v = 0.5 * h * accel_x, eye + 0.5 * h * accel_v  # velocity Verlet
    x_x, x_v = eye + h * vh_x, h * vh_v
    return np.block(
        [
            [x_x, x_v],
            [
                vh_x + 0.5 * h * (accel_x @ x_x + accel_v @ vh_x),
                vh_v + 0.5 * h * (accel_x @ x_v + accel_v @ vh_v),
            ],
        ]
    )


def test_estimate_holds_for_the_linearised_paper_ball():
    """The paper's ball (162 vertices, k = 300 N/m, c = 0.5 N s/m, nRT = 40 J, as in
    bouncing-balls) linearised about its inflated rest state: M x'' = K x + C x'. At 0.99
    of each explicit scheme's estimate the step matrix has spectral radius at most
    exp(TOLERATED_GROWTH_RATE h), plus 1e-6 for the finite-difference Jacobian and the
    rigid motions' double eigenvalue 1. (Checking only the stiffest mode, as before, gave
    velocity Verlet a step 1.4x too long: spectral radius 1.5 there; its damped stiff
    mode is stable where less stiff, less damped ones grow.)"""
    from softbody.stability import TOLERATED_GROWTH_RATE

    model = ball_model(radius=0.32, stiffness=300.0, damping=0.5, gas=40.0)
    q = settle(model, dt=2e-4).particle_q
    stiffness, damping = _force_jacobians(model, q)
    inv_mass = np.repeat(model.particle_inv_mass, 3)[:, None]
    for integrator in ["euler", "midpoint", "rk4", "symplectic_euler", "velocity_verlet"]:
        h = 0.99 * sb.stable_dt(model, integrator, q)
        g = _linear_step(integrator, h, inv_mass * stiffness, inv_mass * damping)
        radius = np.abs(np.linalg.eigvals(g)).max()
        assert radius <= np.exp(TOLERATED_GROWTH_RATE * h) + 1e-6, (integrator, h, radius)


def test_velocity_verlet_at_its_estimate_damps_a_perturbed_ball():
    """The same ball at rest, kicked with random velocities of 1 mm/s (seed 0), at 0.95 of
    velocity Verlet's estimate: 3,000 steps later the fastest particle is slower than at
    the start (spring damping wins). At 1.2x the estimate the kick grows (the estimate
    holds a margin of sqrt(SPECTRAL_MARGIN) = 1.07 on the frequencies)."""
    model = ball_model(radius=0.32, stiffness=300.0, damping=0.5, gas=40.0)
    rest = settle(model, dt=2e-4)
    h = sb.stable_dt(model, "velocity_verlet", rest.particle_q)
    speeds = []
    for factor in (0.95, 1.2):
        state = sb.State(rest.particle_q.copy(), np.zeros_like(rest.particle_q))
        state.particle_qd[:] = np.random.default_rng(0).normal(0.0, 1e-3, state.particle_qd.shape)
        v0 = np.abs(state.particle_qd).max()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sb.StabilityWarning)
            sim = sb.Simulator(model, integrator="velocity_verlet", dt=factor * h)
        sim.run(state, 3000)
        speeds.append(np.abs(state.particle_qd).max() / v0)
    assert speeds[0] < 1.0 < speeds[1]


@pytest.mark.parametrize("subdivisions", [1, 2])
def test_spectral_bounds_are_the_linearised_balls_eigenvalues(subdivisions):
    """The paper's ball, settled, with one particle tied by a stretched damped spring to a
    point 0.3 m away: the largest eigenvalues of M^-1/2 (-K) M^-1/2 and M^-1/2 (-C) M^-1/2
    from finite-difference Jacobians of the force (dense; every spring is stretched, so
    the transverse stiffness k (1 - L0/L) is the |1 - L0/L| the bounds take) equal the
    spectral bounds' whole stiffness and damping rate: to 1e-9 for 42 vertices (solved
    densely) and to Lanczos' tolerance (LANCZOS_TOLERANCE) for 162. The whole is at most
    the damped and undamped parts' sum (Weyl), and the estimate uses SPECTRAL_MARGIN times
    these."""
    from softbody.stability import LANCZOS_TOLERANCE, spectral_bounds, stiffest_mode

    def ball(tied: bool) -> sb.Model:
        builder = sb.ModelBuilder(gravity=(0, 0, 0))
        mesh = sb.icosphere(subdivisions, radius=0.32)
        builder.add_soft_body(mesh, mass=1.0, stiffness=300.0, damping=0.5, gas=40.0)
        if tied:
            anchor = (0.0, 0.0, 0.62)
            builder.add_attachment(0, anchor, stiffness=50.0, damping=0.2, rest_length=0.05)
        return builder.finalize()

    q = settle(ball(False), dt=2e-4).particle_q  # the tied ball would swing for long
    model = ball(True)
    stiffness, damping = _force_jacobians(model, q)
    scale = np.repeat(np.sqrt(model.particle_inv_mass), 3)
    whole = np.linalg.eigvalsh(-scale[:, None] * stiffness * scale[None, :])[-1]
    rate = np.linalg.eigvalsh(-scale[:, None] * damping * scale[None, :])[-1]
    grad = np.zeros_like(q)
    tri = model.tri_indices
    normal = np.cross(q[tri[:, 1]] - q[tri[:, 0]], q[tri[:, 2]] - q[tri[:, 0]]) / 6.0
    for c in range(3):
        np.add.at(grad, tri[:, c], normal)
    volume = sb.body_volume(model, sb.State(q, np.zeros_like(q)))
    pressure = 40.0 / volume
    damped, undamped, total, damping_rate = spectral_bounds(
        model, q, pressure - model.body_ambient_pressure, -pressure / volume, grad
    )
    rel = 1e-9 if subdivisions == 1 else LANCZOS_TOLERANCE
    assert total == pytest.approx(whole, rel=max(rel, 1e-6))  # 1e-6: the difference step
    assert damping_rate == pytest.approx(rate, rel=rel)
    assert total <= (damped + undamped) * (1 + rel) ** 2  # Weyl
    mode = stiffest_mode(model, q)
    # the estimate takes the margin on these (its Gershgorin bounds are larger here)
    assert mode.omega**2 == pytest.approx(SPECTRAL_MARGIN * total, rel=1e-6)
    assert mode.damping_rate == pytest.approx(SPECTRAL_MARGIN * damping_rate, rel=1e-6)


@pytest.mark.parametrize("integrator", ["rk4", "symplectic_euler", "velocity_verlet"])
def test_estimate_is_tight_for_the_linearised_paper_ball(integrator):
    """The same linearised ball: at 1.15x the estimate some mode grows faster than the
    accepted rate, so the estimate is within 15% of the true limit (the margin is
    sqrt(SPECTRAL_MARGIN) = 1.07). Gershgorin bounds alone put it 1.2-1.7x too low here:
    the largest eigenvalue of a triangle mesh's spring matrix is about half their bound.
    (Not Euler and Midpoint: their estimate also covers undamped modes, which spring
    damping on every edge leaves this ball without.)"""
    from softbody.stability import TOLERATED_GROWTH_RATE

    model = ball_model(radius=0.32, stiffness=300.0, damping=0.5, gas=40.0)
    q = settle(model, dt=2e-4).particle_q
    stiffness, damping = _force_jacobians(model, q)
    inv_mass = np.repeat(model.particle_inv_mass, 3)[:, None]
    h = 1.15 * sb.stable_dt(model, integrator, q)
    g = _linear_step(integrator, h, inv_mass * stiffness, inv_mass * damping)
    radius = np.abs(np.linalg.eigvals(g)).max()
    assert radius > np.exp(TOLERATED_GROWTH_RATE * h) + 1e-6, (h, radius)


def test_pure_damper_limits_match_closed_form():
    """A damper without stiffness (k = 0, c = 2 N s/m) between 1 kg and 3 kg: the relative
    velocity obeys u' = -d u, d = c (1/m1 + 1/m2); one explicit step multiplies u by
    1 - h d (Euler, symplectic Euler), 1 - h d + (h d)^2 / 2 (Midpoint) or (1 - h d / 2)^2
    (velocity Verlet), stable to h d = 2, 2 and 4."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    i = builder.add_particle((0, 0, 0), mass=1.0)
    j = builder.add_particle((1, 0, 0), mass=3.0)
    builder.add_spring(i, j, stiffness=0.0, damping=2.0)
    model = builder.finalize()
    d = 2.0 * (1 + 1 / 3)
    limits = {"euler": 2, "symplectic_euler": 2, "midpoint": 2, "velocity_verlet": 4}
    for integrator, limit in limits.items():
        # the estimate accepts growth up to 1e-3 of the mode's rate: 0.1% past the limit
        assert sb.stable_dt(model, integrator) == pytest.approx(limit / d, rel=2e-3)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "velocity_verlet", "rk4"])
def test_step_radius_is_accurate_at_small_steps(integrator):
    """An overdamped oscillator (omega = 1, d = 16 /s) is stable under these schemes for
    every step from 1e-10 s to 0.1 s: the amplification's eigenvalues are real, in (0, 1)
    (e.g. 1 - h d + O(h^2)), so the computed spectral radius must not exceed 1. The
    textbook discriminant trace^2 / 4 - det cancels to rounding at small h (radius
    1 + 9e-9 at h = 1e-9 s), which made the estimate's scan reject tiny steps: 2e-22 s
    for symplectic Euler on a 40,962-vertex ball whose step is 8e-6 s."""
    h = np.geomspace(1e-10, 1e-1, 200)
    radius = step_radius(Integrator.parse(integrator), h, 1.0, 16.0)
    assert radius.max() <= 1.0


def _split_cases():
    """The every-term model with its control (a grab spring, an attachment, each gas law),
    and a balloon of neo-Hookean membrane with material bending and springs under a
    pressure schedule; each scaled by 1.1 (every spring and attachment stretched) and
    moved at random by 1 mm."""
    from trajectory_cases import every_term_model

    model, control = every_term_model()
    b = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    b.add_soft_body(sb.icosphere(1, radius=0.2), mass=0.05, stiffness=50.0, damping=0.1,
                    gas=sb.Gas.isothermal(60.0), bending=sb.Bending(0.02),
                    membrane=sb.Membrane.neo_hookean(3e4, 1e-3, damping=2e-3))  # fmt: skip
    balloon = b.finalize()
    return {"every-term": (model, control), "membrane-bending": (balloon, balloon.control())}


@pytest.mark.parametrize("name", ["every-term", "membrane-bending"])
def test_spectral_parts_split_the_implicit_product(name):
    """softbody._core.SpectralOperator's four parts against the implicit schemes' product
    (softbody._core.apply_jacobians, its gas linearisation given as the estimate's), for
    random p at a state where every spring and attachment is stretched (there the
    transverse k |1 - L0/L| is the implicit product's k max(0, 1 - L0/L)): the whole part
    is K p and the damping part C p, to 1e-12 of their largest entry (the springs'
    direction is d / L there, d times 1 / L in the implicit product); the damped and
    undamped parts add up to the whole, except for a term that does not split its
    Jacobian (the grab spring), which counts whole in each: damped + undamped - whole is
    the grab's -k p on its particle. An unknown part is refused naming the parts."""
    from softbody import _core
    from softbody.core import core_model
    from softbody.sim.control import control_data

    model, control = _split_cases()[name]
    data = control.write(model, control_data(model))
    rng = np.random.default_rng(4)
    q = 1.1 * model.particle_q + rng.uniform(-1e-3, 1e-3, model.particle_q.shape)
    pieces = _core.stiffness_bounds(core_model(model), data, q)
    pnet, dpdv = pieces["body_pnet"], pieces["body_dpdv"]
    gradient = pieces["volume_gradient"]
    operator = _core.SpectralOperator(core_model(model), data, q, pnet, dpdv, gradient)
    gas = {"gas": np.concatenate([dpdv, pnet])}
    for _ in range(2):
        p = rng.normal(size=q.shape)
        parts = [np.zeros_like(q) for _ in range(4)]
        for k, out in enumerate(parts):
            operator.apply(k, p, out)
        damped, undamped, whole, damping = parts
        kp, cp = np.zeros_like(q), np.zeros_like(q)
        _core.apply_jacobians(core_model(model), data, q, p, 0.0, 0.0, 1.0, kp,
                              linearization=gas, volume_gradient=gradient)  # fmt: skip
        _core.apply_jacobians(core_model(model), data, q, p, 0.0, 1.0, 0.0, cp,
                              linearization=gas, volume_gradient=gradient)  # fmt: skip
        np.testing.assert_allclose(whole, kp, rtol=0, atol=1e-12 * np.abs(kp).max())
        np.testing.assert_allclose(damping, cp, rtol=0, atol=1e-12 * np.abs(cp).max())
        grab = np.zeros_like(q)
        if data.grab_particle >= 0:
            grab[data.grab_particle] = -data.grab_stiffness * p[data.grab_particle]
        np.testing.assert_allclose(damped + undamped - whole, grab, rtol=0,
                                   atol=1e-12 * np.abs(kp).max())  # fmt: skip
        assert np.abs(damped).max() > 0 and np.abs(undamped).max() > 0
    with pytest.raises(ValueError, match="part must be 0"):
        operator.apply(4, p, parts[0])
