"""The main demo: the paper's hanging ball (Figure 1, right) at several gas amounts.

Three of the paper's balls (162-vertex icospheres, radius 0.5 m, 1 kg) hang side by side
from their pinned top caps, each with a different amount of gas nRT. Under gravity the
soft springs stretch and the gas pushes back: the less gas, the narrower and longer the
ball sags. Writes a shaded side view of the final shapes, plots of volume, pressure and
kinetic energy over time, and a JSON summary.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from softbody.diagnostics import body_center_of_mass, body_pressure, body_volume, energies
from softbody.gas import Gas
from softbody.mesh.generators import icosphere
from softbody.sim.builder import ModelBuilder
from softbody.sim.model import Model
from softbody.sim.simulator import Simulator

#: Default duration [s] and time step [s] of the demo (the CLI uses them too).
DEMO_DEFAULTS = {"duration": 4.0, "dt": 1e-3}

#: Gas amounts nRT [J] of the demo's balls, softest first.
DEMO_GAS = (1.0, 4.0, 16.0)


@dataclass
class DemoResult:
    """What :func:`hanging_balls` measured; arrays are (frames,) or (frames, B)."""

    model: Model
    time: np.ndarray
    volume: np.ndarray
    pressure: np.ndarray
    kinetic: np.ndarray
    potential: np.ndarray
    final_q: np.ndarray
    wall_seconds: float
    steps: int


def hanging_balls_model(gas: tuple[float, ...] = DEMO_GAS) -> Model:
    """Balls of radius 0.5 m and 1 kg centred 2 m apart at y = 1 m, top caps pinned."""
    builder = ModelBuilder()
    for k, nrt in enumerate(gas):
        mesh = icosphere(2, radius=0.5, center=(2.0 * k, 1.0, 0.0))
        cap = np.flatnonzero(mesh.vertices[:, 1] > 1.0 + 0.85 * 0.5)  # 15 vertices
        builder.add_soft_body(
            mesh,
            mass=1.0,
            stiffness=30.0,
            damping=0.3,
            gas=Gas.isothermal(nrt),
            bend_stiffness=1.0,
            bend_damping=0.03,
            pinned=cap,
        )
    return builder.finalize()


def hanging_balls(
    *,
    duration: float = DEMO_DEFAULTS["duration"],
    dt: float = DEMO_DEFAULTS["dt"],
    integrator: str = "midpoint",
    frames: int = 200,
    log=print,
) -> DemoResult:
    """Simulate the hanging balls; ``frames`` samples of the diagnostics over ``duration`` s."""
    model = hanging_balls_model()
    sim = Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    steps = max(1, round(duration / dt))
    per_frame = max(1, steps // frames)
    rows = []
    start = time.perf_counter()
    next_log = start
    for frame in range(steps // per_frame + 1):
        if frame:
            sim.run(state, per_frame)
        e = energies(model, state)
        rows.append(
            (
                state.time,
                body_volume(model, state),
                body_pressure(model, state),
                e.body_kinetic,
                e.body_gravitational + e.body_spring + e.body_gas,
            )
        )
        now = time.perf_counter()
        if log and now >= next_log:
            log(f"t = {state.time:6.3f} s / {duration:g} s  ({state.step_count} steps)")
            next_log = now + 1.0
    wall = time.perf_counter() - start
    return DemoResult(
        model=model,
        time=np.array([r[0] for r in rows]),
        volume=np.array([r[1] for r in rows]),
        pressure=np.array([r[2] for r in rows]),
        kinetic=np.array([r[3] for r in rows]),
        potential=np.array([r[4] for r in rows]),
        final_q=state.particle_q.copy(),
        wall_seconds=wall,
        steps=state.step_count,
    )


def _write_atomic(path: Path, write) -> None:
    """Write through a temporary file in the same folder, then rename: whole or nothing."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_outputs(result: DemoResult, out: Path) -> list[Path]:
    """Side view PNG, time-series plot PNG and summary JSON into ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    model = result.model
    labels = [f"nRT = {v:g} J" for v in DEMO_GAS]
    paths = []

    # side view from +z: front faces, shaded, drawn far to near (painter's order)
    fig, ax = plt.subplots(figsize=(8, 3.4), dpi=120)
    draw_side_view(ax, model, result.final_q)
    for b, (p0, p1) in enumerate(model.body_particle_range):
        rest = model.particle_q[p0:p1]
        c = rest.mean(axis=0)
        ring = np.linspace(0, 2 * np.pi, 100)
        ax.plot(
            c[0] + 0.5 * np.cos(ring),
            c[1] + 0.5 * np.sin(ring),
            color="0.5",
            lw=0.8,
            ls="--",
            zorder=5,
        )
        ax.text(c[0], 0.1, labels[b], ha="center", va="top")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"Hanging balls after {result.time[-1]:.2g} s (dashed: unloaded shape)")
    ax.set_xlim(-0.8, 2.0 * (model.body_count - 1) + 0.8)
    ax.set_ylim(-0.1, 1.7)
    fig.tight_layout()
    path = out / "hanging-balls.png"
    _write_atomic(path, lambda tmp: fig.savefig(tmp, format="png"))
    plt.close(fig)
    paths.append(path)

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), dpi=110)
    for b in range(model.body_count):
        axes[0].plot(result.time, result.volume[:, b], color=f"C{b}", label=labels[b])
        axes[1].plot(result.time, result.pressure[:, b], color=f"C{b}")
        axes[2].plot(result.time, result.kinetic[:, b], color=f"C{b}")
    axes[0].set_ylabel("volume [m^3]")
    axes[1].set_ylabel("pressure [Pa]")
    axes[2].set_ylabel("kinetic energy [J]")
    axes[2].set_yscale("symlog", linthresh=1e-6)
    for ax in axes:
        ax.set_xlabel("time [s]")
        ax.grid(alpha=0.3)
    axes[0].legend()
    fig.tight_layout()
    path = out / "hanging-balls-plots.png"
    _write_atomic(path, lambda tmp: fig.savefig(tmp, format="png"))
    plt.close(fig)
    paths.append(path)

    com = body_center_of_mass(model, _final_state(result))
    summary = {
        "scene": "hanging-balls",
        "particle_count": model.particle_count,
        "tri_count": model.tri_count,
        "steps": result.steps,
        "simulated_seconds": float(result.time[-1]),
        "wall_seconds": result.wall_seconds,
        "bodies": [
            {
                "gas_nrt_J": DEMO_GAS[b],
                "volume_m3": float(result.volume[-1, b]),
                "rest_volume_m3": float(model.body_rest_volume[b]),
                "pressure_Pa": float(result.pressure[-1, b]),
                "center_of_mass_y_m": float(com[b, 1]),
                "kinetic_energy_J": float(result.kinetic[-1, b]),
            }
            for b in range(model.body_count)
        ],
    }
    path = out / "summary.json"
    _write_atomic(path, lambda tmp: Path(tmp).write_text(json.dumps(summary, indent=2)))
    paths.append(path)
    return paths


def draw_side_view(ax, model: Model, q: np.ndarray, light=(0.4, 0.6, 0.7)) -> None:
    """Draw every body seen from +z: back faces culled, the rest shaded by a directional
    light and painted far to near. q : (N, 3) positions [m]."""
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import to_rgb

    tri = model.tri_indices
    x = q[tri]  # (T, 3, 3)
    n = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    front = n[:, 2] > 0
    body_of_tri = np.repeat(
        np.arange(model.body_count), np.diff(model.body_tri_range, axis=1)[:, 0]
    )
    order = np.argsort(x[:, :, 2].mean(axis=1))
    order = order[front[order]]
    lam = np.clip(n[order] @ (np.asarray(light) / np.linalg.norm(light)), 0.0, 1.0)
    base = np.array([to_rgb(f"C{b}") for b in body_of_tri[order]])
    colors = base * (0.35 + 0.65 * lam)[:, None]
    ax.add_collection(
        PolyCollection(
            x[order][:, :, :2], facecolors=colors, edgecolors=colors * 0.85, linewidths=0.3
        )
    )


def _final_state(result: DemoResult):
    from softbody.sim.state import State

    return State(result.final_q, np.zeros_like(result.final_q))
