"""The Simulator as a library user meets it: defaults, reprs, interrupting a long run, progress
bars, readbacks of what a Control applied, one Simulator per thread, and meshes in and out."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest
import trimesh

import softbody as sb
from conftest import ball_model
from softbody.sim import progress as progress_module

# A child process: a long run (10**9 steps) of a ball dropped on the ground, interrupted by
# the parent; it prints the clock its state reports and whether a fresh Simulator, run
# from the initial state for that many steps, lands on the same positions and velocities.
INTERRUPTED_RUN = textwrap.dedent(
    """
    import json, signal, sys
    import numpy as np
    import softbody as sb

    integrator, how = sys.argv[1], sys.argv[2]

    class Terminated(Exception):
        pass

    def on_sigterm(signum, frame):
        raise Terminated()

    signal.signal(signal.SIGTERM, on_sigterm)  # as the command line does

    def model():
        b = sb.ModelBuilder()
        b.add_soft_body(sb.icosphere(2, center=(0, 1.5, 0)), mass=1.0, stiffness=500.0,
                        damping=1.0, gas=300.0)
        b.add_collider(sb.ColliderPlane())
        return b.finalize()

    m = model()
    dt = 1e-3 if integrator == "implicit_euler" else 1e-4
    sim = sb.Simulator(m, integrator=integrator, dt=dt)
    state = m.state()
    print("running", flush=True)
    try:
        if how == "advance":
            sim.advance(state, 1e9 * dt)
        else:
            sim.run(state, 10**9)
        caught = "none"
    except KeyboardInterrupt:
        caught = "KeyboardInterrupt"
    except Terminated:
        caught = "Terminated"
    replay = m.state()
    sb.Simulator(m, integrator=integrator, dt=dt).run(replay, state.step_count)
    print(json.dumps({
        "caught": caught,
        "time": state.time,
        "step_count": state.step_count,
        "replay_time": replay.time,
        "same_q": bool(np.array_equal(replay.particle_q, state.particle_q)),
        "same_qd": bool(np.array_equal(replay.particle_qd, state.particle_qd)),
    }), flush=True)
    """
)


@pytest.mark.parametrize(
    ("integrator", "how", "signum"),
    [
        ("symplectic_euler", "run", signal.SIGINT),  # the fused symplectic loop
        ("velocity_verlet", "run", signal.SIGINT),  # the general explicit loop
        ("velocity_verlet", "advance", signal.SIGINT),
        ("implicit_euler", "run", signal.SIGINT),
        ("projective", "run", signal.SIGINT),
        ("velocity_verlet", "run", signal.SIGTERM),  # a Python handler that raises
    ],
)
def test_a_signal_stops_a_long_run_with_a_consistent_state(integrator, how, signum):
    """Contract (issue 29, item 3): Ctrl-C (SIGINT) or a SIGTERM handler stops a run of
    10**9 steps soon after the signal (here: the child ends within 10 s of it, not hours
    later), and the state's time and step_count describe its positions and velocities: a
    fresh run of step_count steps from the start lands on the same bits."""
    child = subprocess.Popen(
        [sys.executable, "-c", INTERRUPTED_RUN, integrator, how],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert child.stdout.readline().strip() == "running"
        time.sleep(1.0)  # into the compiled loop
        child.send_signal(signum)
        # the replay takes about as long as the run did (1 s): 10 s is generous
        out, err = child.communicate(timeout=10)
    finally:
        if child.poll() is None:
            child.kill()
            child.communicate()
    assert child.returncode == 0, err
    report = json.loads(out.strip().splitlines()[-1])
    expected = "KeyboardInterrupt" if signum == signal.SIGINT else "Terminated"
    assert report["caught"] == expected
    assert report["step_count"] > 0
    assert report["time"] == report["replay_time"]
    assert report["same_q"] and report["same_qd"]


def test_a_jupyter_interrupt_stops_a_long_run():
    """Contract (issue 29, item 3): Jupyter's Interrupt (the kernel manager's SIGINT to
    the kernel) ends a cell running 10**9 steps with KeyboardInterrupt (the reply comes
    within 30 s, not hours later), and the kernel's state then has time = step_count dt."""
    pytest.importorskip("ipykernel")
    manager = pytest.importorskip("jupyter_client.manager")
    kernel, client = manager.start_new_kernel(kernel_name="python3")
    try:
        client.execute_interactive(
            "import softbody as sb\n"
            "b = sb.ModelBuilder()\n"
            "b.add_soft_body(sb.icosphere(2), mass=1, stiffness=500, damping=1, gas=300)\n"
            "m = b.finalize(); sim = sb.Simulator(m, dt=1e-4); s = m.state()\n",
            timeout=60,
        )
        client.execute("sim.run(s, 10**9)")
        time.sleep(1.0)  # into the compiled loop
        kernel.interrupt_kernel()
        reply = client.get_shell_msg(timeout=30)["content"]
        assert (reply["status"], reply.get("ename")) == ("error", "KeyboardInterrupt")
        # read back as a user expression in the shell reply (printed output would come on
        # the iopub channel, where it can be missed after an interrupt)
        asked = client.execute(
            "", user_expressions={"ok": "s.step_count > 0 and s.time == s.step_count * 1e-4"}
        )
        reply = client.get_shell_msg(timeout=30)
        while reply["parent_header"].get("msg_id") != asked:
            reply = client.get_shell_msg(timeout=30)
        value = reply["content"]["user_expressions"]["ok"]
        assert value["status"] == "ok", value
        assert value["data"]["text/plain"] == "True"
    finally:
        client.stop_channels()
        kernel.shutdown_kernel(now=True)


