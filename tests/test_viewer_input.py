"""Values a client sends to the viewer (issue 19, item 9), through a real websocket
speaking viser's protocol (msgpack messages, as viser's page sends them).

A value that is not a finite number, out of range or malformed used to reach the
simulation thread and kill it for good (Time scale = NaN: int(nan) in the step count)
while the page still answered. Now the server checks every value: a bad one pauses the
run with a message, the loop stays alive, and Reset (the page's button) goes on.
"""

from __future__ import annotations

import math
import threading
import time

import msgspec
import pytest

from conftest import start_viewer

pytest.importorskip("viser")

CAMERA = {
    "wxyz": (1.0, 0.0, 0.0, 0.0),
    "position": (0.0, 0.0, 3.0),
    "fov": 1.0,
    "near": 0.01,
    "far": 100.0,
    "image_height": 600,
    "image_width": 800,
    "look_at": (0.0, 0.0, 0.0),
    "up_direction": (0.0, 1.0, 0.0),
}


@pytest.fixture
def viewer():
    """The hanging-ball scene in a viewer on a free loopback port."""
    v = start_viewer()
    yield v
    v.stop()


class Client:
    """A websocket client that speaks viser's protocol like the page: it announces its
    camera (viser runs GUI callbacks only for such connected clients), then sends
    messages; a thread drains what the server streams back."""

    def __init__(self, viewer):
        import viser
        from websockets.sync.client import connect

        port = viewer.server.get_port()
        self.conn = connect(
            f"ws://127.0.0.1:{port}/?token={viewer.url.partition('?token=')[2]}",
            origin=f"http://127.0.0.1:{port}",
            subprotocols=[f"viser-v{viser.__version__}"],
            open_timeout=10,
        )
        self._drain = threading.Thread(target=self._read, daemon=True)
        self._drain.start()
        self.send("ViewerCameraMessage", **CAMERA)
        time.sleep(0.5)

    def _read(self):
        try:
            while True:
                self.conn.recv()
        except Exception:
            return

    def send(self, kind: str, **fields):
        self.conn.send(msgspec.msgpack.encode({"type": kind, **fields}))

    def set(self, handle, value):
        """What the page sends when a control changes (a button click is value True)."""
        self.send("GuiUpdateMessage", uuid=handle._impl.uuid, updates={"value": value})

    def close(self):
        self.conn.close()


def wait_for(condition, timeout: float = 20.0) -> bool:
    deadline = time.perf_counter() + timeout
    while time.perf_counter() < deadline:
        if condition():
            return True
        time.sleep(0.05)
    return False


def assert_reset_goes_on(viewer, client):
    """Reset, pressed on the page, clears the message and the clock runs again."""
    client.set(viewer.reset_button, True)
    assert wait_for(lambda: viewer.running and viewer.message == "")
    t0 = viewer.state.time
    assert wait_for(lambda: viewer.state.time > t0 + 0.3)
    assert viewer._thread.is_alive()


def test_time_scale_nan_pauses_and_reset_goes_on(viewer):
    """Time scale = NaN (msgpack carries NaN): refused with a message naming the
    slider, the slider goes back to 1, the run pauses, the loop thread lives on, and
    Reset goes on."""
    client = Client(viewer)
    try:
        assert wait_for(lambda: viewer.state.time > 0.2)
        client.set(viewer.scale_slider, math.nan)
        assert wait_for(lambda: "Time scale" in viewer.message)
        assert viewer.message.startswith("paused") and "finite" in viewer.message
        assert not viewer.running and viewer.time_scale == 1.0
        assert viewer.scale_slider.value == 1.0
        time.sleep(0.5)
        assert viewer._thread.is_alive()
        assert_reset_goes_on(viewer, client)
    finally:
        client.close()


def test_negative_nrt_pauses_clamped_and_reset_goes_on(viewer):
    """nRT = -50 J for body 0 (the slider's range is 0..4 J): clamped to 0, never
    handed to the gas, the run pauses with a message naming the slider, the loop
    thread lives on, and Reset restores nRT = 1 J and goes on."""
    client = Client(viewer)
    try:
        client.set(viewer.gas_sliders[0], -50.0)
        assert wait_for(lambda: "nRT" in viewer.message)
        assert "outside" in viewer.message and not viewer.running
        # the handler pauses (the message) before it stores the clamped value, both under
        # the viewer's lock: wait for the handler to finish rather than race it
        with viewer.lock:
            assert viewer.control.body_gas_nrt[0] == 0.0
        assert viewer.gas_sliders[0].value == 0.0
        time.sleep(0.5)
        assert viewer._thread.is_alive()
        assert_reset_goes_on(viewer, client)
        # back to the scene's gas (NaN in the control: the model's own 1 J)
        assert viewer.gas_sliders[0].value == 1.0
        assert math.isnan(viewer.control.body_gas_nrt[0])
    finally:
        client.close()


def test_bad_menu_gizmo_and_click_values_pause_and_the_loop_lives(viewer):
    """An integrator the menu does not offer, a grab gizmo moved to a two-number
    position after a click (the step read it every loop and died), and a click ray of
    zero length: each pauses with its message; the loop thread lives on throughout,
    and Reset goes on."""
    client = Client(viewer)
    try:
        client.set(viewer.integrator_menu, "os.system")
        assert wait_for(lambda: "Integrator" in viewer.message)
        assert viewer.integrator_menu.value == "midpoint"
        client.set(viewer.pause_button, True)  # Play: a refused value needs no Reset
        assert wait_for(lambda: viewer.running)

        p0, _ = viewer.model.body_particle_range[1]
        x = viewer.state.particle_q[p0]
        click = {
            "name": "/bodies/1",
            "instance_index": None,
            "screen_pos": (0.5, 0.5),
            "modifier": None,
        }
        client.send(
            "SceneNodeClickMessage",
            ray_origin=(float(x[0]), float(x[1]), float(x[2]) + 3.0),
            ray_direction=(0.0, 0.0, -1.0),
            **click,
        )
        assert wait_for(lambda: viewer.grabbed is not None)
        client.send(
            "TransformControlsUpdateMessage",
            name="/grab_gizmo",
            wxyz=(1.0, 0.0, 0.0, 0.0),
            position=(1.0, 2.0),
        )
        assert wait_for(lambda: "Grab position" in viewer.message)
        time.sleep(0.5)
        assert viewer._thread.is_alive()

        client.send(
            "SceneNodeClickMessage", ray_origin=(0.0, 0.0, 3.0), ray_direction=(0, 0, 0), **click
        )
        assert wait_for(lambda: "click ray direction" in viewer.message)
        assert viewer._thread.is_alive()
        assert_reset_goes_on(viewer, client)
    finally:
        client.close()
