"""The compiled core's implicit schemes (backward Euler, BDF2; CG with the multigrid V-cycle
or Jacobi): the two preconditioners solve the same system, hash growth, and the core's
checks of the multigrid hierarchy at the Python boundary. tests/test_implicit.py and
tests/test_multigrid.py validate the solvers against closed forms, test_trajectories
against the reference trajectories.

Two runs that solve the same systems with different preconditioners (or from different
CG starting points) stop CG at different iterates, so they are compared within what the
CG tolerance allows: both stop at a residual ||r|| <= tol ||b||, so their
velocity changes differ by at most ||A^-1|| 2 tol ||b||; with A = M - h C - h^2 K >= M (the
springs' -K and -C are positive semi-definite; the gas's indefinite part is small at these
steps) and ||b|| = ||A dv|| <= ||A|| ||dv||, that is 2 tol kappa ||dv||_2 at most, and in
practice (A's largest eigenvalues barely excited) 2 tol ||dv||_2 / m_min * m_max. Summed
over the run (backward Euler and BDF2 do not amplify an error), the velocity bound is
2 tol sum_n ||v_n+1 - v_n||_2 (equal masses), times 10 for the conditioning, and the
position bound dt times its running sum. A wrong term or a wrong history gives errors of
dt times a force, orders of magnitude above it at tol = 1e-10.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import softbody as sb
from conftest import ball_model
from softbody import _core
from softbody.core import core_model
from softbody.sim.control import control_data
from softbody.solvers.base import RunLimits
from softbody.solvers.multigrid import build_multigrid, set_multigrid_step

IMPLICIT = ["implicit_euler", "bdf2"]
PRECONDITIONERS = ["multigrid", "jacobi"]
CG_TOLERANCE = 1e-10


def _pinned_grabbed_ball() -> tuple[sb.Model, sb.Control]:
    """A falling ball with bending springs, pinned at its top, tied to an anchor by a slack
    attachment and pulled by a grab spring: every term of the implicit system's matrix."""
    b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    mesh = sb.icosphere(2, radius=0.5, center=(0.0, 1.0, 0.0))
    top = np.flatnonzero(mesh.vertices[:, 1] > 1.45)
    b.add_soft_body(mesh, mass=1.0, stiffness=400.0, damping=0.4, gas=40.0, pinned=top,
                    bend_stiffness=2.0)  # fmt: skip
    side = int(np.argmax(mesh.vertices[:, 0]))
    b.add_attachment(side, (1.0, 1.0, 0.0), stiffness=50.0, damping=0.2, rest_length=0.2)
    model = b.finalize()
    control = model.control()
    control.grab_particle = int(np.argmin(mesh.vertices[:, 1]))
    control.grab_target = np.array([0.2, 0.3, 0.0])
    control.grab_stiffness, control.grab_damping = 30.0, 0.5
    return model, control


def _dropped_on_cloth() -> tuple[sb.Model, sb.Control | None]:
    """Contacts: a ball dropped at 3 m/s on a cloth pinned at its corners (surface soft
    contacts through the spatial hash), over a ground plane. The first 40 steps of 1/240 s:
    at step 55 a ball vertex meets the cloth at a near tie, where a 1e-15 m nudge of the
    state changes its velocity by 0.2 m/s in the Numba solver alone, so no comparison can
    run past it."""
    b = sb.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    b.set_soft_contact("surface", restitution=0.5, friction=0.3)
    b.add_cloth(sb.rectangle((1.0, 1.0), (8, 8)), mass=2.0, stiffness=2000.0, damping=0.5,
                pinned=[0, 8, 72, 80])  # fmt: skip
    b.add_soft_body(sb.icosphere(2, radius=0.25, center=(0.05, -0.03, 0.27)), mass=1.0,
                    stiffness=400.0, damping=0.5, gas=40.0, velocity=(0.0, 0.0, -3.0))  # fmt: skip
    b.add_collider(sb.ColliderPlane(point=(0.0, 0.0, -0.5), normal=(0.0, 0.0, 1.0),
                                    restitution=0.3, friction=0.2))  # fmt: skip
    return b.finalize(), None


