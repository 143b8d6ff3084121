"""The compiled C++ core against the Numba kernels it replaces, its instruction-set paths
against each other, and its checks at the Python boundary.

Reference for the comparisons: the Numba time loop and force kernels, which the physics
tests validated against closed forms before the port. The core computes each spring's and
each face's terms with the same operations (no FMA contraction, no reassociation) but sums
them per particle (vertex-major) instead of per spring and face, so the forces differ in
their last bits; the tolerance allows that round-off to grow over the run (1e-12 relative
to the motion's scale per step). Its instruction-set paths share one summation order, so
they agree with each other to the last bit.
"""

from __future__ import annotations

import os
import subprocess
import sys
import warnings

import numpy as np
import pytest

import softbody as sb
from conftest import ball_model
from softbody import _core, core
from softbody.core import core_model
from softbody.scenes.loader import load_scene
from softbody.sim.control import control_data

EXPLICIT = ["euler", "midpoint", "rk4", "symplectic_euler", "velocity_verlet"]
STEPS = 150


def _run(model, integrator, dt, *, use_core, steps=STEPS, control=None, state=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator=integrator, dt=dt)
    if not use_core:
        sim._core = None  # the Numba loop (compiled by the session's warm-up)
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


@pytest.mark.parametrize("integrator", EXPLICIT)
def test_every_explicit_term_matches_the_numba_loop(integrator):
    """Every term the core steps, each scheme: positions, velocities, collider poses and
    impulses equal the Numba loop's over 150 steps, to round-off."""
    model, control = _everything_model()
    runs = [_run(model, integrator, 2e-4, use_core=c, control=control) for c in (True, False)]
    (a, error_a), (b, error_b) = runs
    assert error_a == error_b
    tol = _tolerance(b, STEPS)
    for name in ("particle_q", "particle_qd", "collider_q", "collider_rotation",
                 "collider_impulse"):  # fmt: skip
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=tol)
    assert a.step_count == b.step_count


@pytest.mark.parametrize("scene", ["bouncing-balls", "hanging-ball", "hand-punch", "cloth-wind"])
def test_built_in_scenes_match_the_numba_loop(scene):
    """The built-in scenes with their own integrator and step, 150 steps."""
    s = load_scene(scene)
    (a, _), (b, _) = [_run(s.model, s.integrator, s.dt, use_core=c) for c in (True, False)]
    tol = _tolerance(b, STEPS)
    np.testing.assert_allclose(a.particle_q, b.particle_q, rtol=0, atol=tol)
    np.testing.assert_allclose(a.particle_qd, b.particle_qd, rtol=0, atol=tol * 1e3)


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


@pytest.mark.parametrize("cloth", [False, True], ids=["two-balls", "ball-on-cloth"])
@pytest.mark.parametrize("integrator", EXPLICIT)
def test_surface_contacts_match_the_numba_loop(integrator, cloth):
    """Surface soft contacts (vertex against triangle, through the spatial hash), each
    scheme: positions and velocities equal the Numba loop's over 150 steps, to round-off.
    The contacts act: the last ball's momentum along its motion ends at least 10 % away
    from the free fall's p0 + M g t."""
    model = _surface_model(cloth)
    runs = [_run(model, integrator, 2e-4, use_core=c) for c in (True, False)]
    (a, error_a), (b, error_b) = runs
    assert error_a is None and error_b is None
    tol = _tolerance(b, STEPS)
    np.testing.assert_allclose(a.particle_q, b.particle_q, rtol=0, atol=tol)
    np.testing.assert_allclose(a.particle_qd, b.particle_qd, rtol=0, atol=tol)
    ball = slice(*model.body_particle_range[-1])
    axis = 2 if cloth else 0
    mass = model.particle_mass[ball]
    start = (mass * model.particle_qd[ball, axis]).sum()
    free = start + mass.sum() * model.gravity[axis] * b.time
    end = (mass * b.particle_qd[ball, axis]).sum()
    assert abs(end - free) > 0.1 * abs(start)


def _surface_run(small_hash: bool, use_core: bool) -> tuple[sb.State, sb.Simulator]:
    """150 midpoint steps of the two balls, the hash starting at 1 entry or at its default."""
    from softbody.integrators.workspace import Workspace

    model = _surface_model(cloth=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator="midpoint", dt=2e-4)
    if not use_core:
        sim._core = None
        if small_hash:
            sim._work = Workspace.for_model(model, hash_capacity=1)
    elif small_hash:
        sim._core = _core.ExplicitSolver(core_model(model), hash_capacity=1)
    state = model.state()
    sim.run(state, STEPS)
    return state, sim


def test_a_too_small_contact_hash_grows_and_gives_the_same_run():
    """A solver whose spatial hash holds 1 entry stops at the first contact step with
    NEED_HASH (the step undone), is rebuilt with twice the entries needed and goes on: the
    run equals one with the default room (8 entries per triangle) to the last bit (no term
    here depends on the restarted call's time origin)."""
    (big, big_sim), (small, small_sim) = _surface_run(False, True), _surface_run(True, True)
    assert big_sim._core.hash_capacity == 8 * big_sim.model.tri_count
    assert small_sim._core.hash_capacity > 1
    assert small.step_count == big.step_count == STEPS
    np.testing.assert_array_equal(small.particle_q, big.particle_q)
    np.testing.assert_array_equal(small.particle_qd, big.particle_qd)


