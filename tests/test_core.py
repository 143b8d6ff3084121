"""The compiled C++ core: its instruction-set paths against each other, the surface
contacts' hash growth, its checks at the Python boundary, and a start that compiles
nothing. test_trajectories holds its runs to the reference trajectories, test_reference
its terms to their NumPy forms.

The scalar path sums each spring's and face's terms per spring and face, the SIMD paths
per particle (vertex-major), with the same operations (no FMA contraction, no
reassociation), so the paths differ in their last bits; the tolerance allows that
round-off to grow over the run (1e-12 relative to the motion's scale per step).
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
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
from trajectory_cases import every_term_model, surface_model

EXPLICIT = ["euler", "midpoint", "rk4", "symplectic_euler", "velocity_verlet"]
STEPS = 150


def _run(model, integrator, dt, *, steps=STEPS, control=None, state=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state() if state is None else state
    error = None
    try:
        sim.run(state, steps, control)
    except sb.SimulationError as e:
        error = str(e)
    return state, error


def _tolerance(state, steps):
    scale = max(1.0, float(np.abs(state.particle_q).max()))
    return 1e-12 * scale * steps


def _surface_run(small_hash: bool) -> tuple[sb.State, sb.Simulator]:
    """150 midpoint steps of the two balls, the hash starting at 1 entry or at its default."""
    model = surface_model(cloth=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator="midpoint", dt=2e-4)
    if small_hash:
        sim.solver.start_hash(1)
    core = sim.solver._core
    state = model.state()
    sim.run(state, STEPS)
    assert sim.solver._core is core  # grown inside the core, never rebuilt
    return state, sim


def test_a_too_small_contact_hash_grows_and_gives_the_same_run():
    """A solver whose spatial hash holds 1 entry grows it inside the core at the first
    contact step (the same solver goes on, nothing undone): the run equals one with the
    default room (8 entries per triangle) to the last bit."""
    (big, big_sim), (small, small_sim) = _surface_run(False), _surface_run(True)
    assert big_sim.solver._core.hash_capacity == 8 * big_sim.model.tri_count
    assert small_sim.solver._core.hash_capacity > 1
    assert small.step_count == big.step_count == STEPS
    np.testing.assert_array_equal(small.particle_q, big.particle_q)
    np.testing.assert_array_equal(small.particle_qd, big.particle_qd)


def _touching_balls():
    model = surface_model(cloth=False)
    state = model.state()
    shift = np.zeros_like(state.particle_q)
    shift[slice(*model.body_particle_range[0]), 0] = 0.03  # 1 cm into the other ball
    state.particle_q += shift
    return model, state


def _simulate(solver, model, state, steps, ratio_max=1e3):
    state.conform(model)  # the core takes a state that has met its model (its gas set)
    return solver.simulate(1, steps, 2e-4, control_data(model), state,
                           RunLimits(1e4, 1e-3, ratio_max))  # fmt: skip


def test_a_solver_grows_its_hash_to_the_room_it_needs():
    """Five steps of the balls already touching from a 1-entry hash: all done (OK), the
    hash grown to hold the entries the triangles need (at least one per triangle, at most
    8), with the same state as a solver with the default room."""
    model, state = _touching_balls()
    other = state.copy()
    small = _core.ExplicitSolver(core_model(model), hash_capacity=1)
    assert _simulate(small, model, state, 5)[:2] == (0, 5)
    assert model.tri_count <= small.hash_capacity <= 2 * 8 * model.tri_count
    big = _core.ExplicitSolver(core_model(model))
    assert _simulate(big, model, other, 5)[:2] == (0, 5)
    np.testing.assert_array_equal(state.particle_q, other.particle_q)
    np.testing.assert_array_equal(state.particle_qd, other.particle_qd)


def test_a_hash_past_its_most_room_stops_the_run():
    """A body stretched 40 times over another (its triangles spanning thousands of grid
    cells, past 512 per triangle): NEED_HASH (6) with the entries needed, no step done, the
    state as it was; the Simulator says so in one line (a blow-up)."""
    model, state = _touching_balls()
    body = slice(*model.body_particle_range[0])
    centre = state.particle_q[body].mean(axis=0)
    state.particle_q[body] = centre + 40.0 * (state.particle_q[body] - centre)
    before = state.particle_q.copy(), state.particle_qd.copy()
    solver = _core.ExplicitSolver(core_model(model))
    status, done, where, needed = _simulate(solver, model, state, 5, ratio_max=1e9)
    assert (status, done, where) == (6, 0, -1)
    assert needed > 512 * model.tri_count
    np.testing.assert_array_equal(state.particle_q, before[0])
    np.testing.assert_array_equal(state.particle_qd, before[1])
    sim = sb.Simulator(model, integrator="midpoint", dt=2e-4, volume_limits=(1e-3, 1e9))
    with pytest.raises(sb.SimulationError, match="surface contacts blew up at step 0"):
        sim.run(state, 5)


@pytest.mark.parametrize("contacts", ["bounding", "surface"])
def test_every_instruction_set_gives_the_same_run(contacts):
    """The scalar, AVX2 and AVX-512 builds of the kernels (those this CPU runs) give the
    same trajectory to round-off; the scalar path is always there."""
    paths = core.simd_paths()
    assert paths[0] == "scalar"
    if contacts == "bounding":
        model, control = every_term_model()
    else:
        model, control = surface_model(cloth=True), None
    before = core.simd_path()
    runs = {}
    try:
        for name in paths:
            core.use_simd(name)
            assert core.simd_path() == name
            runs[name] = _run(model, "rk4", 2e-4, control=control)[0]
    finally:
        core.use_simd(before)
    reference = runs["scalar"]
    for state in runs.values():
        tol = _tolerance(reference, STEPS)
        np.testing.assert_allclose(state.particle_q, reference.particle_q, rtol=0, atol=tol)


def test_unknown_instruction_set_is_a_clear_error():
    """A set this build or CPU lacks is a ValueError naming the ones it has."""
    with pytest.raises(ValueError, match="not available here; choose one of: scalar"):
        core.use_simd("sse9")


def test_the_core_refuses_inconsistent_model_arrays():
    """An index outside its array, or arrays of mismatched sizes, are ValueErrors at the
    boundary, before any kernel could read out of bounds."""
    model = ball_model(subdivisions=1)
    bad = dataclasses.replace(model, spring_indices=model.spring_indices + model.particle_count)
    with pytest.raises(ValueError, match="spring_indices holds"):
        _core.Model(bad)
    bad = dataclasses.replace(model, spring_stiffness=model.spring_stiffness[:-1])
    with pytest.raises(ValueError, match=r"spring_stiffness must have shape"):
        _core.Model(bad)
    bad = dataclasses.replace(model, tri_indices=model.tri_indices.astype(np.int32))
    with pytest.raises(ValueError, match="tri_indices must be a C-contiguous int64 array"):
        _core.Model(bad)
    with pytest.raises(ValueError, match="hash_capacity must be >= 0"):
        _core.ExplicitSolver(core_model(model), hash_capacity=-1)
    bad = dataclasses.replace(model, soft_contact_mode=2, contact_cell_size=0.0)
    with pytest.raises(ValueError, match="contact_cell_size must be finite and > 0"):
        _core.Model(bad)
    bad = dataclasses.replace(model, soft_contact_mode=2, contact_margin=float("nan"))
    with pytest.raises(ValueError, match="contact_margin must be finite and >= 0"):
        _core.Model(bad)
    solver = _core.ExplicitSolver(core_model(model))
    state = model.state()
    bad = SimpleNamespace(**vars(state))  # a State would refuse the shape itself
    bad.particle_q = state.particle_q[:, :2]
    with pytest.raises(ValueError, match="q must be a writable"):
        solver.simulate(3, 1, 1e-4, control_data(model), bad, RunLimits(1e4, 1e-3, 1e3))


#: Refuses to import a JIT compiler: the engine must run without one.
NO_JIT = """
import importlib.abc, sys
class NoJit(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("numba", "llvmlite"):
            raise ImportError(f"{name} imported by the engine")
sys.meta_path.insert(0, NoJit())
"""


@pytest.mark.parametrize("integrator", ["midpoint", "implicit_euler", "bdf2", "projective"])
def test_a_run_starts_without_compiling_anything(tmp_path, integrator):
    """Building a scene, runs of an explicit, implicit or projective scheme (with its
    multigrid hierarchy or factor; one after another on one state, as the command line
    and the viewer do), a run on two threads, their stability estimate, the diagnostics
    and the command line on the scene that measures every volume method use the compiled
    core only: with any import of a JIT compiler (Numba, llvmlite) refused, every one
    runs and exits 0."""
    code = NO_JIT + (
        "import softbody as sb\n"
        "from softbody.core import available_threads\n"
        "from softbody.scenes.loader import load_scene\n"
        "s = load_scene('bouncing-balls')\n"
        f"sim = sb.Simulator(s.model, integrator='{integrator}', dt=s.dt)\n"
        "st = s.model.state(); sim.run(st, 20); sim.run(st, 20); sim.advance(st, 0.01)\n"
        "t = min(2, available_threads())\n"
        f"sb.Simulator(s.model, integrator='{integrator}', dt=s.dt, threads=t).run(st, 5)\n"
        "print(sb.body_volume(s.model, st).sum(), sb.energies(s.model, st).total)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr
    cli = NO_JIT + "import sys; from softbody.cli import main; sys.exit(main(sys.argv[1:]))"
    command = [sys.executable, "-c", cli, "run", "bounding-volumes", "--duration", "0.05",
               "--no-video", "--no-gif", "--out", str(tmp_path / "out")]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
