"""The viewer's server side, without a browser: real time, blow-up handling, reset."""

from __future__ import annotations

import time

import pytest

import softbody as sb
from conftest import start_viewer


@pytest.fixture
def viewer():
    v = start_viewer()
    yield v
    v.stop()


def test_rebuilt_simulators_keep_the_callers_options():
    """A slider or integrator change builds a new Simulator, and Reset builds the first
    one again: each keeps the options the caller's simulator had (CG tolerance, speed
    limit, threads), not the defaults."""
    options = {"implicit_tolerance": 1e-2, "max_speed": 50.0, "implicit_max_iterations": 30}
    v = start_viewer(**options)
    try:
        expected = v.sim.options
        assert {k: expected[k] for k in options} == options
        v.integrator_menu.value = "implicit_euler"
        v.stiffness_sliders[0].value = 0.5 * v.stiffness_sliders[0].value
        v._rebuild()
        assert v.sim.integrator == sb.Integrator.IMPLICIT_EULER
        assert v.sim.options == expected
        v._reset()
        assert v.sim.options == expected
    finally:
        v.stop()


def test_keeps_up_with_the_wall_clock(viewer):
    """hanging-ball runs 7x faster than real time offline, so the viewer's clock follows
    the wall clock: never ahead of it (by more than one loop, 1/30 s), and at least 70% of
    it over 3 s even if another process takes some of the two cores."""
    t0, w0 = viewer.state.time, time.perf_counter()
    time.sleep(3.0)
    elapsed = time.perf_counter() - w0
    advanced = viewer.state.time - t0
    assert 0.7 * elapsed <= advanced <= elapsed + 1.0 / 30


def test_unstable_slider_pauses_with_a_message_and_reset_recovers(viewer):
    """Undamped explicit Euler (unstable at any dt) blows the ball up: the server keeps
    serving, the run pauses with the blow-up message, and Reset restores the starting
    parameters so the run goes on."""
    viewer.damping_sliders[0].value = 0.0
    viewer.integrator_menu.value = "euler"
    viewer._rebuild()
    assert "exceeds the stable estimate" in viewer.message
    deadline = time.perf_counter() + 30
    while not viewer.message.startswith("paused") and time.perf_counter() < deadline:
        time.sleep(0.2)
    assert viewer.message.startswith("paused: body 0 blew up at step")
    assert not viewer.running
    viewer._reset()
    assert viewer.running and viewer.message == ""
    assert viewer.integrator_menu.value == "midpoint"
    assert viewer.damping_sliders[0].value == pytest.approx(0.3)
    t0 = viewer.state.time
    time.sleep(2.5)
    assert viewer.state.time > t0 + 2.0 and viewer.message == ""


def test_grabbed_vertex_follows_the_gizmo(viewer):
    """A click ray through a vertex grabs that vertex (the one facing the camera, not the
    one behind it on the same ray); moving the grab gizmo 0.3 m away pulls it there with
    a critically damped spring: the vertex ends up much nearer the target."""
    from types import SimpleNamespace

    import numpy as np

    p0, _ = viewer.model.body_particle_range[1]
    with viewer.lock:
        x = viewer.state.particle_q.copy()
    i = int(p0 + np.argmin(x[p0 : p0 + 162, 2] * -1.0))  # the vertex facing the camera (+z)
    origin = x[i] + np.array([0.0, 0.0, 3.0])
    viewer._on_mesh_click(1, SimpleNamespace(ray_origin=origin, ray_direction=(0, 0, -1)))
    assert viewer.grabbed == i
    target = x[i] + np.array([0.0, 0.0, 0.3])
    viewer.grab_gizmo.position = tuple(target)
    time.sleep(2.0)
    with viewer.lock:
        now = viewer.state.particle_q[i].copy()
    assert np.linalg.norm(now - target) < 0.5 * np.linalg.norm(x[i] - target)
    viewer._release()
    assert viewer.grabbed is None and viewer.control.grab_particle == -1