SCENES = {"pinned-grabbed-ball": (_pinned_grabbed_ball, 1 / 60, 40),
          "ball-on-cloth": (_dropped_on_cloth, 1 / 240, 40)}  # fmt: skip


def _simulator(model, integrator, dt, preconditioner):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        return sb.Simulator(model, integrator=integrator, dt=dt, implicit_tolerance=CG_TOLERANCE,
                            implicit_max_iterations=2000,
                            implicit_preconditioner=preconditioner)  # fmt: skip


def _trajectory(model, control, integrator, dt, steps, preconditioner):
    """The run one step per call (BDF2's history carries over), with the CG statistics of
    each step and sum_n ||v_n+1 - v_n||_2."""
    sim = _simulator(model, integrator, dt, preconditioner)
    state = model.state()
    iterations, dv_sum = [], 0.0
    for _ in range(steps):
        before = state.particle_qd.copy()
        sim.run(state, 1, control)
        iterations.append(sim.solver_iterations[1])
        dv_sum += float(np.linalg.norm(state.particle_qd - before))
    return state, np.array(iterations), dv_sum


@pytest.mark.parametrize("scene", list(SCENES))
@pytest.mark.parametrize("integrator", IMPLICIT)
def test_both_preconditioners_give_the_same_run(integrator, scene):
    """Multigrid and Jacobi precondition the same system, so positions and velocities
    agree within the CG-tolerance bound of the module docstring, step by step, with every
    term of the matrix (pins, bending springs, an attachment, a grab) or surface
    contacts; and the contacts act (the ball is far from free fall)."""
    build, dt, steps = SCENES[scene]
    model, control = build()
    a, its_a, _ = _trajectory(model, control, integrator, dt, steps, "multigrid")
    b, its_b, dv_sum = _trajectory(model, control, integrator, dt, steps, "jacobi")
    tol_v = 10 * 2 * CG_TOLERANCE * dv_sum + 1e-12
    tol_q = dt * steps * tol_v
    np.testing.assert_allclose(a.particle_qd, b.particle_qd, rtol=0, atol=tol_v)
    np.testing.assert_allclose(a.particle_q, b.particle_q, rtol=0, atol=tol_q)
    assert a.step_count == b.step_count == steps
    assert its_a.max() < its_b.max()  # the V-cycle does precondition
    if scene == "ball-on-cloth":
        ball = slice(*model.body_particle_range[-1])
        mass = model.particle_mass[ball]
        start = (mass * model.particle_qd[ball, 2]).sum()
        end = (mass * b.particle_qd[ball, 2]).sum()
        assert abs(end - (start + mass.sum() * model.gravity[2] * b.time)) > 0.1 * abs(start)


def test_core_v_cycle_is_a_symmetric_positive_operator():
    """The V-cycle (forward sweeps down, backward up, exact coarse solve) is symmetric and
    positive definite: u . V(w) = w . V(u) to round-off (1e-12 relative) and u . V(u) > 0,
    for random u, w, on a 642-vertex ball (two levels and a dense coarse solve)."""
    model = ball_model(subdivisions=3, stiffness=500.0, damping=0.5)
    mg = build_multigrid(model)
    set_multigrid_step(mg, 1 / 60)
    rng = np.random.default_rng(11)
    u, w = rng.normal(size=(2, model.particle_count, 3))
    vu = _core.apply_multigrid(core_model(model), mg, u)
    vw = _core.apply_multigrid(core_model(model), mg, w)
    assert abs(np.vdot(u, vw) - np.vdot(w, vu)) <= 1e-12 * abs(np.vdot(u, vw))
    assert np.vdot(u, vu) > 0.0


