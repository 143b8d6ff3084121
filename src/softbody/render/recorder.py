"""Record a model built in Python and save the clip as MP4, GIF, USD or a mesh sequence.

``Recorder`` is the Python path to what ``softbody run`` writes for a scene file::

    rec = sb.Recorder(model, fps=30)
    sim.advance(state, 2.0, record=rec)     # captures a frame every 1/30 s (61 frames)
    rec.save("drop.mp4")                    # or .gif, .usdc/.usda/.usd, or a folder
    rec.dataframe()                         # per-frame, per-body table (pandas)

A capture writes the frame's positions to a temporary file on disk (not to a list in
memory), so a long recording costs disk, not memory; :meth:`Recorder.save` renders or
converts the frames when asked and writes the output whole or not at all: into a
temporary folder next to the target, then renamed into place.
"""

from __future__ import annotations

import base64
import io
import math
import os
import re
import shutil
import tempfile
import weakref
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from softbody.diagnostics import body_center_of_mass, body_pressure, body_volume, energies
from softbody.render.frame import PALETTE, FrameRenderer, RenderSettings
from softbody.render.raster import Camera
from softbody.sim.control import Control
from softbody.sim.model import Model
from softbody.sim.state import State

#: Most frames one recorder holds unless asked for more (``max_frames``): 10^5 frames
#: are 55 minutes of video at 30 fps; more is almost always an fps or a duration off by
#: orders of magnitude (the CLI's limit, ``softbody.run.MAX_FRAMES``).
MAX_FRAMES = 100_000
#: The inline clip of a notebook (``_repr_html_``): at most this many frames (every
#: k-th frame of a longer recording) at most this many pixels wide.
REPR_MAX_FRAMES = 100
REPR_MAX_WIDTH = 320
#: The files a saved mesh sequence holds (``save(folder)``): frame_00000.obj, ...
FRAME_FILE = re.compile(r"frame_\d{5,}\.(obj|ply)")
#: Per-body columns of the table file, in order (see :meth:`Recorder.dataframe`).
_BODY_COLUMNS = (
    "volume_m3",
    "pressure_Pa",
    "com_x_m",
    "com_y_m",
    "com_z_m",
    "kinetic_J",
    "gravitational_J",
    "spring_J",
    "gas_J",
    "gas_mol",
    "gas_temperature_K",
)
_FORMATS = {".mp4": "mp4", ".gif": "gif", ".usd": "usd", ".usda": "usd", ".usdc": "usd"}


def _camera(camera, name: str = "camera") -> Camera | None:
    """``None``, a :class:`Camera`, or ``(eye, target)`` [m] as a Camera; ValueError
    naming ``name`` for anything else (wrong shape, non-finite, eye on the target)."""
    if camera is None:
        return None
    if isinstance(camera, Camera):
        eye, target, fov = camera.eye, camera.target, camera.fov
    else:
        try:
            eye, target = camera
        except (TypeError, ValueError):
            raise ValueError(
                f"{name} must be (eye, target), two points of 3 numbers [m], or a "
                f"softbody.render.raster.Camera, got {camera!r}"
            ) from None
        fov = Camera.fov
    points = []
    for what, value in (("eye", eye), ("target", target)):
        try:
            p = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            p = np.empty(0)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"{name} {what} must be 3 finite numbers [m], got {value!r}")
        points.append(p)
    if not np.linalg.norm(points[1] - points[0]) > 0:
        raise ValueError(f"{name} eye and target are the same point {tuple(points[0])}")
    if not (np.isfinite(fov) and 0 < fov < 180):
        raise ValueError(f"{name} fov must be in (0, 180) degrees, got {fov!r}")
    up = camera.up if isinstance(camera, Camera) else Camera.up
    return Camera(
        eye=tuple(map(float, points[0])), target=tuple(map(float, points[1])), fov=fov, up=up
    )


