"""Run a scene to files: video, plots, summary, and on request mesh sequences and USD.

Everything is written to a temporary folder inside the output folder and moved into
place only when the whole run has succeeded: a failed run leaves no partial files.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from softbody import __version__
from softbody.diagnostics import (
    body_area,
    body_center_of_mass,
    body_pressure,
    body_volume,
    body_volume_by,
    energies,
)
from softbody.errors import StabilityWarning
from softbody.scenes.loader import Scene
from softbody.sim.simulator import Simulator

BOUNDING_METHODS = ("exact", "bounding_box", "bounding_sphere", "bounding_ellipsoid")


@dataclass(frozen=True)
class Outputs:
    """Which files a run writes besides the plots and the JSON summary."""

    video: bool = True
    gif: bool = True
    meshes: str | None = None
    """``"obj"`` or ``"ply"``: one mesh file per frame in ``meshes/``."""
    usd: bool = False
    """A USD point cache (needs usd-core)."""


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
) -> dict:
    """Simulate ``scene`` and write its files into ``out``; returns the JSON summary.

    ``strict_stability`` turns a dt above the stability estimate into an error (the
    CLI's behaviour) instead of a warning. ``threads``: the simulator's opt-in threads
    for the force terms (``Simulator``).
    """
    from softbody.render.frame import FrameRenderer
    from softbody.render.plots import plot_bounding_volumes, plot_time_series

    model = scene.model
    integrator = integrator or scene.integrator
    dt = dt if dt is not None else scene.dt
    auto = dt == "auto"
    duration = float(duration if duration is not None else scene.duration)
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be > 0 seconds, got {duration!r}")
    with warnings.catch_warnings():
        if strict_stability:
            warnings.simplefilter("error", StabilityWarning)
        sim = Simulator(
            model,
            integrator=integrator,
            dt=dt,
            threads=threads,
            implicit_tolerance=scene.implicit_tolerance,
        )
    # compile (first run) or load the kernels now, so that the timings below are the
    # simulation's and not the compiler's
    t0 = time.perf_counter()
    sim.run(model.state(), 1)
    prepare_seconds = time.perf_counter() - t0
    settings = scene.render
    if auto:
        # each frame is 1 / fps, advanced in substeps re-chosen from the stability estimate
        steps_per_frame, frame_dt = 0, 1.0 / settings.fps
    else:
        steps_per_frame = max(1, round(1.0 / (settings.fps * dt)))
        frame_dt = steps_per_frame * dt
    # a frame is a whole number of steps; the run ends on the first frame at or after
    # the requested duration
    frame_count = max(1, int(np.ceil(duration / frame_dt - 1e-9)))
    fps = 1.0 / frame_dt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".softbody-run-", dir=out))
    try:
        renderer = FrameRenderer(model, settings, open_bodies=model.body_closed == 0)
        video = None
        if outputs.video or outputs.gif:
            from softbody.render.video import VideoWriter

            video = VideoWriter(tmp / f"{scene.name}.mp4", fps, gif=outputs.gif)
        if outputs.meshes:
            if outputs.meshes not in ("obj", "ply"):
                raise ValueError(f"mesh format must be obj or ply, got {outputs.meshes!r}")
            (tmp / "meshes").mkdir()
        state = model.state()
        times, vol, pres, kin, total = [], [], [], [], []
        bounding = {m: [] for m in BOUNDING_METHODS} if settings.bounding_objects else None
        usd_frames = [] if outputs.usd else None
        sim_seconds = render_seconds = 0.0
        progress = Progress(frame_count, progress_stream)
        for frame in range(frame_count + 1):
            if frame:
                t0 = time.perf_counter()
                if auto:
                    sim.advance(state, frame_dt)
                else:
                    sim.run(state, steps_per_frame)
                sim_seconds += time.perf_counter() - t0
            times.append(state.time)
            vol.append(body_volume(model, state))
            pres.append(body_pressure(model, state))
            e = energies(model, state)
            kin.append(e.body_kinetic)
            total.append(e.total)
            if bounding is not None:
                for m in BOUNDING_METHODS:
                    bounding[m].append(body_volume_by(model, state, m)[0])
            if usd_frames is not None:
                usd_frames.append(state.particle_q.astype(np.float32))
            if outputs.meshes:
                from softbody.io.sequence import write_mesh_frame

                write_mesh_frame(
                    tmp / "meshes" / f"frame_{frame:05d}.{outputs.meshes}",
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
                video.write_gif(tmp / f"{scene.name}.gif")
            if not outputs.video:
                (tmp / f"{scene.name}.mp4").unlink()

        import imageio.v3 as iio

        iio.imwrite(tmp / f"{scene.name}-last-frame.png", last_frame)
        times = np.array(times)
        series = {
            "volume": np.array(vol),
            "pressure": np.array(pres),
            "kinetic": np.array(kin),
            "total": np.array(total),
        }
        plot_time_series(
            tmp / f"{scene.name}-plots.png",
            times,
            series,
            scene.body_names,
            f"{scene.name}: {model.particle_count} particles, {integrator}, "
            f"dt = {'auto' if auto else f'{dt:g} s'}",
        )
        if bounding is not None:
            plot_bounding_volumes(
                tmp / f"{scene.name}-bounding-volumes.png",
                times,
                {m: np.array(v) for m, v in bounding.items()},
                scene.body_names[0],
            )
        if usd_frames is not None:
            from softbody.io.usd import write_usd

            write_usd(
                tmp / f"{scene.name}.usdc", model, np.array(usd_frames), fps, scene.body_names
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
            "dt_s": sim.dt if auto else dt,
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
                }
                for b in range(model.body_count)
            ],
            "colliders": [
                {"center_m": state.collider_q[c].tolist()} for c in range(model.collider_count)
            ],
        }
        (tmp / f"{scene.name}-summary.json").write_text(json.dumps(summary, indent=2))
        # the run succeeded: move every file into place
        written = []
        for item in sorted(tmp.iterdir()):
            target = out / item.name
            if target.is_dir():
                shutil.rmtree(target)
            item.replace(target)
            written.append(target)
        summary["files"] = [str(p) for p in written]
        return summary
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _num(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None