def test_core_implicit_hash_growth_gives_the_same_run():
    """Implicit Euler from a 1-entry contact hash: the core grows the hash at the first
    contact and goes on with the same solver (its warm start kept), so the run equals one
    with the default room to the last bit."""
    model, _ = _dropped_on_cloth()
    big, _, _ = _trajectory(model, None, "implicit_euler", 1 / 240, 60, "multigrid")
    sim = _simulator(model, "implicit_euler", 1 / 240, "multigrid")
    sim.solver.start_hash(1)
    core = sim.solver._core
    small = model.state()
    sim.run(small, 60)
    assert sim.solver._core is core and core.hash_capacity > 1
    assert big.step_count == small.step_count == 60
    np.testing.assert_array_equal(small.particle_qd, big.particle_qd)
    np.testing.assert_array_equal(small.particle_q, big.particle_q)


def _bad(mg, **changes):
    return mg._replace(**changes)


def test_the_core_refuses_an_inconsistent_multigrid_hierarchy():
    """A hierarchy that does not fit the model, or whose offsets, CSR rows or indices point
    outside its arrays, is a ValueError naming the array before any kernel runs."""
    model = ball_model(subdivisions=3)
    core = core_model(model)
    mg = build_multigrid(model)
    set_multigrid_step(mg, 1 / 60)
    other = build_multigrid(ball_model(subdivisions=2))
    with pytest.raises(ValueError, match=r"level_size\[0\] must be the particle count"):
        _core.ImplicitSolver(core, multigrid=other)
    springs = mg.stencils["springs"]

    def bad_springs(**changes):
        return _bad(mg, stencils={**mg.stencils, "springs": springs._replace(**changes)})

    cases = {
        "stencil springs neighbor": bad_springs(neighbor=springs.neighbor + model.particle_count),
        "springs: map holds a bad spring": bad_springs(map=springs.map - model.spring_count),
        "vec_offset": _bad(mg, vec_offset=mg.vec_offset + 1),
        "A level 0 columns": _bad(mg, a_indices=mg.a_indices * 1000),
        "P level 0": _bad(mg, p_nz_offset=mg.p_nz_offset + len(mg.p_indices)),
        "a_diag must have shape": _bad(mg, a_diag=mg.a_diag[:-1]),
        "coarse_cholesky must have shape": _bad(mg, coarse_cholesky=np.zeros((2, 2))),
        "stencil springs ptr": bad_springs(ptr=springs.ptr[::-1].copy()),
        "stencil membrane is missing": _bad(mg, stencils={"springs": springs}),
    }
    for what, bad in cases.items():
        with pytest.raises(ValueError, match=what):
            _core.ImplicitSolver(core, multigrid=bad)
    with pytest.raises(ValueError, match="multigrid"):
        _core.apply_multigrid(core, cases["stencil springs neighbor"],
                              np.zeros((model.particle_count, 3)))  # fmt: skip
    solver = _core.ImplicitSolver(core, multigrid=mg)
    state = model.state()
    state.conform(model)  # the core takes a state that has met its model (its gas set)
    args = (control_data(model), state, RunLimits(1e4, 1e-3, 1e3))
    with pytest.raises(ValueError, match="tolerance must lie in"):
        solver.simulate(False, 1, 1 / 60, *args, 0.0, 10, False)
    with pytest.raises(ValueError, match="max_iterations must be >= 1"):
        solver.simulate(False, 1, 1 / 60, *args, 1e-6, 0, False)
    assert solver.simulate(False, 2, 1 / 60, *args, 1e-6, 50, False)[:2] == (0, 2)
    assert state.step_count == 2 and state.time == pytest.approx(2 / 60)
    steps, total, most = solver.cg_stats
    assert steps == 2 and 0 < most <= total <= 100
    solver.clear_stats()
    assert solver.cg_stats == (0, 0, 0)