def test_a_too_small_contact_hash_grows_as_in_the_numba_loop():
    """From a 1-entry hash the core and the Numba loop grow to the same room and end at
    the same state, to round-off."""
    (core_state, core_sim), (numba_state, numba_sim) = (
        _surface_run(True, True),
        _surface_run(True, False),
    )
    assert numba_sim._work.hash_entries.shape[0] == core_sim._core.hash_capacity
    tol = _tolerance(numba_state, STEPS)
    np.testing.assert_allclose(core_state.particle_q, numba_state.particle_q, rtol=0, atol=tol)
    np.testing.assert_allclose(core_state.particle_qd, numba_state.particle_qd, rtol=0, atol=tol)


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


def test_a_blow_up_stops_at_the_same_step_with_the_same_reason():
    """A ball far above its stable step blows up at the same step, for the same body or
    particle and reason, in the core and in the Numba loop; the state is the last good
    one in both."""
    model = ball_model(stiffness=5e4, gas=2000.0)
    (a, error_a), (b, error_b) = [
        _run(model, "euler", 2e-3, use_core=c, steps=2000) for c in (True, False)
    ]
    assert error_a is not None and error_a == error_b
    assert a.step_count == b.step_count
    tol = _tolerance(b, a.step_count)
    np.testing.assert_allclose(a.particle_q, b.particle_q, rtol=0, atol=tol)


def test_forces_and_jacobian_products_match_the_numba_kernels():
    """Forces, volumes and pressures at a deformed state, and the matrix-free product
    alpha_m M p + alpha_c C p + alpha_k K p, equal the Numba kernels' to round-off."""
    from softbody.forces.evaluate import eval_forces
    from softbody.integrators.implicit import (
        _body_pressure_slopes,
        _prepare_springs,
        apply_jacobians,
    )
    from softbody.integrators.workspace import Workspace

    model, control = _everything_model()
    rng = np.random.default_rng(3)
    q = model.particle_q + rng.uniform(-0.01, 0.01, model.particle_q.shape)
    qd = rng.normal(0.0, 0.3, q.shape)
    data = control.write(model, control_data(model))
    f, volume, pressure, _ = _core.eval_forces(core_model(model), data, 0.02, q, qd)
    w = Workspace.for_model(model)
    f_ref = np.zeros_like(q)
    eval_forces(model.data, data, 0.02, q, qd, w, f_ref)
    scale = np.abs(f_ref).max()
    np.testing.assert_allclose(f, f_ref, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(volume, w.body_volume, rtol=1e-14)
    np.testing.assert_allclose(pressure, w.body_pressure, rtol=1e-14)

    _prepare_springs(q, model.spring_indices, model.spring_rest_length, model.spring_stiffness,
                     w.spring_u, w.spring_a, w.spring_b)  # fmt: skip
    _body_pressure_slopes(model.data, w.body_volume, w.body_pressure, w.body_dpdv, w.body_pnet)
    p = rng.normal(size=q.shape)
    out, out_ref = np.zeros_like(q), np.zeros_like(q)
    args = (q, p, 2.0, 0.3, 0.7, w.spring_u, w.spring_a, w.spring_b, w.volume_gradient,
            w.body_dpdv, w.body_pnet)  # fmt: skip
    _core.apply_jacobians(core_model(model), data, *args, out)
    apply_jacobians(model.data, data, *args, out_ref)
    np.testing.assert_allclose(out, out_ref, rtol=0, atol=1e-12 * np.abs(out_ref).max())


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
            runs[name] = _run(model, "rk4", 2e-4, use_core=True, control=control)[0]
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


@pytest.mark.parametrize("integrator", ["midpoint", "implicit_euler", "bdf2", "projective"])
def test_a_run_starts_without_compiling_anything(tmp_path, integrator):
    """On an empty kernel cache, building a scene, runs of an explicit, implicit or
    projective scheme (with its multigrid hierarchy or factor; one after another on one
    state, as the command line and the viewer do), an explicit run on two threads, their
    stability estimate and the diagnostics use the compiled core only: the Numba kernels'
    warm-up never starts and nothing compiles (either would write files into the cache
    folder)."""
    code = (
        "import softbody as sb\n"
        "from softbody.scenes.loader import load_scene\n"
        "s = load_scene('bouncing-balls')\n"
        f"sim = sb.Simulator(s.model, integrator='{integrator}', dt=s.dt)\n"
        "st = s.model.state(); sim.run(st, 20); sim.run(st, 20); sim.advance(st, 0.01)\n"
        "import numba; t = min(2, numba.config.NUMBA_NUM_THREADS)\n"
        "sb.Simulator(s.model, integrator='rk4', dt=s.dt, threads=t).run(st, 5)\n"
        "print(sb.body_volume(s.model, st).sum(), sb.energies(s.model, st).total)\n"
    )
    cache = tmp_path / "cache"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "compiling the kernels" not in done.stderr
    # the command line on the scene that measures every volume method, with its plots
    command = [sys.executable, "-m", "softbody.cli", "run", "bounding-volumes", "--duration",
               "0.05", "--no-video", "--no-gif", "--out", str(tmp_path / "out")]  # fmt: skip
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "compiling the kernels" not in done.stderr
    # (importing the Numba kernels makes their empty cache folders, nothing more)
    assert not [p for p in cache.rglob("*") if p.is_file()], sorted(cache.rglob("*"))[:5]
