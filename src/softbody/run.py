"""Run a scene to files: video, plots, summary, and on request mesh sequences and USD.

A run adds its files to the output folder by name and never deletes or replaces a file
it did not write (:mod:`softbody.io.outputs`): everything is written to a temporary
folder ``.softbody-run-*`` that the run makes inside the output folder, and only when the
whole run has succeeded are the files moved into place. Every name starts with the
scene's file stem (``NAME.mp4``, ``NAME-summary.json``, ``NAME-meshes/``), so runs of
different scenes share a folder; a file or folder of one of this run's names that
exists already stops the run with a one-line error before simulating (checked again
before moving anything), unless ``overwrite`` is given, which replaces exactly those
files. A failed or interrupted run (an error, Ctrl-C, SIGTERM) removes its temporary
folder and kills its ffmpeg, and leaves the output folder as it was.

File names come from the scene's ``name`` made into a safe file stem
(:func:`file_stem`): a scene file cannot write outside the output folder.

Runs are bounded before they start: at most ``max_steps`` simulation steps (a tiny dt
or a tiny ``render.fps`` would otherwise run for hours or days in silence) and
``max_frames`` rendered frames, and the frames kept in memory (GIF, USD) must fit
:func:`softbody.limits.memory_limit`.
"""

from __future__ import annotations

import json
import re
import shutil
import sys
import tempfile
import time
import unicodedata
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from softbody import __version__
from softbody.diagnostics import (
    body_area,
    body_center_of_mass,
    body_gas_flows,
    body_pressure,
    body_volume,
    body_volume_by,
    energies,
    gas_state_bodies,
    has_gas_flows,
)
from softbody.errors import StabilityWarning
from softbody.io.outputs import check_targets, commit, folder_lock, prepare
from softbody.limits import check_memory
from softbody.scenes.loader import Scene
from softbody.scenes.plan import MAX_FRAMES, MAX_STEPS, FramePlan, plan_frames
from softbody.sim.simulator import Simulator

BOUNDING_METHODS = ("exact", "bounding_box", "bounding_sphere", "bounding_ellipsoid")
#: Longest file stem made from a scene's name [bytes of UTF-8] (:func:`file_stem`).
MAX_STEM_BYTES = 100


@dataclass(frozen=True)
class Outputs:
    """Which files a run writes besides the plots and the JSON summary."""

    video: bool = True
    gif: bool = True
    meshes: str | None = None
    """``"obj"`` or ``"ply"``: one mesh file per frame in ``NAME-meshes/``."""
    usd: bool = False
    """A USD cache of the bodies and colliders (needs usd-core, see :mod:`softbody.io.usd`)."""


class Progress:
    """A progress bar on a terminal; a plain line every 10% otherwise (CI logs)."""

    def __init__(self, total: int, stream=None):
        self.total = max(total, 1)
        self.stream = stream or sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self._next = 0.0

    def update(self, done: int, text: str) -> None:
        fraction = done / self.total
        if self.tty:
            bar = "#" * int(30 * fraction)
            self.stream.write(f"\r[{bar:<30}] {100 * fraction:5.1f}% {text}")
            if done >= self.total:
                self.stream.write("\n")
            self.stream.flush()
        elif fraction >= self._next or done >= self.total:
            self.stream.write(f"{100 * fraction:5.1f}% {text}\n")
            self.stream.flush()
            self._next = min(1.0, np.floor(fraction * 10 + 1) / 10)


def file_stem(name: str) -> str:
    """A scene's ``name`` as a safe, readable file stem.

    Path separators split the name and ``.``/``..`` parts are dropped (``"../../x"`` ->
    ``"x"``, ``"/tmp/abs"`` -> ``"tmp-abs"``); anything but letters, digits, ``_``,
    ``-`` and ``.`` (control characters, spaces, quotes) becomes ``_``; no leading dot
    or dash (no hidden files, no names read as options); at most ``MAX_STEM_BYTES`` of
    UTF-8, so that ``stem + "-bounding-volumes.png"`` fits a file system's 255 bytes;
    ``"scene"`` when nothing is left.
    """
    parts = [p for p in re.split(r"[/\\]+", str(name)) if p not in ("", ".", "..")]
    text = re.sub(r"[^\w.\-]+", "_", unicodedata.normalize("NFC", "-".join(parts)))
    text = text.lstrip("._-")
    text = text.encode()[:MAX_STEM_BYTES].decode(errors="ignore").rstrip("._-")
    return text or "scene"