def test_a_blow_up_leaves_a_consistent_state():
    """Contract: after a SimulationError the state is at the last good step, and its time
    and step_count say which (a fresh run of that many steps gives the same bits)."""
    model = ball_model(damping=0.0)
    with pytest.warns(sb.StabilityWarning):
        sim = sb.Simulator(model, integrator="symplectic_euler", dt=0.05)
    state = model.state()
    state.particle_qd[:] = np.random.default_rng(1).normal(0.0, 0.5, state.particle_qd.shape)
    start = state.copy()
    with pytest.raises(sb.SimulationError) as caught:
        sim.run(state, 10_000)
    assert state.step_count == caught.value.step > 0
    assert state.time == state.step_count * 0.05
    with pytest.warns(sb.StabilityWarning):
        replay_sim = sb.Simulator(model, integrator="symplectic_euler", dt=0.05)
    replay_sim.run(start, state.step_count)
    np.testing.assert_array_equal(start.particle_q, state.particle_q)
    np.testing.assert_array_equal(start.particle_qd, state.particle_qd)


class _Stop(Exception):
    """What the tests' SIGUSR1 handler raises."""


def _raise_stop(signum, frame):
    raise _Stop()


def test_an_exception_from_a_signal_handler_stops_the_run_on_the_main_thread():
    """Contract: the compiled loop runs Python's signal handlers between steps on the main
    thread, so a handler's exception, raised 0.3 s into a run of 10**7 steps (seconds),
    ends the run there with the state consistent (time = step_count dt)."""

    model = ball_model(subdivisions=1)
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-4)
    state = model.state()
    previous = signal.signal(signal.SIGUSR1, _raise_stop)
    timer = threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGUSR1))
    try:
        timer.start()
        with pytest.raises(_Stop):
            sim.run(state, 10**7)
    finally:
        timer.cancel()
        signal.signal(signal.SIGUSR1, previous)
    assert 0 < state.step_count < 10**7
    assert state.time == state.step_count * 1e-4


def test_progress_bar_on_request_and_same_steps(capsys):
    """Contract: progress=True draws a tqdm bar on stderr that ends at the call's steps;
    progress=False draws nothing; the steps are the same bits either way."""
    model = ball_model()
    sim = sb.Simulator(model, dt=1e-4)
    shown, quiet = model.state(), model.state()
    sim.run(shown, 3000, progress=True)
    err = capsys.readouterr().err
    assert "simulating" in err and "3.00k/3.00k" in err
    sim.run(quiet, 3000, progress=False)
    assert capsys.readouterr().err == ""
    np.testing.assert_array_equal(shown.particle_q, quiet.particle_q)
    assert shown.time == quiet.time and shown.step_count == quiet.step_count == 3000
    sim.advance(shown, 0.01, progress=True)
    assert "100/100" in capsys.readouterr().err