def _gif_delays(count: int, fps: float) -> list[int]:
    """Per-frame GIF delays [ms] for ``count`` frames at ``fps``: GIF stores whole
    hundredths of a second, so the delays alternate (3, 3, 4 hundredths at 30 fps) to
    keep frame k at k / fps on average instead of drifting."""
    ticks = np.round(np.arange(count + 1) * 100.0 / fps)
    return [int(10 * max(d, 1)) for d in np.diff(ticks)]


def _write_gif(target, frames: list[np.ndarray], fps: float) -> None:
    """A looping GIF of ``frames`` (H, W, 3) uint8 at ``fps`` to a path or a file."""
    import imageio.v3 as iio

    iio.imwrite(
        target, np.stack(frames), extension=".gif", duration=_gif_delays(len(frames), fps), loop=0
    )


class Recorder:
    """Frames of a simulation of ``model``, captured to disk, saved as a clip or a table.

    Parameters
    ----------
    model : Model
        The model whose states are captured.
    fps : float
        Frames per simulated second, finite and > 0: :meth:`softbody.Simulator.advance`
        with ``record=`` captures a frame every 1 / fps seconds, and saved clips play
        their frames at this rate (a frame per 1 / fps seconds of the file, whatever times
        the frames were captured at).
    camera : (eye, target) or Camera, optional
        Where the rendered frames look from and at [m]: two points of 3 numbers, or a
        ``softbody.render.raster.Camera`` (with its field of view). ``None`` frames every
        body's positions over all captured frames, looking along -z from slightly above.
    width, height : int
        Size of rendered frames (MP4, GIF) [pixels], 16 to 4096.
    style : {"solid", "wireframe", "both"}
        How bodies are drawn.
    body_names : sequence of str, optional
        One name per body (table, USD prims, OBJ objects); ``"body_0"``... by default.
    body_colors : sequence of str, optional
        ``"#rrggbb"`` colours, cycled over the bodies (Tableau 10 by default).
    max_frames : int
        Most frames this recorder holds; a capture or a recorded ``advance`` call that
        would exceed it raises ValueError (before simulating, for ``advance``).
    ground_size : float
        Side of the square drawn (and exported to USD) for each ground plane [m], > 0.

    Notes
    -----
    Each capture appends the positions, velocities and collider poses to a temporary file
    in the system's temporary folder, 8 (6 N + 12 C) bytes a frame for N particles and C
    colliders, and computes the frame's per-body diagnostics; nothing is rendered until
    :meth:`save`. :meth:`close` (or the end of a ``with`` block, or the recorder being
    garbage collected) deletes the temporary file.
    """

    def __init__(
        self,
        model: Model,
        *,
        fps: float = 30.0,
        camera: tuple | Camera | None = None,
        width: int = 640,
        height: int = 480,
        style: str = "solid",
        body_names: Sequence[str] | None = None,
        body_colors: Sequence[str] | None = None,
        max_frames: int = MAX_FRAMES,
        ground_size: float = 8.0,
    ):
        if not isinstance(model, Model):
            raise TypeError(f"model must be a softbody.Model, got {type(model).__name__}")
        if isinstance(fps, bool) or not isinstance(fps, int | float | np.integer | np.floating):
            raise ValueError(f"fps must be a number of frames per second, got {fps!r}")
        if not (math.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be finite and > 0 frames per second, got {fps!r}")
        if (
            isinstance(max_frames, bool)
            or not isinstance(max_frames, int | np.integer)
            or max_frames < 1
        ):
            raise ValueError(f"max_frames must be an integer >= 1, got {max_frames!r}")
        self.model = model
        self.fps = float(fps)
        self.camera = _camera(camera)
        bodies = model.body_count
        if body_names is None:
            body_names = [f"body_{b}" for b in range(bodies)]
        elif isinstance(body_names, str) or len(body_names) != bodies:
            raise ValueError(f"body_names must be {bodies} names, one per body, got {body_names!r}")
        self.body_names = [str(n) for n in body_names]
        colors = tuple(body_colors) if body_colors is not None else PALETTE
        if not colors:
            raise ValueError("body_colors must hold at least one '#rrggbb' colour")
        # checks width, height, style and the colours (ValueError naming the setting)
        self.settings = RenderSettings(
            width=width, height=height, fps=self.fps, style=style, body_colors=colors,
            ground_size=ground_size,
        )  # fmt: skip
        self.max_frames = int(max_frames)
        n, c = model.particle_count, model.collider_count
        # float64 per frame: positions, velocities, collider centres, collider rotations,
        # each body's gas amount and temperature, each vent's latch (the recorder's file
        # lives as long as the recorder: no file of another layout is ever read back)
        self._row = 6 * n + 12 * c + 2 * bodies + len(model.vent_body)
        self._table_row = 1 + len(_BODY_COLUMNS) * bodies  # time, then the body columns
        self._dir = Path(tempfile.mkdtemp(prefix="softbody-recorder-"))
        self._frames = open(self._dir / "frames.f64", "wb")  # closed by close()
        self._table = open(self._dir / "table.f64", "wb")
        self._finalizer = weakref.finalize(self, _remove, self._frames, self._table, str(self._dir))
        self._count = 0
        self._origin = 0.0  # time of the first frame of the current stretch of frames
        self._last_time = -math.inf

    # -- capturing -----------------------------------------------------------------------
    @property
    def frame_count(self) -> int:
        """Number of frames captured."""
        return self._count

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called (the frames are gone)."""
        return not self._finalizer.alive

    def _check_open(self) -> None:
        if self.closed:
            raise RuntimeError("this Recorder is closed: its frames were deleted")

    def capture(self, state: State, control: Control | None = None) -> None:
        """Add ``state`` as the next frame.

        ``control``: the inputs applied at this state (a pressure or nRT set through
        :class:`Control`), so that the frame's pressure is the one applied. Raises
        ValueError when the state does not fit the model or ``max_frames`` frames are
        already held.
        """
        self._check_open()
        model = self.model
        if not isinstance(state, State):
            raise TypeError(f"state must be a softbody.State, got {type(state).__name__}")
        state.conform(model)
        if self._count >= self.max_frames:
            raise ValueError(
                f"the recorder holds max_frames={self.max_frames:,} frames already: save it and "
                "start another, or raise max_frames"
            )
        time = float(state.time)
        e = energies(model, state, control)
        columns = (
            body_volume(model, state),
            body_pressure(model, state, control),
            *body_center_of_mass(model, state).T,
            e.body_kinetic,
            e.body_gravitational,
            e.body_spring,
            e.body_gas,
            state.body_gas_moles,
            state.body_gas_temperature,
        )
        table = np.concatenate([[time], np.stack(columns, axis=1).reshape(-1)])
        frame = np.concatenate(
            [
                state.particle_q.reshape(-1),
                state.particle_qd.reshape(-1),
                state.collider_q.reshape(-1),
                state.collider_rotation.reshape(-1),
                state.body_gas_moles,
                state.body_gas_temperature,
                state.vent_open,
            ]
        )
        self._frames.write(np.ascontiguousarray(frame, dtype=np.float64).tobytes())
        self._table.write(table.astype(np.float64).tobytes())
        if self._count == 0 or time < self._last_time - 1e-6 / self.fps:
            self._origin = time  # the first frame, or time went back: a new stretch
        self._last_time = time
        self._count += 1

    def frame_offsets(self, time: float, duration: float) -> np.ndarray:
        """When :meth:`softbody.Simulator.advance` with ``record=`` captures: offsets [s]
        from ``time``, increasing, in [0, ``duration``], shape (K,).

        Frames fall every 1 / fps seconds from the first frame of the recording, after the
        last captured frame; the first call (or one whose ``time`` lies before the last
        frame, a new run) captures at ``time`` itself. So ``advance(state, T, record=rec)``
        from a fresh recorder captures ``floor(T fps) + 1`` frames (T fps + 1 when T is a
        whole number of frames), and a second call goes on without repeating the frame at
        the joint. ValueError when the frames would exceed ``max_frames``.
        """
        self._check_open()
        time, duration = float(time), float(duration)
        period = 1.0 / self.fps
        tol = 1e-6 * period  # times this close are the same frame (round-off of state.time)
        if self._count == 0 or time < self._last_time - tol:
            origin, after = time, -math.inf
        else:
            origin, after = self._origin, self._last_time + tol
        first = math.ceil((max(time - tol, after) - origin) * self.fps)
        last = math.floor((time + duration + tol - origin) * self.fps)
        count = max(0, last - first + 1)
        if self._count + count > self.max_frames:
            raise ValueError(
                f"recording {duration:.6g} s at {self.fps:g} frames per second adds {count:,} "
                f"frames to the {self._count:,} held, over max_frames={self.max_frames:,}: lower "
                "fps, advance less at a time, or raise max_frames"
            )
        free = shutil.disk_usage(self._dir).free
        need = 8 * count * (self._row + self._table_row)
        if need > free:
            raise OSError(
                f"recording {count:,} frames needs {need / 2**20:,.0f} MiB in {self._dir.parent}, "
                f"which has {free / 2**20:,.0f} MiB free"
            )
        offsets = origin + np.arange(first, first + count) * period - time
        offsets[np.abs(offsets - duration) <= tol] = duration  # no sliver step at the end
        return np.clip(offsets, 0.0, duration)

    # -- reading back --------------------------------------------------------------------
    def _read(self, name: str, width: int) -> np.ndarray:
        self._check_open()
        handle = self._frames if name == "frames.f64" else self._table
        handle.flush()
        if self._count == 0:
            return np.empty((0, width))
        return np.memmap(self._dir / name, dtype=np.float64, mode="r", shape=(self._count, width))

    @property
    def times(self) -> np.ndarray:
        """Simulated time of each frame [s], shape (F,)."""
        return np.array(self._read("table.f64", self._table_row)[:, 0])

    @property
    def positions(self) -> np.ndarray:
        """Particle positions of each frame [m], shape (F, N, 3), read-only, read from the
        recorder's file on demand (not loaded into memory)."""
        n = self.model.particle_count
        return self._read("frames.f64", self._row)[:, : 3 * n].reshape(-1, n, 3)

    @property
    def velocities(self) -> np.ndarray:
        """Particle velocities of each frame [m/s], shape (F, N, 3), read-only, read from
        the recorder's file on demand."""
        n = self.model.particle_count
        return self._read("frames.f64", self._row)[:, 3 * n : 6 * n].reshape(-1, n, 3)

    @property
    def collider_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """The colliders' centres [m], shape (F, C, 3), and rotations, shape (F, C, 3, 3),
        of each frame."""
        n, c = self.model.particle_count, self.model.collider_count
        rows = np.array(self._read("frames.f64", self._row)[:, 6 * n : 6 * n + 12 * c])
        return rows[:, : 3 * c].reshape(-1, c, 3), rows[:, 3 * c :].reshape(-1, c, 3, 3)

    @property
    def gas(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each frame's gas state: the amount of each body [mol], shape (F, B), its
        temperature [K], shape (F, B), and each vent's latch (1.0: open), shape (F, V)."""
        n, c, b = self.model.particle_count, self.model.collider_count, self.model.body_count
        rows = np.array(self._read("frames.f64", self._row)[:, 6 * n + 12 * c :])
        return rows[:, :b], rows[:, b : 2 * b], rows[:, 2 * b :]

    def state(self, frame: int) -> State:
        """Frame ``frame`` as a :class:`State`: positions, velocities, collider poses, and
        the gas state (each body's amount and temperature, each vent's latch), so that a
        run can go on from it (a Control's gas applied and the step count are not
        recorded)."""
        k = int(frame)
        if not -self._count <= k < self._count:
            raise IndexError(f"frame {frame} out of range for {self._count} frames")
        k %= self._count
        row = self._read("frames.f64", self._row)[k]
        n, c, b = self.model.particle_count, self.model.collider_count, self.model.body_count
        gas = 6 * n + 12 * c
        return State(
            np.array(row[: 3 * n]).reshape(n, 3),
            np.array(row[3 * n : 6 * n]).reshape(n, 3),
            time=float(self._read("table.f64", self._table_row)[k, 0]),
            collider_q=np.array(row[6 * n : 6 * n + 3 * c]).reshape(c, 3),
            collider_rotation=np.array(row[6 * n + 3 * c : gas]).reshape(c, 3, 3),
            body_gas_moles=np.array(row[gas : gas + b]),
            body_gas_temperature=np.array(row[gas + b : gas + 2 * b]),
            vent_open=np.array(row[gas + 2 * b :]),
        )

    def dataframe(self):
        """A tidy ``pandas.DataFrame``: one row per frame and body, in frame order.

        Columns: ``frame``, ``time_s`` [s], ``body`` (index), ``name``, ``volume_m3``
        [m^3] (NaN for an open surface), ``pressure_Pa`` [Pa] (absolute, with the
        captured control's gas), ``com_x_m``, ``com_y_m``, ``com_z_m`` (mass-weighted
        centre of the body's particles [m]), ``kinetic_J``, ``gravitational_J``,
        ``spring_J``, ``gas_J`` and their sum ``energy_J`` [J]
        (:func:`softbody.energies`' per-body split), ``gas_mol`` and ``gas_temperature_K``
        (the state's gas amount [mol] and temperature [K]). Needs pandas.
        """
        try:
            import pandas as pd
        except ImportError:
            raise ImportError(
                "Recorder.dataframe() needs pandas: pip install pandas "
                "(or softbody's docs extra: pip install 'softbody[docs]')"
            ) from None
        table = np.array(self._read("table.f64", self._table_row))
        frames, bodies = self._count, self.model.body_count
        values = table[:, 1:].reshape(frames * bodies, len(_BODY_COLUMNS))
        df = pd.DataFrame(
            {
                "frame": np.repeat(np.arange(frames), bodies),
                "time_s": np.repeat(table[:, 0], bodies),
                "body": np.tile(np.arange(bodies), frames),
                "name": np.tile(np.array(self.body_names, dtype=object), frames),
                **{name: values[:, k] for k, name in enumerate(_BODY_COLUMNS)},
            }
        )
        df["energy_J"] = df[["kinetic_J", "gravitational_J", "spring_J", "gas_J"]].sum(axis=1)
        return df

    # -- rendering -----------------------------------------------------------------------
    def _view(self) -> Camera:
        """The camera: the one given, or one framing the bodies over every frame."""
        if self.camera is not None:
            return self.camera
        model = self.model
        q = self.positions
        if model.body_count:
            lo_p, hi_p = model.body_particle_range[0, 0], model.body_particle_range[-1, 1]
            q = q[:, lo_p:hi_p]
        if q.shape[0] == 0 or q.shape[1] == 0:
            return Camera()
        lo = q.min(axis=(0, 1))
        hi = q.max(axis=(0, 1))
        target = 0.5 * (lo + hi)
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-3)
        fov = Camera.fov
        direction = np.array([0.0, 0.35, 1.0]) / np.linalg.norm([0.0, 0.35, 1.0])
        eye = target + direction * 1.1 * radius / math.sin(math.radians(fov / 2))
        return Camera(eye=tuple(map(float, eye)), target=tuple(map(float, target)), fov=fov)

    def _renderer(self, width: int, height: int) -> FrameRenderer:
        settings = RenderSettings(
            width=width,
            height=height,
            fps=self.fps,
            camera=self._view(),
            style=self.settings.style,
            body_colors=self.settings.body_colors,
            ground_size=self.settings.ground_size,
        )
        return FrameRenderer(self.model, settings, open_bodies=self.model.body_closed == 0)

    def _images(self, width: int, height: int, frames: Sequence[int]) -> Iterator[np.ndarray]:
        """Rendered frames (H, W, 3) uint8, one at a time."""
        renderer = self._renderer(width, height)
        for k in frames:
            yield renderer.render(self.state(k))

    def render(self, frame: int = -1) -> np.ndarray:
        """Frame ``frame`` (default the last) drawn as an (height, width, 3) uint8 image."""
        k = int(frame)
        if not -self._count <= k < self._count:
            raise IndexError(f"frame {frame} out of range for {self._count} frames")
        return next(self._images(self.settings.width, self.settings.height, [k % self._count]))

    def _repr_html_(self) -> str:
        """The clip as an inline looping GIF (a notebook shows it): every k-th frame, at
        most ``REPR_MAX_FRAMES`` frames at most ``REPR_MAX_WIDTH`` pixels wide."""
        if self.closed:
            return "<p>Recorder (closed)</p>"
        if self._count == 0:
            return "<p>Recorder: no frame captured yet</p>"
        stride = max(1, math.ceil(self._count / REPR_MAX_FRAMES))
        width = min(self.settings.width, REPR_MAX_WIDTH)
        height = max(16, round(self.settings.height * width / self.settings.width))
        frames = list(self._images(width, height, range(0, self._count, stride)))
        buffer = io.BytesIO()
        _write_gif(buffer, frames, self.fps / stride)
        data = base64.b64encode(buffer.getvalue()).decode("ascii")
        times = self.times
        caption = (
            f"{self._count} frames at {self.fps:g} fps, t = {times[0]:.3g} to {times[-1]:.3g} s"
        )
        return (
            f'<figure><img src="data:image/gif;base64,{data}" width="{width}" '
            f'height="{height}" alt="recorded clip"/><figcaption>{caption}</figcaption></figure>'
        )

    def __repr__(self) -> str:
        if self.closed:
            return "Recorder(closed)"
        span = ""
        if self._count:
            times = self.times
            span = f", t={times[0]:.6g}..{times[-1]:.6g} s"
        return f"Recorder(frame_count={self._count}, fps={self.fps:g}{span})"

    # -- saving --------------------------------------------------------------------------
    def save(self, path: str | os.PathLike, *, overwrite: bool = False,
             mesh_format: str = "obj", start_frame: float = 0) -> Path:  # fmt: skip
        """Write the captured frames to ``path``; returns it.

        The suffix picks the format: ``.mp4`` (H.264 at exactly ``fps``), ``.gif``
        (looping; GIF delays are whole hundredths of a second, so they alternate to keep
        ``fps`` on average), ``.usd``, ``.usda`` or ``.usdc`` (one mesh per body with
        points, normals, velocities and extent per frame, the colliders as shapes placed
        per frame, and a map to the input mesh's vertices, see :mod:`softbody.io.usd`;
        frame k at time code ``start_frame + k``, ``fps`` time codes per second; needs
        usd-core), or no suffix for a folder of one mesh file per frame,
        ``frame_00000.obj``... (``mesh_format`` ``"obj"`` or ``"ply"``, vertex order =
        particle order).

        The file is written whole or not at all: into a temporary folder beside it, then
        renamed into place. An existing file is replaced only with ``overwrite=True``
        (FileExistsError otherwise); an existing folder only when it is empty or, with
        ``overwrite=True``, holds nothing but ``frame_*.obj``/``.ply`` files.
        FileNotFoundError when the folder to write into does not exist; ValueError for
        an unknown suffix or when no frame was captured.
        """
        self._check_open()
        target = Path(os.fspath(path))
        suffix = target.suffix.lower()
        if mesh_format not in ("obj", "ply"):
            raise ValueError(f"mesh_format must be 'obj' or 'ply', got {mesh_format!r}")
        if suffix in _FORMATS:
            kind = _FORMATS[suffix]
        elif suffix == "" or target.is_dir():
            kind = mesh_format
        else:
            raise ValueError(
                f"cannot tell the format of {str(target)!r} from its suffix: use .mp4, .gif, "
                ".usd, .usda, .usdc, or a folder (no suffix) for an OBJ or PLY sequence"
            )
        if self._count == 0:
            raise ValueError("nothing to save: no frame was captured")
        if kind == "usd":
            from softbody.io.usd import check_start_frame

            check_start_frame(start_frame)
        parent = target.parent
        if not parent.is_dir():
            raise FileNotFoundError(f"cannot save {target}: folder {parent} does not exist")
        sequence = kind in ("obj", "ply")
        self._check_target(target, sequence, overwrite)
        tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=parent))
        try:
            written = tmp / target.name
            if kind == "mp4":
                self._save_mp4(written)
            elif kind == "gif":
                self._save_gif(written)
            elif kind == "usd":
                from softbody.io.usd import write_usd

                collider_q, collider_rotation = self.collider_poses
                write_usd(
                    written,
                    self.model,
                    self.positions,
                    self.fps,
                    self.body_names,
                    velocities=self.velocities,
                    collider_q=collider_q,
                    collider_rotation=collider_rotation,
                    start_frame=start_frame,
                    ground_size=self.settings.ground_size,
                )
            else:
                written.mkdir()
                self._save_meshes(written, kind)
            self._check_target(target, sequence, overwrite)  # again: time has passed
            if sequence and target.is_dir() and any(target.iterdir()):
                # overwrite=True over a previous sequence: swap, then drop the old frames
                old = tmp / ".previous"
                os.replace(target, old)
                os.replace(written, target)
            else:
                os.replace(written, target)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return target

    @staticmethod
    def _check_target(target: Path, sequence: bool, overwrite: bool) -> None:
        """Refuse to replace what the user may not want replaced (see :meth:`save`)."""
        if not (target.exists() or target.is_symlink()):
            return
        if sequence:
            if not target.is_dir() or target.is_symlink():
                raise FileExistsError(f"cannot save a mesh sequence to {target}: it is a file")
            entries = list(target.iterdir())
            if not entries:
                return
            if not overwrite:
                raise FileExistsError(
                    f"{target} is not empty; pass overwrite=True to replace a saved sequence"
                )
            foreign = [
                e.name for e in entries if not (FRAME_FILE.fullmatch(e.name) and e.is_file())
            ]
            if foreign:
                raise FileExistsError(
                    f"{target} holds files a recorder does not write ({', '.join(foreign[:3])}"
                    f"{', ...' if len(foreign) > 3 else ''}); choose another folder"
                )
            return
        if target.is_dir() and not target.is_symlink():
            raise IsADirectoryError(f"cannot save to {target}: it is a folder")
        if not overwrite:
            raise FileExistsError(f"{target} exists; pass overwrite=True to replace it")

    def _save_mp4(self, path: Path) -> None:
        from softbody.render.video import VideoWriter

        video = VideoWriter(path, self.fps, gif=False)
        try:
            for image in self._images(self.settings.width, self.settings.height,
                                      range(self._count)):  # fmt: skip
                video.append(image)
            video.close()
        finally:
            video.abort()  # a no-op after close(); else kills and reaps ffmpeg

    def _save_gif(self, path: Path) -> None:
        from softbody.limits import check_memory

        # the GIF encoder holds every frame (RGB and its palette image) until it writes
        size = self.settings.width * self.settings.height * 4
        check_memory(
            "gif", self._count * size, f"{self._count:,} GIF frames (save .mp4 to stream instead)"
        )
        frames = list(self._images(self.settings.width, self.settings.height, range(self._count)))
        _write_gif(path, frames, self.fps)

    def _save_meshes(self, folder: Path, fmt: str) -> None:
        from softbody.io.sequence import write_mesh_frame

        positions = self.positions
        digits = max(5, len(str(self._count - 1)))
        for k in range(self._count):
            write_mesh_frame(
                folder / f"frame_{k:0{digits}d}.{fmt}",
                self.model,
                np.asarray(positions[k]),
                self.body_names,
            )

    # -- lifetime ------------------------------------------------------------------------
    def close(self) -> None:
        """Delete the captured frames' temporary files; the recorder holds nothing after."""
        self._finalizer()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _remove(frames, table, folder: str) -> None:
    """Close and delete a recorder's temporary files (its finalizer)."""
    for handle in (frames, table):
        try:
            handle.close()
        except OSError:
            pass
    shutil.rmtree(folder, ignore_errors=True)


__all__ = ["Recorder"]