def _check_frame_memory(plan: FramePlan, scene: Scene, outputs: Outputs) -> None:
    """Refuse a run whose kept frames (GIF: every other frame at half size; USD: every
    frame's float32 positions and velocities, float64 collider poses) would not fit in
    memory."""
    frames = plan.frame_count + 1
    if outputs.gif:
        settings = scene.render
        size = ((settings.height + 1) // 2) * ((settings.width + 1) // 2) * 3
        count = (frames + 1) // 2
        check_memory("gif", count * size, f"keeping {count:,} GIF frames (--no-gif skips it)")
    if outputs.usd:
        size = 24 * scene.model.particle_count + 96 * scene.model.collider_count
        check_memory("usd", frames * size, f"keeping {frames:,} frames for the USD cache")


def _expected_files(stem: str, plan: FramePlan, outputs: Outputs, bounding: bool) -> list[str]:
    """The files a run of this plan writes, relative to the output folder."""
    names = [f"{stem}-last-frame.png", f"{stem}-plots.png", f"{stem}-summary.json"]
    names += [f"{stem}.mp4"] * outputs.video + [f"{stem}.gif"] * outputs.gif
    names += [f"{stem}-bounding-volumes.png"] * bounding + [f"{stem}.usdc"] * outputs.usd
    if outputs.meshes:
        names += [_mesh_frame(stem, k, outputs.meshes) for k in range(plan.frame_count + 1)]
    return names


def _mesh_frame(stem: str, frame: int, fmt: str) -> str:
    return f"{stem}-meshes/frame_{frame:05d}.{fmt}"


def run_scene(
    scene: Scene,
    out: Path,
    *,
    integrator: str | None = None,
    dt: float | None = None,
    duration: float | None = None,
    outputs: Outputs = Outputs(),
    strict_stability: bool = False,
    progress_stream=None,
    threads: int = 1,
    max_steps: int = MAX_STEPS,
    max_frames: int = MAX_FRAMES,
    overwrite: bool = False,
) -> dict:
    """Simulate ``scene`` and write its files into ``out``; returns the JSON summary, with
    ``"files"`` (the top-level paths written), ``"replaced"`` (the files that existed and
    were replaced) and ``"others"`` (files in this run's ``NAME-meshes/`` folder that it
    did not write, left as they were) added.

    ``strict_stability`` turns a dt above the stability estimate into an error (the
    CLI's behaviour) instead of a warning. ``threads``: the simulator's opt-in threads
    for the force terms (``Simulator``). ``max_steps``, ``max_frames``: the run is
    refused (ValueError) before it starts when it would take more (:func:`plan_frames`).
    ``OutputError`` when ``out`` holds a file or folder where this run's files go, unless
    ``overwrite`` (then those files are replaced; a link or a folder in the way is refused
    all the same; see the module docstring).
    """
    model = scene.model
    integrator = integrator or scene.integrator
    dt = dt if dt is not None else scene.dt
    auto = dt == "auto"
    duration = float(duration if duration is not None else scene.duration)
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be > 0 seconds, got {duration!r}")
    for key, value in (("max_steps", max_steps), ("max_frames", max_frames)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
            raise ValueError(f"{key} must be an integer >= 1, got {value!r}")
    if outputs.meshes not in (None, "obj", "ply"):
        raise ValueError(f"mesh format must be obj or ply, got {outputs.meshes!r}")
    settings = scene.render
    stem = file_stem(scene.name)
    limits = {"max_steps": max_steps, "max_frames": max_frames}
    if not auto:  # refuse an endless run at once, before the stability analysis
        plan = plan_frames(duration, settings.fps, dt, **limits)
    # say what happens before the first step: the stability estimate (Lanczos runs) and
    # the solver's set-up (multigrid hierarchy, projective factor) take seconds on large
    # meshes, and a silent terminal looks hung
    _say(progress_stream, f"preparing {integrator}: stability estimate and solver set-up")
    t_setup = time.perf_counter()
    with warnings.catch_warnings():
        if strict_stability:
            warnings.simplefilter("error", StabilityWarning)
        # a frame is a whole number of steps: the step is dt or a little less
        try:
            sim = Simulator(
                model,
                integrator=integrator,
                dt="auto" if auto else plan.dt,
                threads=threads,
                implicit_tolerance=scene.implicit_tolerance,
            )
        except StabilityWarning as exc:
            if auto or plan.dt == dt:
                raise
            raise StabilityWarning(
                f"{exc} (dt = {dt:.3g} s asked for, lowered to {plan.dt:.3g} s so that a frame "
                f"at {settings.fps:g} fps is {plan.steps_per_frame:,} whole step"
                f"{'s' if plan.steps_per_frame != 1 else ''})"
            ) from None
    if auto:
        plan = plan_frames(duration, settings.fps, sim.dt, auto=True, **limits)
    lowered = "" if auto or plan.dt == dt else f" ({dt * 1e3:.3g} ms asked"
    if lowered:
        lowered += f": {plan.steps_per_frame:,} steps a frame at {settings.fps:g} fps)"
    _check_frame_memory(plan, scene, outputs)
    _say(
        progress_stream,
        f"ready in {time.perf_counter() - t_setup:.1f} s: dt = {sim.dt * 1e3:.4g} ms"
        f"{' (auto)' if auto else lowered}, {plan.total_steps:,} steps, "
        f"{plan.frame_count + 1} frames",
    )

    out = Path(out)
    prepare(out)
    with folder_lock(out):
        # a user's file where ours would go: say so now, not after the simulation
        expected = _expected_files(stem, plan, outputs, settings.bounding_objects)
        check_targets(out, expected, overwrite=overwrite)
        # compile (first run) or load the kernels now, so that the timings below are the
        # simulation's and not the compiler's
        t0 = time.perf_counter()
        sim.run(model.state(), 1)
        prepare_seconds = time.perf_counter() - t0
        tmp = Path(tempfile.mkdtemp(prefix=".softbody-run-", dir=out))
        try:
            summary = _simulate_and_write(
                scene, sim, tmp, stem, plan, outputs, dt, progress_stream, prepare_seconds
            )
            done = commit(tmp, out, expected, overwrite=overwrite)
            summary["files"] = [str(p) for p in done.written]
            summary["replaced"] = [str(p) for p in done.replaced]
            summary["others"] = [str(p) for p in done.others]
            return summary
        finally:
            shutil.rmtree(tmp, ignore_errors=True)


def _say(stream, text: str) -> None:
    """One status line on ``stream`` (nothing when it is None)."""
    if stream is not None:
        stream.write(text + "\n")
        stream.flush()


def _simulate_and_write(
    scene: Scene,
    sim: Simulator,
    tmp: Path,
    stem: str,
    plan: FramePlan,
    outputs: Outputs,
    dt: float | str,
    progress_stream,
    prepare_seconds: float,
) -> dict:
    """Simulate the planned frames and write every file into ``tmp``; the summary."""
    from softbody.render.frame import FrameRenderer
    from softbody.render.plots import plot_bounding_volumes, plot_time_series

    model = scene.model
    auto = dt == "auto"
    settings = scene.render
    integrator = sim.integrator.name.lower()
    frame_count, frame_dt, steps_per_frame = plan.frame_count, plan.frame_dt, plan.steps_per_frame
    fps = settings.fps  # exactly: a frame is 1 / fps, a whole number of steps
    video = None
    try:
        renderer = FrameRenderer(model, settings, open_bodies=model.body_closed == 0)
        if outputs.video or outputs.gif:
            from softbody.render.video import VideoWriter

            video = VideoWriter(tmp / f"{stem}.mp4", fps, gif=outputs.gif)
        if outputs.meshes:
            (tmp / f"{stem}-meshes").mkdir()
        state = model.state()
        times, vol, pres, kin, total = [], [], [], [], []
        height, moles, temp, inflow, outflow = [], [], [], [], []
        flows = has_gas_flows(model)
        bounding = {m: [] for m in BOUNDING_METHODS} if settings.bounding_objects else None
        usd_frames = [] if outputs.usd else None
        usd_velocities, usd_collider_q, usd_collider_rotation = [], [], []
        sim_seconds = render_seconds = 0.0
        progress = Progress(frame_count, progress_stream)
        for frame in range(frame_count + 1):
            if frame:
                t0 = time.perf_counter()
                # the command line prints its own progress, a line per frame
                if auto:
                    sim.advance(state, frame_dt, progress=False)
                else:
                    sim.run(state, steps_per_frame, progress=False)
                sim_seconds += time.perf_counter() - t0
            times.append(state.time)
            vol.append(body_volume(model, state))
            pres.append(body_pressure(model, state))
            e = energies(model, state)
            kin.append(e.body_kinetic)
            total.append(e.total)
            height.append(body_center_of_mass(model, state)[:, 1])
            moles.append(state.body_gas_moles.copy())
            temp.append(state.body_gas_temperature.copy())
            if flows:
                f = body_gas_flows(model, state)
                inflow.append(f.mass_inflow)
                outflow.append(f.mass_outflow)
            if bounding is not None:
                for m in BOUNDING_METHODS:
                    bounding[m].append(body_volume_by(model, state, m)[0])
            if usd_frames is not None:
                usd_frames.append(state.particle_q.astype(np.float32))
                usd_velocities.append(state.particle_qd.astype(np.float32))
                usd_collider_q.append(state.collider_q.copy())
                usd_collider_rotation.append(state.collider_rotation.copy())
            if outputs.meshes:
                from softbody.io.sequence import write_mesh_frame

                write_mesh_frame(
                    tmp / _mesh_frame(stem, frame, outputs.meshes),
                    model,
                    state.particle_q,
                    scene.body_names,
                )
            t0 = time.perf_counter()
            image = renderer.render(state)
            if video is not None:
                video.append(image)
            render_seconds += time.perf_counter() - t0
            progress.update(frame, f"t = {state.time:.3f} s")
        last_frame = image
        if video is not None:
            video.close()
            if outputs.gif:
                video.write_gif(tmp / f"{stem}.gif")
            if not outputs.video:
                (tmp / f"{stem}.mp4").unlink()
    finally:
        if video is not None:
            video.abort()  # a no-op after close(); else kills and reaps ffmpeg

    import imageio.v3 as iio

    iio.imwrite(tmp / f"{stem}-last-frame.png", last_frame)
    times = np.array(times)
    series = {
        "volume": np.array(vol),
        "pressure": np.array(pres),
        "kinetic": np.array(kin),
        "total": np.array(total),
        "height": np.array(height),
    }
    gas = gas_state_bodies(model)
    if gas.any():
        # bodies without a gas state (cloths, fixed pressures) are NaN: no line is drawn
        series["gas_moles"] = np.where(gas, np.array(moles), np.nan)
        series["gas_temperature"] = np.where(gas, np.array(temp), np.nan)
    if flows:
        series["mass_inflow"] = np.where(gas, np.array(inflow), np.nan)
        series["mass_outflow"] = np.where(gas, np.array(outflow), np.nan)
    plot_time_series(
        tmp / f"{stem}-plots.png",
        times,
        series,
        scene.body_names,
        f"{scene.name}: {model.particle_count} particles, {integrator}, "
        f"dt = {'auto' if auto else f'{sim.dt:.4g} s'}",
    )
    if bounding is not None:
        plot_bounding_volumes(
            tmp / f"{stem}-bounding-volumes.png",
            times,
            {m: np.array(v) for m, v in bounding.items()},
            scene.body_names[0],
        )
    if usd_frames is not None:
        from softbody.io.usd import write_usd

        write_usd(
            tmp / f"{stem}.usdc",
            model,
            np.array(usd_frames),
            fps,
            scene.body_names,
            velocities=np.array(usd_velocities),
            collider_q=np.array(usd_collider_q).reshape(-1, model.collider_count, 3),
            collider_rotation=np.array(usd_collider_rotation).reshape(
                -1, model.collider_count, 3, 3
            ),
            start_frame=settings.usd_start_frame,
            ground_size=settings.ground_size,
        )

    area = body_area(model, state)
    com = body_center_of_mass(model, state)
    e = energies(model, state)
    summary = {
        "scene": scene.name,
        "description": scene.description,
        "softbody_version": __version__,
        "parameters": scene.data,
        "integrator": sim.integrator.name.lower(),
        "threads": sim.threads,
        "implicit_tolerance": sim.implicit_tolerance if sim.integrator.implicit else None,
        "dt_s": sim.dt,
        "dt_requested_s": None if auto else dt,
        "dt_auto": auto,
        "stable_dt_estimate_s": sim.stable_dt,
        "duration_s": float(times[-1]),
        "steps": state.step_count,
        "frames": frame_count + 1,
        "fps": fps,
        "particle_count": model.particle_count,
        "tri_count": model.tri_count,
        "timings_s": {
            "kernel_compile_or_load": prepare_seconds,
            "simulation": sim_seconds,
            "rendering": render_seconds,
            "simulated_per_wall_second": float(times[-1]) / max(sim_seconds, 1e-12),
        },
        "energy_J": {
            "kinetic": e.kinetic,
            "gravitational": e.gravitational,
            "spring": e.spring,
            "gas": e.gas,
            "total": e.total,
            "initial_total": float(series["total"][0]),
        },
        "bodies": [
            {
                "name": scene.body_names[b],
                "closed": bool(model.body_closed[b]),
                "volume_m3": _num(series["volume"][-1, b]),
                "rest_volume_m3": _num(model.body_rest_volume[b]),
                "pressure_Pa": _num(series["pressure"][-1, b]),
                "area_m2": float(area[b]),
                "center_of_mass_m": com[b].tolist(),
                "kinetic_energy_J": float(e.body_kinetic[b]),
                **_gas_summary(series, times, b),
            }
            for b in range(model.body_count)
        ],
        "vents": [
            {"body": int(model.vent_body[v]), "open": bool(state.vent_open[v])}
            for v in range(len(model.vent_body))
        ],
        "colliders": [
            {"center_m": state.collider_q[c].tolist()} for c in range(model.collider_count)
        ],
    }
    # standard JSON only: a value that is not finite (a body that blew up) is null
    text = json.dumps(_finite_or_null(summary), indent=2, allow_nan=False)
    (tmp / f"{stem}-summary.json").write_text(text)
    return summary


def _gas_summary(series: dict, t: np.ndarray, b: int) -> dict:
    """Body ``b``'s gas in the summary, where it has a gas state: its amount [mol] and
    temperature [K] at the end and their extremes, the largest pressure [Pa], and where
    the model has flows, the mass flows in and out at the end and at their largest
    [kg/s] and the mass gone in and out over the run [kg] (trapezoid rule over the
    frames)."""
    if "gas_moles" not in series or np.isnan(series["gas_moles"][0, b]):
        return {}
    moles, temp = series["gas_moles"][:, b], series["gas_temperature"][:, b]
    out = {
        "gas_moles": _num(moles[-1]),
        "gas_moles_initial": _num(moles[0]),
        "gas_temperature_K": _num(temp[-1]),
        "gas_temperature_max_K": _num(np.max(temp)),
        "gas_temperature_min_K": _num(np.min(temp)),
        "pressure_max_Pa": _num(np.max(series["pressure"][:, b])),
    }
    if "mass_inflow" in series:
        for key, name in (("mass_inflow", "inflow"), ("mass_outflow", "outflow")):
            flow = series[key][:, b]
            out[f"gas_mass_{name}_kg_s"] = _num(flow[-1])
            out[f"gas_mass_{name}_max_kg_s"] = _num(np.max(flow))
            total = float(np.sum(0.5 * (flow[1:] + flow[:-1]) * np.diff(t))) if t.size > 1 else 0.0
            out[f"gas_mass_{name}_total_kg"] = _num(total)
    return out


def _finite_or_null(value):
    """``value`` (nested dicts, lists, numbers) with every NaN or infinity as None, so
    that the summary is standard JSON (which has no ``Infinity``)."""
    if isinstance(value, dict):
        return {k: _finite_or_null(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite_or_null(v) for v in value]
    if isinstance(value, float | np.floating) and not np.isfinite(value):
        return None
    return value


def _num(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None
