"""The browser viewer: simulates in real time and streams meshes to a viser (three.js) page.

The simulation runs in a background thread. Each loop it advances the state by the wall
time since the last loop times the time scale (as many steps as that takes, capped so
that the page still gets at least 20 updates a second when the machine cannot keep up),
then pushes the new vertex positions, overlays and readouts to every connected page.
Parameters that live in the immutable Model (stiffness, damping, gravity, volume method)
are changed by building a new Model with ``dataclasses.replace``; gas goes through
``Control``. A blow-up pauses the simulation with its message; Reset restores the start.
"""

from __future__ import annotations

import atexit
import contextlib
import dataclasses
import html
import io
import math
import socket
import sys
import threading
import time
import warnings
from collections import deque

import numpy as np

from softbody.collision.colliders import ColliderKind
from softbody.collision.mesh_collider import collider_mesh
from softbody.diagnostics import body_pressure, body_volume
from softbody.errors import SimulationError, StabilityWarning
from softbody.gas import GasLaw
from softbody.integrators import Integrator
from softbody.render.frame import BOX_CORNERS, BOX_EDGES, PALETTE, bounding_segments, hex_rgb
from softbody.sim.model import Model
from softbody.sim.simulator import Simulator
from softbody.sim.state import State
from softbody.viewer.guard import Guard, is_loopback, start_guarded
from softbody.volume import VolumeMethod

VOLUME_METHODS = [m.name.lower() for m in VolumeMethod]
INTEGRATORS = [m.name.lower() for m in Integrator]
HISTORY_SECONDS = 10.0
#: Updates sent to the page per second (when the simulation keeps up).
UPDATE_RATE = 30.0
#: Readout and plot refreshes per second.
READOUT_RATE = 4.0


def _check_address(host: str, port: int) -> None:
    """Refuse a port outside 0..65535 or a host that names no address, before viser
    tries (its server thread dies on the first and retries 1000 ports on the second)."""
    if isinstance(port, bool) or not isinstance(port, int | np.integer):
        raise ValueError(f"viewer port must be an integer, got {port!r}")
    if not 0 <= port <= 65535:
        raise ValueError(f"viewer port must be in 0..65535, got {port}")
    try:
        socket.getaddrinfo(host.strip("[]"), port, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError) as exc:
        raise ValueError(f"viewer host {host!r} is not an address to bind: {exc}") from None


#: Ports viser tries from the one asked for, the next when one is taken.
PORT_ATTEMPTS = 1000


def _free_port(host: str, port: int) -> int:
    """The first port from ``port`` on (at most :data:`PORT_ATTEMPTS`, none past 65535)
    that every address of ``host`` can bind, as viser would pick it; ``port`` 0 stays 0
    (the system picks). ValueError when all are taken: viser would go on past 65535 and
    its server thread would die with a traceback."""
    if port == 0:
        return 0
    infos = socket.getaddrinfo(host.strip("[]"), port, type=socket.SOCK_STREAM)
    last = min(port + PORT_ATTEMPTS - 1, 65535)
    for candidate in range(port, last + 1):
        try:
            for family, kind, proto, _, address in infos:
                with socket.socket(family, kind, proto) as sock:
                    # as asyncio's server does: a port in TIME_WAIT is free
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                    sock.bind((address[0], candidate, *address[2:]))
        except OSError:
            continue
        return candidate
    span = f"port {port} is" if last == port else f"ports {port} to {last} are"
    raise ValueError(
        f"viewer {span} taken on {host}; choose another with --port (0: any free one)"
    )


def _start_server(host: str, port: int, guard: Guard):
    """A viser server on ``host``:``port`` behind ``guard``, without viser's own banner
    (its URL lacks the token) and without its share-URL tunnel (a client could ask it to
    open the viewer to the internet through an outside relay)."""
    import viser
    from viser import _messages

    def build():
        with contextlib.redirect_stdout(io.StringIO()):
            return viser.ViserServer(host=host, port=int(port), verbose=False)

    server = start_guarded(build, guard)
    infra = server._websock_server
    for message in (_messages.ShareUrlRequest, _messages.ShareUrlDisconnect):
        if message in infra._incoming_handlers:
            infra.unregister_handler(message)
    server.gui.configure_theme(show_share_button=False)
    return server


