"""Projective dynamics in the compiled C++ core: its instruction-set paths, hash growth,
factor cache, and its checks of the factor it is given. test_trajectories holds its runs
to the reference trajectories; test_projective validates it against backward Euler and
closed forms.
"""

from __future__ import annotations

import warnings
from types import SimpleNamespace

import numpy as np
import pytest

import softbody as sb
from conftest import ball_model
from softbody import _core, core
from softbody.core import core_model
from softbody.sim.control import control_data
from softbody.solvers.base import RunLimits
from softbody.solvers.factor import build_projective
from trajectory_cases import surface_model

STEPS = 60


def _sim(model, dt, *, iterations=2):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator="projective", dt=dt, projective_iterations=iterations)
    assert isinstance(sim.solver._core, _core.ProjectiveSolver)
    return sim


def _run(model, dt, *, steps=STEPS, control=None, iterations=2):
    sim = _sim(model, dt, iterations=iterations)
    state = model.state()
    error = None
    try:
        sim.run(state, steps, control)
    except sb.SimulationError as e:
        error = str(e)
    return state, error


def _pinned_attached_ball() -> tuple[sb.Model, sb.Control]:
    """A ball hanging from two attachments, with two pinned vertices driven to targets, a
    grab, an external force, under gravity."""
    b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    b.add_soft_body(sb.icosphere(2, radius=0.3, center=(0.0, 1.0, 0.0)), mass=1.0,
                    stiffness=2000.0, damping=1.0, gas=40.0, pinned=[0, 7])  # fmt: skip
    b.add_attachment(3, anchor=(0.0, 1.6, 0.0), stiffness=200.0, damping=2.0)
    b.add_attachment(11, anchor=(0.2, 1.5, 0.1), stiffness=150.0, damping=1.0, rest_length=0.1)
    model = b.finalize()
    control = model.control()
    control.particle_f[20] = (0.0, 1.0, 0.5)
    control.grab_particle = 30
    control.grab_target = np.array([0.5, 1.2, 0.0])
    control.grab_stiffness, control.grab_damping = 30.0, 0.5
    control.pin_target = model.particle_q[model.pin_particle] + (0.0, 0.05, 0.0)
    return model, control


def test_every_instruction_set_gives_the_same_run():
    """The scalar, AVX2 and AVX-512 builds (those this CPU runs) step projective dynamics
    alike: the scalar path sums dV/dx face by face, the SIMD paths particle by particle
    (vertex-major), so they agree to round-off (1e-12 of the motion's scale per step), and
    the two SIMD paths, with one summation order, to the last bit."""
    model, control = _pinned_attached_ball()
    before = core.simd_path()
    runs = {}
    try:
        for name in core.simd_paths():
            core.use_simd(name)
            runs[name] = _run(model, 1 / 120, control=control, steps=30)[0]
    finally:
        core.use_simd(before)
    for state in runs.values():
        np.testing.assert_allclose(state.particle_q, runs["scalar"].particle_q, rtol=0,
                                   atol=30 * 1e-12)  # fmt: skip
        np.testing.assert_allclose(state.particle_qd, runs["scalar"].particle_qd, rtol=0,
                                   atol=30 * 1e-10)  # fmt: skip
    simd = [runs[name] for name in runs if name != "scalar"]
    for state in simd[1:]:
        np.testing.assert_array_equal(state.particle_q, simd[0].particle_q)


def test_a_too_small_contact_hash_grows_and_gives_the_same_run():
    """Surface contacts with a 1-entry hash: the core grows it inside the run (the same
    solver and factor go on), and the run equals one with the default room to the last
    bit."""
    model = surface_model(cloth=False)
    runs = []
    for small in (False, True):
        sim = _sim(model, 5e-4)
        if small:
            sim.solver.start_hash(1)
        state = model.state()
        sim.run(state, 100)
        runs.append((state, sim))
    (big, big_sim), (small, small_sim) = runs
    assert big_sim.solver._core.hash_capacity == 8 * model.tri_count
    assert small_sim.solver._core.hash_capacity > 1
    assert small_sim.solver._core.factor is small_sim.solver.factor(5e-4)
    np.testing.assert_array_equal(small.particle_q, big.particle_q)
    np.testing.assert_array_equal(small.particle_qd, big.particle_qd)