def test_progress_auto_shows_a_bar_only_for_long_calls(capsys, monkeypatch):
    """Contract: progress=None (default) shows nothing where no one can see it (stderr
    not a terminal, no notebook), and where one can, a bar only for a call expected to
    take longer than AUTO_SECONDS (here shrunk: 0 s, and a day)."""
    model = ball_model()
    sim = sb.Simulator(model, dt=1e-4)
    sim.run(model.state(), 20_000)  # not interactive under pytest: no bar
    assert capsys.readouterr().err == ""
    monkeypatch.setattr(progress_module, "interactive", lambda: True)
    monkeypatch.setattr(progress_module, "AUTO_AFTER", 0.0)
    monkeypatch.setattr(progress_module, "AUTO_SECONDS", 86400.0)
    sim.run(model.state(), 20_000)
    assert capsys.readouterr().err == ""
    monkeypatch.setattr(progress_module, "AUTO_SECONDS", 0.0)
    sim.run(model.state(), 20_000)
    assert "20.0k/20.0k" in capsys.readouterr().err
    with pytest.raises(ValueError, match="progress must be True, False or None"):
        sim.run(model.state(), 10, progress="yes")


def test_an_exception_from_the_progress_callback_stops_the_run_on_any_thread():
    """Contract of the solvers' simulate(): the compiled loop calls progress(steps_done)
    every 50 ms or so on any thread; its exception stops a run of 10**9 steps, and the
    state's clock (time, step_count) has advanced by the steps done before it is raised."""
    model = ball_model(subdivisions=1)
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-4)
    from softbody.sim.control import control_data
    from softbody.solvers import RunLimits

    seen: list[int] = []
    outcome: dict = {}

    def progress(done):
        seen.append(done)
        if len(seen) == 3:
            raise ArithmeticError("stop here")

    def work():
        state = model.state()
        try:
            sim.solver.simulate(state, 10**9, 1e-4, control_data(model),
                                RunLimits(1e4, 1e-3, 1e3), progress)  # fmt: skip
        except ArithmeticError as exc:
            outcome["error"] = str(exc)
        outcome["state"] = state

    worker = threading.Thread(target=work)
    worker.start()
    worker.join(timeout=60)
    assert not worker.is_alive()
    assert outcome["error"] == "stop here"
    state = outcome["state"]
    assert seen == sorted(seen) and seen[-1] == state.step_count > 0
    assert state.time == state.step_count * 1e-4


def test_readback_reports_the_gas_a_control_applied():
    """Contract (issue 29, item 4): after a run with Control's pressure 20 Pa where the
    model says 100 Pa, body_pressure gives 20 Pa; an isothermal body driven at nRT = 20 J
    (model: 100 J) reads nRT / V = 20 / V; body_gas_value gives 20 for both; a later run
    without a control reads the model's values again."""
    builder = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    for x, gas in ((0.0, sb.Gas.fixed_pressure(100.0)), (3.0, sb.Gas.isothermal(100.0))):
        builder.add_soft_body(sb.icosphere(1, center=(x, 0.0, 0.0)), mass=1.0,
                              stiffness=200.0, damping=1.0, gas=gas)  # fmt: skip
    model = builder.finalize()
    sim = sb.Simulator(model, dt=1e-4)
    control = model.control()
    control.body_gas_pressure[0] = 20.0
    control.body_gas_nrt[1] = 20.0
    state = model.state()
    sim.run(state, 50, control)
    volume = sb.body_volume(model, state)
    np.testing.assert_allclose(sb.body_pressure(model, state), [20.0, 20.0 / volume[1]],
                               rtol=1e-14)  # fmt: skip
    np.testing.assert_array_equal(sb.body_gas_value(model, state), [20.0, 20.0])
    # the state carries it: a copy reads the same, an explicit control still wins
    np.testing.assert_array_equal(sb.body_gas_value(model, state.copy()), [20.0, 20.0])
    np.testing.assert_array_equal(sb.body_gas_value(model, state, model.control()), [100, 100])
    energy = sb.energies(model, state, control)
    assert sb.energies(model, state).gas == energy.gas
    sim.run(state, 1)
    np.testing.assert_array_equal(sb.body_gas_value(model, state), [100.0, 100.0])
    volume = sb.body_volume(model, state)
    np.testing.assert_allclose(sb.body_pressure(model, state), [100.0, 100.0 / volume[1]],
                               rtol=1e-14)  # fmt: skip


