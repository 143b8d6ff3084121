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

import subprocess
import sys
import warnings

import numpy as np
import pytest

import softbody as sb
from conftest import ball_model
from softbody import _core, core
from softbody.core import core_model
from softbody.sim.control import control_data

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


def _everything_model() -> tuple[sb.Model, sb.Control]:
    """Every term the explicit core steps: each volume method and gas law, a schedule,
    ambient pressure, attachments, pins driven to targets, a grab, external forces, each
    collider kind with each motion, and bounding soft contacts."""
    b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    b.add_soft_body(sb.icosphere(2, radius=0.3, center=(-0.5, 0.5, 0.0)), mass=1.0,
                    stiffness=400.0, damping=0.5, gas=sb.Gas.isothermal(40.0),
                    bend_stiffness=20.0, bend_damping=0.1)  # fmt: skip
    b.add_soft_body(
        sb.icosphere(2, radius=0.3, center=(0.2, 0.55, 0.0)), mass=1.0, stiffness=400.0,
        damping=0.5, volume_method="bounding_ellipsoid",
        gas=sb.Gas.adiabatic(30.0, ambient_pressure=5.0, schedule=[(0.0, 30.0), (0.05, 60.0)]),
    )  # fmt: skip
    b.add_soft_body(
        sb.icosphere(1, radius=0.25, center=(0.8, 0.5, 0.1)), mass=0.5, stiffness=300.0,
        damping=0.3, volume_method="monte_carlo", gas=sb.Gas.fixed_pressure(80.0),
    )  # fmt: skip
    b.add_soft_body(
        sb.icosphere(1, radius=0.25, center=(0.0, 1.2, 0.0)), mass=0.5, stiffness=300.0,
        damping=0.3, volume_method="bounding_box", gas=20.0, pinned=[0, 1],
    )  # fmt: skip
    b.add_soft_body(
        sb.icosphere(1, radius=0.2, center=(-0.2, 1.0, 0.3)), mass=0.5, stiffness=300.0,
        damping=0.3, volume_method="bounding_sphere", gas=15.0,
    )  # fmt: skip
    b.add_attachment(5, anchor=(-0.5, 1.0, 0.0), stiffness=50.0, damping=1.0)
    b.add_spring(0, 170, stiffness=30.0, damping=0.2)  # between two bodies, off any ring
    b.add_collider(sb.ColliderPlane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0),
                                    restitution=0.5, friction=0.2))  # fmt: skip
    b.add_collider(sb.ColliderSphere(center=(0.2, 0.1, 0.0), radius=0.2,
                                     motion=sb.MotionOscillation(amplitude=(0.0, 0.1, 0.0),
                                                                 frequency=3.0)))  # fmt: skip
    b.add_collider(
        sb.ColliderBox(
            center=(0.8, 0.1, 0.0),
            half_extents=(0.2, 0.1, 0.2),
            motion=sb.MotionRotation(angular_velocity=(0.0, 2.0, 0.0)),
        )
    )
    b.add_collider(
        sb.ColliderBox(
            center=(0.0, 0.8, 0.0),
            half_extents=(1.5, 1.2, 1.0),
            container=True,
            motion=sb.MotionTranslation(velocity=(0.0, 0.1, 0.0)),
        )
    )
    b.set_soft_contact("bounding", restitution=0.4, friction=0.1)
    model = b.finalize()
    control = model.control()
    control.particle_f[10] = (0.0, 2.0, 0.0)
    control.grab_particle = 20
    control.grab_target = np.array([-0.4, 0.9, 0.0])
    control.grab_stiffness, control.grab_damping = 30.0, 0.5
    control.pin_target = model.particle_q[model.pin_particle] + (0.0, 0.05, 0.0)
    return model, control


def _surface_model(cloth: bool) -> sb.Model:
    """Surface soft contacts: two balls meeting head on at +-2 m/s from 2 cm apart, or
    (``cloth``) a falling ball hitting a cloth pinned at its corners, at 3 m/s."""
    b = sb.ModelBuilder(gravity=(0.0, 0.0, -9.81) if cloth else (0.0, 0.0, 0.0))
    b.set_soft_contact("surface", restitution=0.5, friction=0.3)
    if cloth:
        b.add_cloth(sb.rectangle((1.0, 1.0), (8, 8)), mass=2.0, stiffness=2000.0, damping=0.5,
                    pinned=[0, 8, 72, 80])  # fmt: skip
        centers, velocities = [(0.05, -0.03, 0.27)], [(0.0, 0.0, -3.0)]
    else:
        centers, velocities = [(-0.31, 0.0, 0.0), (0.31, 0.02, 0.0)], [(2, 0, 0), (-2, 0, 0)]
    for center, velocity in zip(centers, velocities, strict=True):
        b.add_soft_body(sb.icosphere(2, radius=0.3 if not cloth else 0.25, center=center),
                        mass=1.0, stiffness=400.0, damping=0.5, gas=40.0,
                        velocity=velocity)  # fmt: skip
    return b.finalize()