def test_a_new_step_size_gets_its_own_factor():
    """advance() with substeps of another size: the solver is given the factor built for
    that dt (the core refuses a factor of another dt), and the run is the same as a
    simulator made with that dt from the start, bit for bit."""
    model = ball_model(stiffness=2000.0, damping=1.0, gravity=(0.0, -9.81, 0.0))
    sim = _sim(model, 1 / 60)
    state = model.state()
    sim.run(state, 3)
    sim.advance(state, 0.01)  # one substep of 0.01 s
    assert sim.solver._core.factor.dt == 0.01
    other = _sim(model, 1 / 60)
    ref = model.state()
    other.run(ref, 3)
    other.dt = 0.01
    other.run(ref, 1)
    np.testing.assert_array_equal(state.particle_q, ref.particle_q)


def _solver_and_state(model, dt):
    solver = _core.ProjectiveSolver(core_model(model))
    solver.set_factor(build_projective(model, dt))
    return solver, model.state()


def test_the_core_refuses_a_bad_factor_or_call():
    """A factor of another model, a wrong dt, or one whose structure would send the solves
    out of their arrays are ValueErrors naming the problem, before any kernel runs."""
    model = ball_model(subdivisions=1)
    dt = 1e-2
    good = build_projective(model, dt)
    solver = _core.ProjectiveSolver(core_model(model))
    state = model.state()
    args = (control_data(model), state, RunLimits(1e4, 1e-3, 1e3))
    with pytest.raises(ValueError, match="no projective factor set"):
        solver.simulate(1, dt, 2, *args)
    with pytest.raises(ValueError, match="has size 162 for a model of 42 particles"):
        solver.set_factor(build_projective(ball_model(subdivisions=2), dt))
    solver.set_factor(good)
    assert solver.factor is good
    with pytest.raises(ValueError, match="built for dt = 0.01"):
        solver.simulate(1, 2e-2, 2, *args)
    with pytest.raises(ValueError, match="iterations must be >= 1"):
        solver.simulate(1, dt, 0, *args)
    perm = good.perm.copy()
    perm[0] = perm[1]
    with pytest.raises(ValueError, match="perm is not a permutation"):
        solver.set_factor(good._replace(perm=perm))
    perm[0] = model.particle_count
    with pytest.raises(ValueError, match="perm holds 42 at 0"):
        solver.set_factor(good._replace(perm=perm))
    rows = good.node_row.copy()
    last = good.node_row_ptr[-1] - 1
    rows[last] = model.particle_count  # below the last node: no such row
    with pytest.raises(ValueError, match="rows must be its columns, then rows below"):
        solver.set_factor(good._replace(node_row=rows))
    with pytest.raises(ValueError, match="node_value_ptr must run from 0 to at most"):
        solver.set_factor(good._replace(node_value=good.node_value[:-1]))
    value_ptr = good.node_value_ptr.copy()
    value_ptr[1] += 1
    with pytest.raises(ValueError, match="values are not a"):
        solver.set_factor(good._replace(node_value_ptr=value_ptr))
    with pytest.raises(ValueError, match="node_col must run from 0 to 42"):
        solver.set_factor(good._replace(node_col=good.node_col[:-1],
                                        node_row_ptr=good.node_row_ptr[:-1],
                                        node_value_ptr=good.node_value_ptr[:-1]))  # fmt: skip
    with pytest.raises(ValueError, match="inv_diag must be a C-contiguous float64 array"):
        solver.set_factor(good._replace(inv_diag=good.inv_diag.astype(np.float32)))
    assert solver.factor is good  # a refused factor leaves the last good one
    with pytest.raises(ValueError, match="q must be a writable"):
        bad = SimpleNamespace(**vars(state))  # a State would refuse the shape itself
        bad.particle_q = state.particle_q[:, :2]
        solver.simulate(1, dt, 2, args[0], bad, args[2])