def _with_user_ball(model: Model, state: State) -> tuple[Model, State, int]:
    """The model with a rigid sphere the user drives (its first sphere collider if it has
    one, else a new one parked above the scene), the matching state, and its index."""
    spheres = np.flatnonzero(model.collider_kind == ColliderKind.SPHERE)
    if len(spheres):
        return model, state, int(spheres[0])
    q = model.particle_q
    lo, hi = q.min(axis=0), q.max(axis=0)
    size = float(np.linalg.norm(hi - lo))
    radius = 0.12 * size
    park = np.array([lo[0] - 3.0 * radius, 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])])

    def append(name, row):
        return np.concatenate([getattr(model, name), np.asarray(row)[None]])

    model = dataclasses.replace(
        model,
        collider_kind=append("collider_kind", ColliderKind.SPHERE),
        collider_center=append("collider_center", park),
        collider_rotation=append("collider_rotation", np.eye(3)),
        collider_size=append("collider_size", [radius] * 3),
        collider_restitution=append("collider_restitution", 0.5),
        collider_friction=append("collider_friction", 0.1),
        collider_motion=append("collider_motion", 0),
        collider_motion_vector=append("collider_motion_vector", np.zeros(3)),
        collider_motion_pivot=append("collider_motion_pivot", park),
        collider_motion_frequency=append("collider_motion_frequency", 0.0),
        collider_mesh_range=append("collider_mesh_range", [0, 0]),
        collider_mesh_root=append("collider_mesh_root", -1),
        collider_mesh_margin=append("collider_mesh_margin", 0.0),
    )
    state = State(
        state.particle_q.copy(),
        state.particle_qd.copy(),
        state.time,
        state.step_count,
        np.vstack([state.collider_q, park]),
        np.concatenate([state.collider_rotation, np.eye(3)[None]]),
        body_gas_moles=state.body_gas_moles,
        body_gas_temperature=state.body_gas_temperature,
        vent_open=state.vent_open,
    )
    return model, state, model.collider_count - 1