def test_default_simulator_is_velocity_verlet_at_the_auto_step():
    """Contract (issue 29, item 5): Simulator(model) needs no dt or integrator: velocity
    Verlet at the automatic step (below the stability estimate), which keeps the energy
    of an undamped vibrating ball (kinetic + spring + gas, conserved by the physics)
    within 1% over 2 s, where midpoint (the old default) at that step blows up."""
    model = ball_model(damping=0.0)
    sim = sb.Simulator(model)
    assert sim.integrator == sb.Integrator.VELOCITY_VERLET
    assert sim.auto_dt and 0 < sim.dt <= sim.stable_dt
    state = model.state()
    rng = np.random.default_rng(7)
    state.particle_qd[:] = rng.normal(0.0, 0.3, state.particle_qd.shape)
    state.particle_qd -= state.particle_qd.mean(axis=0)
    start = state.copy()
    energy = sb.energies(model, state).total
    sim.advance(state, 2.0)
    assert abs(sb.energies(model, state).total - energy) < 0.01 * abs(energy)
    with pytest.warns(sb.StabilityWarning):
        midpoint = sb.Simulator(model, integrator="midpoint", dt=sim.dt)
    with pytest.raises(sb.SimulationError, match="blew up"):
        midpoint.advance(start, 2.0)


def test_short_reprs():
    """Contract: State and Simulator print on one short line with their sizes and
    settings, not their arrays."""
    model = ball_model()
    sim = sb.Simulator(model)
    state = model.state()
    sim.run(state, 3)
    text = repr(state)
    assert text.startswith("State(particle_count=162, time=") and "step_count=3" in text
    assert "\n" not in text and len(text) < 120
    text = repr(sim)
    assert text.startswith("Simulator(integrator='velocity_verlet', dt=") and "(auto)" in text
    assert "particle_count=162" in text and "\n" not in text and len(text) < 200


def test_package_ships_py_typed():
    """Contract (PEP 561): the package carries py.typed, so type checkers read its hints."""
    from importlib.resources import files

    assert files("softbody").joinpath("py.typed").is_file()


def test_add_soft_body_takes_a_trimesh():
    """Contract: add_soft_body accepts a trimesh.Trimesh as it accepts the TriMesh of the
    same vertices and faces (the same particles and triangles)."""
    ours = sb.icosphere(2, radius=0.5)
    theirs = trimesh.Trimesh(np.array(ours.vertices), np.array(ours.faces), process=False)
    models = []
    for mesh in (ours, theirs):
        builder = sb.ModelBuilder()
        builder.add_soft_body(mesh, mass=1.0, stiffness=100.0, damping=1.0, gas=50.0)
        models.append(builder.finalize())
    np.testing.assert_array_equal(models[0].particle_q, models[1].particle_q)
    np.testing.assert_array_equal(models[0].tri_indices, models[1].tri_indices)
    with pytest.raises(TypeError, match="mesh must be a softbody.TriMesh or a trimesh.Trimesh"):
        sb.ModelBuilder().add_soft_body([1, 2], mass=1.0, stiffness=1.0, damping=0.0, gas=1.0)


def test_body_mesh_is_the_deformed_surface():
    """Contract: body_mesh(model, state, b) is body b's particles at the state and its
    triangles, indexed from 0; its enclosed volume (trimesh's) is body_volume's exact
    volume, and it converts to a trimesh.Trimesh."""
    builder = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    builder.add_soft_body(sb.icosphere(1), mass=1.0, stiffness=100.0, damping=1.0, gas=50.0)
    builder.add_soft_body(sb.icosphere(2, center=(3.0, 0.0, 0.0)), mass=1.0,
                          stiffness=100.0, damping=1.0, gas=80.0)  # fmt: skip
    model = builder.finalize()
    state = model.state()
    sb.Simulator(model).advance(state, 0.05)
    mesh = sb.body_mesh(model, state, 1)
    assert isinstance(mesh, sb.TriMesh)
    p0, p1 = model.body_particle_range[1]
    np.testing.assert_array_equal(mesh.vertices, state.particle_q[p0:p1])
    assert mesh.faces.min() == 0 and mesh.faces.max() == p1 - p0 - 1
    volume = mesh.to_trimesh().volume
    np.testing.assert_allclose(volume, sb.body_volume(model, state)[1], rtol=1e-12)
    with pytest.raises(ValueError, match=r"body must lie in \[0, 1\], got 2"):
        sb.body_mesh(model, state, 2)
    with pytest.raises(TypeError, match="body must be an integer"):
        sb.body_mesh(model, state, 1.0)


