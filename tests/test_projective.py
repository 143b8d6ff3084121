"""Projective dynamics: its fixed point is backward Euler, it holds the closed-form
equilibria, stays stable at large steps with the gas explicit, and sags at rest with
few iterations. Momentum, energy and the built-in scenes: test_implicit (``SOLVED``)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import softbody as sb
from conftest import ball_model, uniform_scaling_stationary
from softbody import _core
from softbody.core import core_model
from softbody.sim.control import control_data
from test_implicit import assert_explicit_euler_blows_up, centre_heights, dropped_stiff_ball


def _forces(sim, state, t=0.0):
    """f(x, v) [N] (N, 3) with the library's own force terms."""
    model = sim.model
    q, qd = state.particle_q, state.particle_qd
    return _core.eval_forces(core_model(model), control_data(model), t, q, qd)[0]


def test_fixed_point_is_backward_euler():
    """Backward Euler: M (x1 - x0 - h v0) / h^2 = f(x1, (x1 - x0) / h). The residual of
    that equation, with this library's spring, damper, gravity and pressure forces, falls
    geometrically with the local-global iterations, to round-off (1e-9 of the force
    scale) after 400 of them: the iterations converge to backward Euler itself."""
    model = ball_model(subdivisions=1, stiffness=200.0, damping=0.5, gravity=(0.0, -9.81, 0.0))
    start = model.state()
    rng = np.random.default_rng(11)
    start.particle_qd[:] = rng.normal(scale=0.5, size=start.particle_qd.shape)
    h = 1e-2
    m = model.particle_mass[:, None]
    residuals = []
    for iterations in (1, 4, 16, 400):
        sim = sb.Simulator(model, integrator="projective", dt=h, projective_iterations=iterations)
        state = start.copy()
        sim.run(state, 1)
        inertia = m * (state.particle_q - start.particle_q - h * start.particle_qd) / h**2
        residual = inertia - _forces(sim, state, h)
        residuals.append(np.abs(residual).max() / np.abs(inertia).max())
    assert residuals[0] > 1e-3  # one iteration is not converged: the test can tell
    assert residuals[1] < residuals[0] and residuals[2] < residuals[1]
    assert residuals[3] < 1e-9


def test_icosahedron_settles_at_uniform_scaling_equilibrium():
    """Equilibrium is a fixed point of every local-global iteration (y = x0 there, and
    the projections then reproduce the spring forces that balance the gas), so even at
    dt = 25 ms (its gas limit is 27 ms) with two iterations the icosahedron settles where
    1/2 k (s-1)^2 sum L0^2 - nRT ln(s^3 V0) is stationary, to 1e-9."""
    k, nrt = 200.0, 150.0
    model = ball_model(subdivisions=0, stiffness=k, damping=4.0, gas=nrt)
    sim = sb.Simulator(model, integrator="projective", dt=0.025, projective_iterations=2)
    state = model.state()
    sim.run(state, 2000)
    s = uniform_scaling_stationary(k, model.spring_rest_length, nrt)
    scale = (sb.body_volume(model, state)[0] / model.body_rest_volume[0]) ** (1 / 3)
    assert scale == pytest.approx(s, rel=1e-9)


@pytest.mark.parametrize("scene", ["bouncing-balls", None])
def test_factor_solves_the_global_matrix_with_less_fill(scene):
    """Reference: the factorisation's definition, A = P^T L D L^T P, so two triangular
    solves invert the global matrix A (system_matrix) to round-off (relative residual
    1e-12 here; A's condition numbers are 132 and 4,766), the five separate balls and a
    2,562-vertex ball with a pinned vertex (an identity row). The nested-dissection order
    is a permutation and, on that ball, leaves fewer entries in L than the natural
    (Morton) order, by more than half, and than SuperLU's minimum degree order."""
    import scipy.sparse.linalg as spla

    from softbody.scenes.loader import load_scene
    from softbody.solvers.factor import build_projective, dissection_order, system_matrix

    if scene:
        model = load_scene(scene).model
    else:
        builder = sb.ModelBuilder()
        builder.add_soft_body(
            sb.icosphere(4), mass=1.0, stiffness=500.0, damping=0.5, gas=300.0, pinned=[0]
        )
        model = builder.finalize()
    dt = 1.0 / 60.0
    factored = build_projective(model, dt)
    a = system_matrix(model, dt)
    b = np.random.default_rng(3).standard_normal((model.particle_count, 3))
    x = _core.solve_factor(core_model(model), factored, b)
    assert np.linalg.norm(a @ x - b) <= 1e-12 * np.linalg.norm(b)
    order = dissection_order(a.tocsr(), model.particle_q)
    np.testing.assert_array_equal(np.sort(order), np.arange(model.particle_count))
    if scene is None:
        options = {"diag_pivot_thresh": 0.0, "options": {"SymmetricMode": True}}
        natural = spla.splu(a.tocsc(), permc_spec="NATURAL", **options).L.nnz
        minimum_degree = spla.splu(a.tocsc(), permc_spec="MMD_AT_PLUS_A", **options).L.nnz
        # SuperLU's L counts its unit diagonal; factor_nonzeros does not
        n = model.particle_count
        assert factored.factor_nonzeros < 0.5 * (natural - n)
        assert factored.factor_nonzeros < minimum_degree - n