def _quaternion(rot: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of a rotation matrix (3, 3)."""
    w = np.sqrt(max(0.0, 1.0 + np.trace(rot))) / 2.0
    if w > 1e-6:
        return np.array(
            [
                w,
                (rot[2, 1] - rot[1, 2]) / (4 * w),
                (rot[0, 2] - rot[2, 0]) / (4 * w),
                (rot[1, 0] - rot[0, 1]) / (4 * w),
            ]
        )
    k = int(np.argmax(np.diag(rot)))
    i, j = (k + 1) % 3, (k + 2) % 3
    s = np.sqrt(max(0.0, 1.0 + rot[k, k] - rot[i, i] - rot[j, j])) * 2
    q = np.zeros(4)
    q[0] = (rot[j, i] - rot[i, j]) / s
    q[1 + k] = s / 4
    q[1 + i] = (rot[i, k] + rot[k, i]) / s
    q[1 + j] = (rot[j, k] + rot[k, j]) / s
    return q


class _BadInput(ValueError):
    """A value a client sent that the server refused or clamped."""


class Viewer:
    """A running viewer. Create with :func:`softbody.viewer.show`."""

    def __init__(
        self,
        model: Model,
        state: State,
        simulator: Simulator,
        *,
        host: str = "127.0.0.1",
        port: int = 8080,
        body_names: list[str] | None = None,
        body_colors: tuple[str, ...] | None = None,
        camera: tuple | None = None,
    ):
        _check_address(host, port)
        port = _free_port(host, port)
        model, state, self.ball = _with_user_ball(model, state)
        self.model = model
        self.initial_model = model
        self.initial_state = state.copy()
        self.state = state.copy()
        self.integrator = simulator.integrator.name.lower()
        self.dt = simulator.dt
        # the caller's solver, checks and threads carry over to every rebuilt simulator
        self.sim_options = simulator.options
        self.control = model.control()
        self.body_names = body_names or [f"body {b}" for b in range(model.body_count)]
        colors = body_colors or PALETTE
        self.colors = [
            tuple(int(255 * c) for c in hex_rgb(colors[b % len(colors)]))
            for b in range(model.body_count)
        ]
        self.lock = threading.RLock()
        self.running = True
        self.time_scale = 1.0
        self.message = ""
        self.updates_per_second = 0.0
        self.realtime_factor = 0.0
        self.grabbed: int | None = None
        #: a blow-up or an unexpected error in a step: only Reset goes on from here
        self.needs_reset = False
        self._grab_target: np.ndarray | None = None
        self._logged = ""
        #: (low, high, label) of each slider, kept here: a client may rewrite a slider's
        #: min and max on the page, so those are never trusted
        self._limits: dict[int, tuple[float, float, str]] = {}
        #: the last accepted value of each control, by id of its handle
        self._good: dict[int, object] = {}
        self._stop = threading.Event()
        self._close_lock = threading.Lock()
        self._closed = False
        self._history: deque = deque()
        self._restoring = False
        self._last_readout = 0.0
        self._volume_method = [VolumeMethod(int(m)).name.lower() for m in model.body_volume_method]

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", StabilityWarning)
            self.sim = Simulator(model, integrator=self.integrator, dt=self.dt, **self.sim_options)
        # compile (or load) the kernels now, so the page never shows a frozen scene
        self.sim.run(self.state.copy(), 1, self.control)

        self.host = host
        self.guard = Guard(loopback=is_loopback(host))
        self.server = _start_server(host, port, self.guard)
        try:
            self.server.scene.set_up_direction("+y")
            self._camera = camera
            self.server.on_client_connect(self._guarded(self._on_connect, "connect"))
            self._workspace = self._workspace_box()
            self._build_scene()
            self._build_gui()
        except BaseException:
            self.server.stop()
            raise
        self._thread = threading.Thread(target=self._loop, name="softbody-viewer", daemon=True)
        self._thread.start()
        # a script that ends without close() stops the viewer on the way out, before the
        # interpreter tears down the objects the simulation thread still uses
        atexit.register(self.stop)

    # -- public ----------------------------------------------------------------------------
    @property
    def port(self) -> int:
        """The port the server is bound to (viser moves on to the next one if taken)."""
        return int(self.server.get_port())

    @property
    def url(self) -> str:
        """Address of the page, with the access token (``http://HOST:PORT/?token=...``).

        A wildcard bind (0.0.0.0, ::) is shown as the loopback address of its family.
        """
        host = {"0.0.0.0": "127.0.0.1", "": "127.0.0.1", "::": "::1"}.get(self.host, self.host)
        if ":" in host and not host.startswith("["):
            host = f"[{host}]"
        return f"http://{host}:{self.port}/?token={self.guard.token}"

    @property
    def exposed(self) -> bool:
        """True if the server is bound to a non-loopback address (reachable from the
        network; the token still protects it)."""
        return not self.guard.loopback

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` (or :meth:`stop`) ended the viewer."""
        return self._closed

    def stop(self) -> None:
        """Stop the simulation thread and the server, freeing its port; safe to call more
        than once."""
        with self._close_lock:
            if self._closed:
                return
            self._closed = True
        atexit.unregister(self.stop)
        self._stop.set()
        self._thread.join(timeout=5)
        self.server.stop()

    def close(self) -> None:
        """Same as :meth:`stop`: end the simulation and the server, free the port."""
        self.stop()

    def __enter__(self) -> Viewer:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def __repr__(self) -> str:
        state = "closed" if self._closed else self.url
        return f"Viewer({state})"

    def _repr_html_(self) -> str:
        """A link to the page (a notebook shows it as the cell's output)."""
        if self._closed:
            return "<p>softbody viewer (closed)</p>"
        url = html.escape(self.url, quote=True)
        return (
            f'<p>softbody viewer: <a href="{url}" target="_blank" rel="noopener">{url}</a> '
            "(<code>.close()</code> stops it)</p>"
        )

    def wait(self) -> None:
        """Block until interrupted (Ctrl-C), then stop."""
        try:
            while not self._stop.is_set():
                time.sleep(0.2)
        except KeyboardInterrupt:
            pass
        finally:
            self.stop()

    # -- scene -----------------------------------------------------------------------------
    def _on_connect(self, client) -> None:
        q = self.state.particle_q
        lo, hi = q.min(axis=0), q.max(axis=0)
        center = 0.5 * (lo + hi)
        size = max(float(np.linalg.norm(hi - lo)), 1e-3)
        if self._camera is not None:
            eye, target = self._camera
        else:
            eye, target = center + np.array([0.0, 0.35, 1.6]) * size, center
        client.camera.position = tuple(float(x) for x in eye)
        client.camera.look_at = tuple(float(x) for x in target)

    def _build_scene(self) -> None:
        scene = self.server.scene
        model, state = self.model, self.state
        scene.add_light_hemisphere(
            "/light/sky", sky_color=(255, 255, 255), ground_color=(110, 110, 120), intensity=0.6
        )
        scene.add_light_directional("/light/sun", intensity=1.0, wxyz=(0.92, -0.28, 0.25, 0.0))
        self.meshes = []
        for b, (p0, p1) in enumerate(model.body_particle_range):
            t0, t1 = model.body_tri_range[b]
            self.meshes.append(
                scene.add_mesh_simple(
                    f"/bodies/{b}",
                    vertices=state.particle_q[p0:p1].astype(np.float32),
                    faces=(model.tri_indices[t0:t1] - p0).astype(np.uint32),
                    color=self.colors[b],
                    side="double" if model.body_closed[b] == 0 else "front",
                    cast_shadow=False,
                    receive_shadow=False,
                )
            )
        self.collider_nodes = []
        for c in range(model.collider_count):
            kind = int(model.collider_kind[c])
            center, rot = state.collider_q[c], state.collider_rotation[c]
            size = model.collider_size[c]
            if kind == ColliderKind.PLANE:
                node = scene.add_grid(
                    f"/colliders/{c}",
                    width=20.0,
                    height=20.0,
                    plane="xz",
                    position=tuple(center),
                    cell_size=0.25,
                    section_size=1.0,
                    plane_color=(235, 235, 235),
                    plane_opacity=0.6,
                    shadow_opacity=0.0,
                )
            elif kind == ColliderKind.SPHERE:
                node = scene.add_icosphere(
                    f"/colliders/{c}",
                    radius=float(size[0]),
                    color=(150, 150, 160) if c != self.ball else (200, 90, 60),
                    position=tuple(center),
                )
            elif kind == ColliderKind.MESH:
                local, tris = collider_mesh(model, c)
                node = scene.add_mesh_simple(
                    f"/colliders/{c}",
                    vertices=local.astype(np.float32),
                    faces=tris.astype(np.uint32),
                    color=(160, 160, 165),
                    flat_shading=True,
                    position=tuple(center),
                    wxyz=tuple(_quaternion(rot)),
                )
            elif kind == ColliderKind.BOX:
                node = scene.add_box(
                    f"/colliders/{c}",
                    color=(160, 160, 165),
                    dimensions=tuple(2 * size),
                    position=tuple(center),
                    wxyz=tuple(_quaternion(rot)),
                )
            else:
                node = scene.add_line_segments(
                    f"/colliders/{c}",
                    self._box_lines(c),
                    colors=(60, 60, 70),
                    thickness=2.0,
                    thickness_units="screen",
                )
            self.collider_nodes.append(node)
        self.ball_gizmo = scene.add_transform_controls(
            "/ball_gizmo",
            scale=float(3 * model.collider_size[self.ball, 0] + 0.05),
            disable_rotations=True,
            position=tuple(state.collider_q[self.ball]),
        )
        self.ball_gizmo.on_update(self._guarded(self._on_ball_moved, "Ball"))
        self.grab_gizmo = scene.add_transform_controls(
            "/grab_gizmo", scale=0.15, disable_rotations=True, visible=False
        )
        self.grab_gizmo.on_update(self._guarded(self._on_grab_moved, "Grab"))
        for b, mesh in enumerate(self.meshes):
            mesh.on_click(self._guarded(lambda event, b=b: self._on_mesh_click(b, event), "Click"))
        self._overlays: dict = {}

    def _box_lines(self, c: int) -> np.ndarray:
        corners = (
            self.state.collider_q[c]
            + (BOX_CORNERS * self.model.collider_size[c]) @ self.state.collider_rotation[c].T
        )
        return corners[BOX_EDGES].astype(np.float32)

    # -- gui -------------------------------------------------------------------------------
    def _slider(self, label: str, low: float, high: float, step: float, value: float):
        """A slider whose values the server accepts only within [low, high]."""
        handle = self.server.gui.add_slider(
            label, min=low, max=high, step=step, initial_value=value
        )
        self._limits[id(handle)] = (float(low), float(high), label)
        self._good[id(handle)] = float(value)
        return handle

    def _build_gui(self) -> None:
        gui = self.server.gui
        model = self.model
        on = self._guarded
        with gui.add_folder("Simulation"):
            self.pause_button = gui.add_button("Pause")
            self.pause_button.on_click(on(lambda _: self._toggle_pause(), "Pause"))
            self.step_button = gui.add_button("Step")
            self.step_button.on_click(on(lambda _: self._step_once(), "Step"))
            self.reset_button = gui.add_button("Reset")
            self.reset_button.on_click(on(lambda _: self._reset(), "Reset"))
            self.scale_slider = self._slider("Time scale", 0.05, 2.0, 0.05, 1.0)
            self.scale_slider.on_update(on(lambda _: self._scale_changed(), "Time scale"))
            self.integrator_menu = gui.add_dropdown(
                "Integrator", INTEGRATORS, initial_value=self.integrator
            )
            self.integrator_menu.on_update(on(lambda _: self._rebuild(), "Integrator"))
            self.volume_menu = gui.add_dropdown(
                "Volume method", VOLUME_METHODS, initial_value=self._volume_method[0]
            )
            self.volume_menu.on_update(on(lambda _: self._rebuild(), "Volume method"))
            g = float(model.gravity[1])
            self.gravity_slider = self._slider(
                "Gravity y [m/s^2]", min(-20.0, g), max(5.0, g), 0.1, round(g, 2)
            )
            self.gravity_slider.on_update(on(lambda _: self._rebuild(), "Gravity"))
        self.gas_sliders, self.stiffness_sliders, self.damping_sliders = [], [], []
        with gui.add_folder("Bodies"):
            for b in range(model.body_count):
                name = self.body_names[b]
                law = GasLaw(int(model.body_gas_law[b]))
                value = float(model.body_gas_value[b])
                label = "pressure [Pa]" if law == GasLaw.FIXED_PRESSURE else "nRT [J]"
                top = max(4.0 * value, 1.0)
                slider = self._slider(f"{name}: {label}", 0.0, top, top / 400, value)
                slider.on_update(on(lambda _, b=b: self._gas_changed(b), f"{name}: {label}"))
                self.gas_sliders.append(slider)
                springs = model.spring_body == b
                k = float(model.spring_stiffness[springs].max()) if springs.any() else 0.0
                c = float(model.spring_damping[springs].max()) if springs.any() else 0.0
                ktop, ctop = max(4 * k, 1.0), max(4 * c, 0.1)
                ks = self._slider(f"{name}: stiffness [N/m]", 0.0, ktop, ktop / 400, k)
                cs = self._slider(f"{name}: damping [N s/m]", 0.0, ctop, ctop / 400, c)
                ks.on_update(on(lambda _: self._rebuild(), f"{name}: stiffness"))
                cs.on_update(on(lambda _: self._rebuild(), f"{name}: damping"))
                self.stiffness_sliders.append(ks)
                self.damping_sliders.append(cs)
        with gui.add_folder("Display"):
            self.wireframe_box = gui.add_checkbox("Wireframe", False)
            self.wireframe_box.on_update(on(lambda _: self._set_wireframe(), "Wireframe"))
            self.velocity_box = gui.add_checkbox("Velocity vectors", False)
            self.bounding_box = gui.add_checkbox("Bounding objects", False)
        with gui.add_folder("Interaction"):
            gui.add_markdown(
                "Pull the orange ball's arrows to hit a body. Click a body to "
                "grab the nearest vertex, then pull the small arrows."
            )
            self.release_button = gui.add_button("Release vertex")
            self.release_button.on_click(on(lambda _: self._release(), "Release"))
        self._initial_values = [handle.value for handle in self._controls()]
        for handle, value in zip(self._controls(), self._initial_values, strict=True):
            self._good[id(handle)] = value
        with gui.add_folder("Readouts"):
            self.readout = gui.add_markdown("starting...")
            self.plot = gui.add_uplot(
                data=(np.zeros(1), np.zeros(1), np.zeros(1)),
                series=(
                    self._series("t"),
                    self._series("volume (body 0) [m^3]", "#4e79a7"),
                    self._series("pressure (body 0) [Pa]", "#e15759", scale="p"),
                ),
                scales={"x": self._scale(True), "y": self._scale(), "p": self._scale()},
                aspect=1.6,
            )

    @staticmethod
    def _series(label, stroke=None, scale=None):
        import viser.uplot as uplot

        kwargs = {"label": label}
        if stroke:
            kwargs.update(stroke=stroke, width=2)
        if scale:
            kwargs["scale"] = scale
        return uplot.Series(**kwargs)

    @staticmethod
    def _scale(time_axis=False):
        import viser.uplot as uplot

        return uplot.Scale(time=False, auto=True) if time_axis else uplot.Scale(auto=True)

    # -- input checks ----------------------------------------------------------------------
    def _guarded(self, callback, what: str):
        """``callback`` for viser: a rejected value or any error pauses the run with a
        message on the page and the console instead of a traceback in viser's threads."""

        def run(*args):
            try:
                return callback(*args)
            except _BadInput as exc:
                self._pause(f"paused: {exc}. Press Play to go on, or Reset.")
            except Exception as exc:
                self._pause(f"paused: {what} failed: {type(exc).__name__}: {exc}. Press Reset.")
                with self.lock:
                    self.needs_reset = True

        return run

    def _pause(self, message: str) -> None:
        """Pause with ``message`` on the page, and print it once on the server's console."""
        with self.lock:
            self.message = message
            if self.running:
                self._toggle_pause()
        if message != self._logged:
            self._logged = message
            print(f"softbody view: {message}", file=sys.stderr, flush=True)

    def _write_back(self, handle, value) -> None:
        """Show ``value`` in ``handle`` without running its callbacks again."""
        with self.lock:
            self._restoring = True
            try:
                handle.value = value
            finally:
                self._restoring = False

    def _read_slider(self, handle) -> float:
        """The slider's value, checked: a value that is not a finite number is refused
        (the slider goes back to its last good value; raises _BadInput), one outside the
        slider's range is clamped into it (and pauses with a message)."""
        low, high, label = self._limits[id(handle)]
        raw = handle.value
        try:
            value = float(raw)
        except (TypeError, ValueError, OverflowError):
            value = math.nan
        good = self._good.get(id(handle))
        if not math.isfinite(value):
            self._write_back(handle, good)
            raise _BadInput(f"{label} = {raw!r} is not a finite number; kept {good:g}")
        if not low <= value <= high:
            clamped = min(max(value, low), high)
            self._write_back(handle, clamped)
            self._pause(
                f"paused: {label} = {value:g} is outside [{low:g}, {high:g}]; set to "
                f"{clamped:g}. Press Play to go on, or Reset."
            )
            value = clamped
        self._good[id(handle)] = value
        return value

    def _read_choice(self, handle, options: list[str], label: str) -> str:
        """The dropdown's value if it is one of ``options``, else _BadInput (and the
        dropdown goes back to its last good value)."""
        value = handle.value
        if isinstance(value, str) and value in options:
            self._good[id(handle)] = value
            return value
        good = self._good[id(handle)]
        self._write_back(handle, good)
        raise _BadInput(f"{label} = {value!r} is not one of {', '.join(options)}; kept {good}")

    def _workspace_box(self) -> tuple[np.ndarray, np.ndarray]:
        """Where the ball and a grabbed vertex may be driven: the bodies' and colliders'
        box, grown by twice its size each way."""
        points = np.vstack([self.state.particle_q, self.state.collider_q])
        lo, hi = points.min(axis=0), points.max(axis=0)
        size = max(float(np.linalg.norm(hi - lo)), 1.0)
        return lo - 2.0 * size, hi + 2.0 * size

    def _point(self, value, label: str) -> np.ndarray:
        """``value`` as a finite (3,) point inside the workspace (clamped into it)."""
        try:
            point = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            point = np.full(1, np.nan)
        if point.shape != (3,) or not np.all(np.isfinite(point)):
            raise _BadInput(f"{label} position {value!r} is not three finite numbers")
        return np.clip(point, *self._workspace)

    # -- callbacks -------------------------------------------------------------------------
    def _toggle_pause(self) -> None:
        with self.lock:
            if not self.running and self.needs_reset:
                # a blown-up or failed run cannot go on: keep its message, wait for Reset
                return
            self.running = not self.running
            if self.running and self.message.startswith("paused"):
                self.message = ""
        self.pause_button.label = "Pause" if self.running else "Play"

    def _step_once(self) -> None:
        with self.lock:
            if self.running:
                self._toggle_pause()
            if not self.needs_reset:
                self._advance(1)
        self._push(force_readout=True)

    def _controls(self) -> list:
        """Every parameter control whose change rebuilds or re-drives the simulation."""
        return [
            self.scale_slider,
            self.integrator_menu,
            self.volume_menu,
            self.gravity_slider,
            *self.gas_sliders,
            *self.stiffness_sliders,
            *self.damping_sliders,
        ]

    def _reset(self) -> None:
        """Back to the starting state and parameters (also after a blow-up, an error or
        a refused value)."""
        with self.lock:
            self._restoring = True
            try:
                for handle, value in zip(self._controls(), self._initial_values, strict=True):
                    handle.value = value
                    self._good[id(handle)] = value
            finally:
                self._restoring = False
            self.time_scale = float(self.scale_slider.value)
            self.model = self.initial_model
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", StabilityWarning)
                self.sim = Simulator(
                    self.model, integrator=self.integrator, dt=self.dt, **self.sim_options
                )
            self.state = self.initial_state.copy()
            self.control = self.model.control()
            self._history.clear()
            self.message = ""
            self._logged = ""
            self.needs_reset = False
            self.grabbed = None
            self._grab_target = None
            self.grab_gizmo.visible = False
            self.ball_gizmo.position = tuple(self.state.collider_q[self.ball])
            if not self.running:
                self._toggle_pause()
        self._push(force_readout=True)

    def _scale_changed(self) -> None:
        with self.lock:
            if self._restoring:
                return
            self.time_scale = self._read_slider(self.scale_slider)

    def _gas_changed(self, b: int) -> None:
        with self.lock:
            if self._restoring:
                return
            value = self._read_slider(self.gas_sliders[b])
            if self.model.body_gas_law[b] == GasLaw.FIXED_PRESSURE:
                self.control.body_gas_pressure[b] = value
            else:
                self.control.body_gas_nrt[b] = value

    def _rebuild(self) -> None:
        """A new Model for changed stiffness, damping, gravity or volume method."""
        with self.lock:
            if self._restoring:
                return
            base = self.initial_model
            # every value is read through the checks, not only the one that changed: a
            # client can set a control's value without triggering its callback
            stiffness = [self._read_slider(h) for h in self.stiffness_sliders]
            damping = [self._read_slider(h) for h in self.damping_sliders]
            gravity_y = self._read_slider(self.gravity_slider)
            integrator = self._read_choice(self.integrator_menu, INTEGRATORS, "Integrator")
            method_name = self._read_choice(self.volume_menu, VOLUME_METHODS, "Volume method")
            k = base.spring_stiffness.copy()
            c = base.spring_damping.copy()
            for b in range(base.body_count):
                mask = base.spring_body == b
                if mask.any():
                    k0, c0 = base.spring_stiffness[mask].max(), base.spring_damping[mask].max()
                    k[mask] *= (stiffness[b] / k0) if k0 > 0 else 0.0
                    c[mask] = c[mask] * damping[b] / c0 if c0 > 0 else damping[b]
            gravity = base.gravity.copy()
            gravity[1] = gravity_y
            method = VolumeMethod.parse(method_name)
            methods = np.where(base.body_closed == 1, int(method), 0).astype(np.int64)
            samples, mc_range = base.mc_samples, base.body_mc_range
            if method == VolumeMethod.MONTE_CARLO:
                samples = np.random.default_rng(0).random((2048, 2))
                mc_range = np.tile([0, 2048], (base.body_count, 1))
            model = dataclasses.replace(
                base,
                spring_stiffness=k,
                spring_damping=c,
                gravity=gravity,
                body_volume_method=methods,
                mc_samples=samples,
                body_mc_range=mc_range,
            )
            rest = body_volume(
                model,
                State(
                    base.particle_q,
                    base.particle_qd,
                    collider_q=base.collider_center,
                    collider_rotation=base.collider_rotation,
                ),
            )
            model = dataclasses.replace(
                model, body_rest_volume=np.where(np.isnan(rest), base.body_rest_volume, rest)
            )
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", StabilityWarning)
                self.sim = Simulator(model, integrator=integrator, dt=self.dt, **self.sim_options)
            if caught:
                self.message = str(caught[0].message)
            elif not self.message.startswith("paused"):
                self.message = ""
            self.model = model
            control = model.control()
            control.body_gas_nrt[:] = self.control.body_gas_nrt
            control.body_gas_pressure[:] = self.control.body_gas_pressure
            control.collider_target = self.control.collider_target
            self.control = control

    def _set_wireframe(self) -> None:
        for mesh in self.meshes:
            mesh.wireframe = bool(self.wireframe_box.value)

    def _on_ball_moved(self, _) -> None:
        point = self._point(self.ball_gizmo.position, "Ball")
        with self.lock:
            target = np.full((self.model.collider_count, 3), np.nan)
            target[self.ball] = point
            self.control.collider_target = target

    def _on_grab_moved(self, _) -> None:
        point = self._point(self.grab_gizmo.position, "Grab")
        with self.lock:
            self._grab_target = point

    def _on_mesh_click(self, b: int, event) -> None:
        """Grab the vertex of body b nearest the click ray."""
        origin = self._point(event.ray_origin, "Click ray origin")
        try:
            direction = np.asarray(event.ray_direction, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            direction = np.full(1, np.nan)
        length = np.linalg.norm(direction) if direction.shape == (3,) else np.nan
        if not (np.isfinite(length) and length > 1e-12 and np.all(np.isfinite(direction))):
            raise _BadInput(f"click ray direction {event.ray_direction!r} is not a direction")
        direction = direction / length
        with self.lock:
            p0, p1 = self.model.body_particle_range[b]
            x = self.state.particle_q[p0:p1] - origin
            along = x @ direction
            dist = np.linalg.norm(x - along[:, None] * direction, axis=1)
            dist[along < 0] = np.inf
            if not np.any(np.isfinite(dist)):
                return  # the body is behind the camera, or blown up: nothing to grab
            # the ray also passes near vertices on the far side: of those near the ray
            # (within half an edge of the nearest), take the one nearest the camera
            t0, t1 = self.model.body_tri_range[b]
            tri = self.model.tri_indices[t0:t1] - p0
            edge = float(np.median(np.linalg.norm(x[tri[:, 1]] - x[tri[:, 0]], axis=1)))
            near = dist <= dist.min() + 0.5 * edge
            i = int(p0 + np.flatnonzero(near)[np.argmin(along[near])])
            self.grabbed = i
            self._grab_target = self.state.particle_q[i].copy()
        self.grab_gizmo.position = tuple(self._grab_target)
        self.grab_gizmo.visible = True

    def _release(self) -> None:
        with self.lock:
            self.grabbed = None
            self._grab_target = None
            self.control.grab_particle = -1
        self.grab_gizmo.visible = False

    # -- loop ------------------------------------------------------------------------------
    def _advance(self, steps: int) -> None:
        """Run ``steps`` steps (lock held); a blow-up pauses with its message."""
        if self.grabbed is not None:
            try:
                # the gizmo's position as it is now (set by a page or by a script)
                self._grab_target = self._point(self.grab_gizmo.position, "Grab")
            except _BadInput as exc:
                self.grabbed, self.control.grab_particle = None, -1
                self._pause(f"paused: {exc}; vertex released. Press Play to go on, or Reset.")
                return
            i = self.grabbed
            m = float(self.model.particle_mass[i])
            omega = 0.3 / self.dt  # stiff, yet well inside every integrator's stable range
            self.control.grab_particle = i
            self.control.grab_target = self._grab_target.copy()
            self.control.grab_stiffness = m * omega**2
            self.control.grab_damping = 2.0 * m * omega  # critically damped
        try:
            self.sim.run(self.state, steps, self.control, progress=False)
        except SimulationError as exc:
            self.needs_reset = True
            self._pause(f"paused: {exc}. Press Reset.")
        if self.control.collider_target is not None:
            # the ball stays where it was driven to
            self.control.collider_target = None

    def _loop(self) -> None:
        """The simulation thread. It never dies of an error: an exception in a step or an
        update pauses the run with its message (Reset goes on); only stop() ends it."""
        last = time.perf_counter()
        carry = 0.0
        step_cost = 1e-5
        updates = deque(maxlen=60)
        while not self._stop.is_set():
            now = time.perf_counter()
            try:
                wall = min(now - last, 0.25)
                last = now
                with self.lock:
                    if self.running and not self.needs_reset:
                        want = wall * self.time_scale / self.dt + carry
                        cap = max(1, int(0.05 / step_cost))  # keep >= 20 updates per second
                        steps = min(int(want), cap)
                        carry = min(want - steps, 1.0)
                        if steps:
                            t0 = time.perf_counter()
                            t_sim = self.state.time
                            self._advance(steps)
                            spent = time.perf_counter() - t0
                            step_cost = 0.8 * step_cost + 0.2 * spent / steps
                            self.realtime_factor = (self.state.time - t_sim) / max(wall, 1e-6)
                    else:
                        self.realtime_factor = 0.0
                self._push()
            except Exception as exc:
                carry = 0.0
                with self.lock:
                    self.needs_reset = True
                self._pause(f"paused: {type(exc).__name__}: {exc}. Press Reset.")
            updates.append(time.perf_counter())
            if len(updates) > 1:
                self.updates_per_second = (len(updates) - 1) / max(updates[-1] - updates[0], 1e-6)
            rest = 1.0 / UPDATE_RATE - (time.perf_counter() - now)
            if rest > 0:
                time.sleep(rest)

    def _push(self, force_readout: bool = False) -> None:
        """Send vertex positions and overlays to the page, and readouts at READOUT_RATE."""
        with self.lock:
            state = self.state.copy()
            model = self.model
            control_values = self.control.body_gas_nrt.copy()
            message = self.message
        with self.server.atomic():
            for b, (p0, p1) in enumerate(model.body_particle_range):
                self.meshes[b].vertices = state.particle_q[p0:p1].astype(np.float32)
            for c, node in enumerate(self.collider_nodes):
                kind = int(model.collider_kind[c])
                if kind == ColliderKind.BOX_CONTAINER:
                    node.points = self._box_lines(c)
                elif kind in (ColliderKind.SPHERE, ColliderKind.BOX, ColliderKind.MESH):
                    node.position = tuple(state.collider_q[c])
                    node.wxyz = tuple(_quaternion(state.collider_rotation[c]))
            self._push_overlays(model, state)
        # readouts and the plot: a few times a second (costly to measure and to redraw)
        wall = time.perf_counter()
        if wall - self._last_readout < 1.0 / READOUT_RATE and not force_readout:
            return
        self._last_readout = wall
        now = state.time
        volumes = body_volume(model, state)
        pressures = body_pressure(
            model, state, None if np.all(np.isnan(control_values)) else self.control
        )
        self._history.append((now, volumes[0], pressures[0]))
        while self._history and self._history[0][0] < now - HISTORY_SECONDS:
            self._history.popleft()
        rows = [
            f"| {self.body_names[b]} | {volumes[b]:.4g} | {pressures[b]:.4g} |"
            for b in range(model.body_count)
        ]
        self.readout.content = "\n".join(
            [
                f"**t = {now:.2f} s** · {'running' if self.running else 'paused'} · "
                f"{self.realtime_factor:.2f}x real time · {self.updates_per_second:.0f} updates/s",
                "",
                "| body | volume [m^3] | pressure [Pa] |",
                "|---|---|---|",
                *rows,
                "",
                f"*{message}*" if message else "",
            ]
        )
        hist = np.array(self._history)
        if len(hist) > 1:
            self.plot.data = (hist[:, 0], hist[:, 1], hist[:, 2])

    def _overlay(self, name: str, segments: np.ndarray | None, color) -> None:
        """Show ``segments`` (K, 2, 3) as the overlay ``name``, or hide it if None."""
        node = self._overlays.get(name)
        if segments is None:
            if node is not None:
                node.visible = False
            return
        seg = segments.astype(np.float32)
        if node is None or len(node.points) != len(seg):
            if node is not None:
                node.remove()
            self._overlays[name] = self.server.scene.add_line_segments(
                f"/overlay/{name}", seg, colors=color, thickness=1.5, thickness_units="screen"
            )
        else:
            node.points = seg
            node.visible = True

    def _push_overlays(self, model: Model, state: State) -> None:
        q = state.particle_q
        velocity = None
        if self.velocity_box.value:
            velocity = np.stack([q, q + 0.05 * state.particle_qd], axis=1)
        self._overlay("velocity", velocity, (220, 30, 30))
        bounding = None
        if self.bounding_box.value:
            bounding = np.concatenate(
                [
                    np.concatenate(bounding_segments(q[p0:p1]))
                    for p0, p1 in model.body_particle_range
                ]
            )
        self._overlay("bounding", bounding, (40, 90, 220))


def show(
    model: Model,
    state: State | None = None,
    simulator: Simulator | None = None,
    *,
    host: str = "127.0.0.1",
    port: int = 8080,
    block: bool = True,
    body_names: list[str] | None = None,
    body_colors: tuple[str, ...] | None = None,
    camera: tuple | None = None,
    quiet: bool = False,
) -> Viewer:
    """Open a browser viewer on ``model`` (from ``state``, stepped like ``simulator``).

    Prints the page's address with its access token,
    ``http://127.0.0.1:PORT/?token=...`` (also ``viewer.url``; ``quiet=True`` prints
    nothing). The server listens on loopback only unless ``host`` says otherwise, and
    serves only a client that has the token (the user guide's viewer page says what
    it checks). ``port=0`` takes any free port; a taken port moves to the next free one.

    With ``block=True`` (default) it runs until Ctrl-C, then stops. With
    ``block=False`` it returns the running :class:`Viewer` at once, as a notebook or a
    script that goes on needs: ``viewer.url`` is the address, ``viewer.close()`` stops
    the simulation and the server and frees the port (a ``with`` block does it too; in
    a notebook the viewer shows as a link). The server's threads do not keep a script
    alive (it stops the viewer as it exits): call ``viewer.wait()`` at its end to serve
    until Ctrl-C.

    Raises ValueError for a port outside 0..65535 or a host that names no address, and
    RuntimeError if the server does not start (within 30 s) or its access checks
    cannot be installed.
    """
    state = model.state() if state is None else state
    if simulator is None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", StabilityWarning)
            simulator = Simulator(model, dt=1e-3)
    viewer = Viewer(
        model,
        state,
        simulator,
        host=host,
        port=port,
        body_names=body_names,
        body_colors=body_colors,
        camera=camera,
    )
    if not quiet:
        if viewer.exposed:
            print(
                f"softbody viewer: listening on {host}, reachable from the network; anyone "
                "with the token in the URL can drive it",
                flush=True,
            )
        print(
            f"softbody viewer: open {viewer.url} in a browser"
            + (" (Ctrl-C to stop)" if block else " (viewer.close() stops it)"),
            flush=True,
        )
    if block:
        viewer.wait()
    return viewer


__all__ = ["Viewer", "show"]