def test_one_simulator_refuses_a_second_thread():
    """Contract (issue 29, item 6): a Simulator steps one state at a time; a call from a
    second thread while one runs raises RuntimeError saying to use one Simulator per
    thread (instead of sharing the solver's buffers and silently giving wrong states)."""

    model = ball_model(subdivisions=1)
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-4)
    errors: list[BaseException] = []

    def second_caller():
        time.sleep(0.2)  # the main thread's run is under way
        for call in (lambda: sim.run(model.state(), 10), lambda: sim.step(model.state()),
                     lambda: sim.advance(model.state(), 0.01)):  # fmt: skip
            try:
                call()
            except RuntimeError as exc:
                errors.append(exc)
        os.kill(os.getpid(), signal.SIGUSR1)  # ends the main thread's run

    previous = signal.signal(signal.SIGUSR1, _raise_stop)
    other = threading.Thread(target=second_caller)
    try:
        other.start()
        with pytest.raises(_Stop):
            sim.run(model.state(), 10**7)  # seconds; the signal ends it 0.2 s in
    finally:
        other.join(timeout=60)
        signal.signal(signal.SIGUSR1, previous)
    assert len(errors) == 3
    for exc, name in zip(errors, ("run", "step", "advance"), strict=True):
        assert f"Simulator.{name}: this Simulator is already running" in str(exc)
        assert "one Simulator per thread" in str(exc)
    sim.run(model.state(), 10)  # free again


def test_one_simulator_per_thread_matches_the_serial_run():
    """Contract: Simulators of one model on two threads at once (the documented way) give
    the serial run's bits."""
    model = ball_model(gravity=(0.0, -9.81, 0.0), damping=1.0)
    rng = np.random.default_rng(3)
    starts = []
    for _ in range(2):
        state = model.state()
        state.particle_qd[:] = rng.normal(0.0, 0.2, state.particle_qd.shape)
        starts.append(state)
    serial = [s.copy() for s in starts]
    for s in serial:
        sb.Simulator(model, dt=2e-4).run(s, 3000)
    parallel = [s.copy() for s in starts]
    workers = [
        threading.Thread(target=sb.Simulator(model, dt=2e-4).run, args=(s, 3000))
        for s in parallel
    ]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    for a, b in zip(serial, parallel, strict=True):
        np.testing.assert_array_equal(a.particle_q, b.particle_q)
        assert a.step_count == b.step_count == 3000


def scheduled_ball() -> sb.Model:
    """A 162-vertex ball whose gas follows a schedule (its nRT read at each step's time),
    self-contact on, under gravity above the ground."""
    builder = sb.ModelBuilder()
    builder.set_soft_contact("surface", self_contact=True)
    builder.add_soft_body(
        sb.icosphere(2, radius=0.5, center=(0.0, 0.6, 0.0)), mass=1.0, stiffness=300.0,
        damping=0.5, gas=sb.Gas.isothermal(60.0, schedule=[(0.0, 60.0), (0.05, 20.0)]),
    )  # fmt: skip
    builder.add_collider(sb.ColliderPlane())
    return builder.finalize()


@pytest.mark.parametrize("integrator", [m.name.lower() for m in sb.Integrator])
def test_runs_of_one_step_are_one_run(integrator):
    """n runs of one step are one run of n steps to the bit (time, positions, velocities,
    gas), on a ball whose gas follows a schedule: the state keeps its clock's origin, so
    step k's time is origin + k dt either way (summing dt n times would differ in the last
    bits, and the schedule reads the time). A time set by hand starts a new origin: from
    there the runs again equal one run from a state at that time."""
    model = scheduled_ball()
    dt = 2e-5 if integrator in ("euler", "midpoint", "rk4") else 1e-3
    steps = 30
    one, many = (sb.Simulator(model, integrator=integrator, dt=dt) for _ in range(2))
    whole, parts = model.state(), model.state()
    one.run(whole, steps)
    for _ in range(steps):
        many.run(parts, 1)
    assert parts.time == whole.time == steps * dt and parts.step_count == steps
    for name in ("particle_q", "particle_qd", "body_gas_moles"):
        np.testing.assert_array_equal(getattr(parts, name), getattr(whole, name))
    # a new origin where the time is set: both go on from 0.01 s alike
    for state in (whole, parts):
        state.time = 0.01
    one.run(whole, 10)
    for _ in range(10):
        many.run(parts, 1)
    assert parts.time == whole.time == 0.01 + 10 * dt
    np.testing.assert_array_equal(parts.particle_q, whole.particle_q)