def test_hanging_particles_rest_at_hookes_extension():
    """A particle hanging from a pinned particle by a spring, and another from an
    attachment, both damped, come to rest where k (L - L0) = m g: L = L0 + m g / k below
    their supports (to 1e-9 m); the pinned particle does not move."""
    g, k, mass, rest = 9.81, 40.0, 0.2, 0.5
    builder = sb.ModelBuilder(gravity=(0.0, -g, 0.0))
    top = builder.add_particle((0.0, 0.0, 0.0), mass=1.0, pinned=True)
    low = builder.add_particle((0.0, -0.3, 0.0), mass=mass)
    builder.add_spring(top, low, stiffness=k, damping=0.5, rest_length=rest)
    hung = builder.add_particle((2.0, -0.2, 0.0), mass=mass)
    builder.add_attachment(hung, (2.0, 0.0, 0.0), stiffness=k, damping=0.5, rest_length=rest)
    model = builder.finalize()
    sim = sb.Simulator(model, integrator="projective", dt=1 / 60, projective_iterations=2)
    state = model.state()
    sim.run(state, 1200)
    drop = rest + mass * g / k
    assert np.allclose(state.particle_q[top], (0.0, 0.0, 0.0), rtol=0, atol=0)
    assert np.allclose(state.particle_q[low], (0.0, -drop, 0.0), rtol=0, atol=1e-9)
    assert np.allclose(state.particle_q[hung], (2.0, -drop, 0.0), rtol=0, atol=1e-9)


def test_stable_at_a_sixtieth_of_a_second_where_explicit_euler_blows_up():
    """The stiff ball of the implicit tests (w dt ~ 52 at 1/60 s): explicit Euler blows
    up, projective dynamics with two iterations runs 2 s with the ball never above its
    drop height (restitution 0.3) and on or above the ground. Its step limit is the
    gas's volume mode, 1 / omega_gas, longer than 1/60 s here, so no warning. (Its volume
    at rest is another matter: see the next test.)"""
    model = dropped_stiff_ball()
    assert_explicit_euler_blows_up(model)
    with warnings.catch_warnings():
        warnings.simplefilter("error", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator="projective", dt=1 / 60)
    assert sim.stable_dt == pytest.approx(1.0 / sim.stiffest_mode.omega_gas)
    assert 1 / 60 < sim.stable_dt < float("inf")
    state = model.state()
    start, heights = centre_heights(model, sim, state)
    assert max(heights) <= start
    assert state.particle_q[:, 1].min() >= 0.0


def test_resting_ball_sags_less_with_more_iterations():
    """A few local-global iterations leave the ball's slow, global modes soft (the stiff
    springs' rotations converge slowly): the stiff ball resting on the ground after
    its 2 s drop sags, its centre of mass below backward Euler's one radius (within 2%,
    test_implicit). More iterations converge to backward Euler, so the resting height
    rises with them: about 0.46 m at 2 iterations, 0.74 m at 10, 0.86 m at 40."""
    model = dropped_stiff_ball()
    heights = []
    for iterations in (2, 10, 40):
        sim = sb.Simulator(
            model, integrator="projective", dt=1 / 60, projective_iterations=iterations
        )
        state = model.state()
        sim.run(state, 120)
        heights.append(sb.body_center_of_mass(model, state)[0, 1])
    assert heights[0] < heights[1] < heights[2] < 1.0
    assert heights[0] < 0.6 and heights[2] > 0.8


def test_too_long_a_step_for_the_gas_is_flagged():
    """A ball with soft springs (k = 5 N/m) and a stiff gas: past 1 / omega_gas the
    explicit gas term makes the iteration diverge; the simulator warns at construction."""
    model = ball_model(stiffness=5.0, gas=sb.Gas.isothermal(3000.0), mass=0.01)
    with pytest.warns(sb.StabilityWarning, match="projective"):
        sim = sb.Simulator(model, integrator="projective", dt=0.05)
    assert sim.stable_dt < 0.05


def test_bad_iteration_counts():
    """projective_iterations must be an integer >= 1: zero, negatives, fractions, booleans
    and strings are ValueErrors."""
    model = ball_model()
    for bad in (0, -1, 1.5, True, "2"):
        with pytest.raises(ValueError, match="projective_iterations must be an integer >= 1"):
            sb.Simulator(model, integrator="projective", dt=1e-2, projective_iterations=bad)


@pytest.mark.parametrize("subdivisions", [3, 4])
def test_dissection_order_is_the_one_it_always_was(subdivisions):
    """The nested-dissection order, computed by the compiled core since its set-up left
    Numba, is the same permutation the Numba version gave on the ball drop's ball (saved
    in tests/data by that version): the factors, their fill and the runs are unchanged.
    Bad patterns are ValueErrors, not reads out of bounds."""
    import sys
    from pathlib import Path

    from softbody.solvers.factor import dissection_order, system_matrix

    sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
    from ball_drop import ball_drop

    model = ball_drop(subdivisions)
    n = model.particle_count
    expected = np.load(Path(__file__).parent / "data" / f"dissection-order-ball-{n}.npy")
    order = dissection_order(system_matrix(model, 1.0 / 60.0).tocsr(), model.particle_q)
    np.testing.assert_array_equal(order, expected)
    indptr, indices = np.array([0, 1, 2], dtype=np.int64), np.array([1, 2], dtype=np.int64)
    with pytest.raises(ValueError, match="pattern indices holds 2"):
        _core.plan_dissection_order(indptr, indices, np.zeros((2, 3)), 8)
    with pytest.raises(ValueError, match="strictly lower triangular"):
        _core.plan_supernodes(indptr, np.array([0, 1], dtype=np.int64), np.ones(2))


def test_every_projected_term_gives_its_part_of_the_matrix():
    """The global matrix's parts (softbody.solvers.factor.MATRIX_PARTS) are exactly the
    core's projected terms (those whose projection stands for their force in projective
    dynamics, softbody._core.term_table), in the registry's order: a projected term
    without a part would leave its stiffness out of the factor."""
    from softbody import _core
    from softbody.solvers.factor import MATRIX_PARTS

    projected = [t["name"] for t in _core.term_table() if t["projected"]]
    assert list(MATRIX_PARTS) == projected