def _surface_run(small_hash: bool) -> tuple[sb.State, sb.Simulator]:
    """150 midpoint steps of the two balls, the hash starting at 1 entry or at its default."""
    model = _surface_model(cloth=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator="midpoint", dt=2e-4)
    if small_hash:
        sim.solver.grow_hash(1)
    state = model.state()
    sim.run(state, STEPS)
    return state, sim


def test_a_too_small_contact_hash_grows_and_gives_the_same_run():
    """A solver whose spatial hash holds 1 entry stops at the first contact step with
    NEED_HASH (the step undone), is rebuilt with twice the entries needed and goes on: the
    run equals one with the default room (8 entries per triangle) to the last bit (no term
    here depends on the restarted call's time origin)."""
    (big, big_sim), (small, small_sim) = _surface_run(False), _surface_run(True)
    assert big_sim.solver._core.hash_capacity == 8 * big_sim.model.tri_count
    assert small_sim.solver._core.hash_capacity > 1
    assert small.step_count == big.step_count == STEPS
    np.testing.assert_array_equal(small.particle_q, big.particle_q)
    np.testing.assert_array_equal(small.particle_qd, big.particle_qd)


def test_a_solver_reports_the_hash_room_it_needs():
    """One step of the balls already touching with a 1-entry hash: NEED_HASH (6), no step
    done, the needed entry count as the value, and the state as it was."""
    model = _surface_model(cloth=False)
    state = model.state()
    shift = np.zeros_like(state.particle_q)
    shift[slice(*model.body_particle_range[0]), 0] = 0.03  # 1 cm into the other ball
    state.particle_q += shift
    before = state.particle_q.copy(), state.particle_qd.copy()
    solver = _core.ExplicitSolver(core_model(model), hash_capacity=1)
    status, done, where, needed = solver.simulate(
        1, 5, 0.0, 2e-4, control_data(model), state.particle_q, state.particle_qd,
        state.collider_q, state.collider_rotation, state.collider_impulse, 1e4, 1e-3, 1e3,
    )  # fmt: skip
    assert (status, done, where) == (6, 0, -1)
    assert model.tri_count <= needed <= 8 * model.tri_count
    np.testing.assert_array_equal(state.particle_q, before[0])
    np.testing.assert_array_equal(state.particle_qd, before[1])


@pytest.mark.parametrize("contacts", ["bounding", "surface"])
def test_every_instruction_set_gives_the_same_run(contacts):
    """The scalar, AVX2 and AVX-512 builds of the kernels (those this CPU runs) give the
    same trajectory to round-off; the scalar path is always there."""
    paths = core.simd_paths()
    assert paths[0] == "scalar"
    if contacts == "bounding":
        model, control = _everything_model()
    else:
        model, control = _surface_model(cloth=True), None
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
    bad = model.data._replace(spring_indices=model.spring_indices + model.particle_count)
    with pytest.raises(ValueError, match="spring_indices holds"):
        _core.Model(bad)
    bad = model.data._replace(spring_stiffness=model.spring_stiffness[:-1])
    with pytest.raises(ValueError, match=r"spring_stiffness must have shape"):
        _core.Model(bad)
    bad = model.data._replace(tri_indices=model.tri_indices.astype(np.int32))
    with pytest.raises(ValueError, match="tri_indices must be a C-contiguous int64 array"):
        _core.Model(bad)
    with pytest.raises(ValueError, match="hash_capacity must be >= 0"):
        _core.ExplicitSolver(core_model(model), hash_capacity=-1)
    bad = model.data._replace(soft_contact_mode=2, contact_cell_size=0.0)
    with pytest.raises(ValueError, match="contact_cell_size must be finite and > 0"):
        _core.Model(bad)
    bad = model.data._replace(soft_contact_mode=2, contact_margin=float("nan"))
    with pytest.raises(ValueError, match="contact_margin must be finite and >= 0"):
        _core.Model(bad)
    solver = _core.ExplicitSolver(core_model(model))
    state = model.state()
    with pytest.raises(ValueError, match="q must be a writable"):
        solver.simulate(3, 1, 0.0, 1e-4, control_data(model), state.particle_q[:, :2],
                        state.particle_qd, state.collider_q, state.collider_rotation,
                        state.collider_impulse, 1e4, 1e-3, 1e3)  # fmt: skip


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
