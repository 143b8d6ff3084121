"""Membranes against springs: the explicit step's rate with a neo-Hookean skin, and
implicit Euler at 1/60 s on a membrane balloon (issue targets in docs/guide/membranes.md).

The cases: the ball drop's ball (``ball_drop.ball_drop``: an icosphere of radius 1 m,
1 kg, nRT = 300 J, over the ground) with its skin as edge springs (k = 500 N/m, c = 0.5
N s/m) or as a neo-Hookean membrane of the same small-strain stiffness (mu H = 2 k /
(3 sqrt 3), the triangle network's: mu = 192 kPa, H = 1 mm, no springs).

1. Explicit: symplectic Euler at 1e-5 s, million vertex-steps per second of each skin at
   2,562 to 40,962 vertices, the two alternating in each of ROUNDS rounds (best of each),
   and the membrane's rate over the springs' in the same round (min-max).
2. Implicit Euler at 1/60 s, 2 s of the drop of the 10,242-vertex membrane ball (CG
   tolerance 1e-4, multigrid; at the spring ball's 1e-2 the membrane ball inverts on
   landing): simulated seconds per wall second, CG iterations per step (mean, most), the
   rebound, the volume range.

Writes results/membranes.{json,png}. Usage: python benchmarks/membranes.py
"""

from __future__ import annotations

import argparse
import platform
import time
import warnings

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import softbody as sb
from results_io import RESULTS, run_record, save_figure, write_json

DT = 1e-5
ROUNDS = 3
MIN_SECONDS = 0.3
K, C = 500.0, 0.5
MU, H = 2 * K / (3 * np.sqrt(3)) / 1e-3, 1e-3


def ball(subdivisions: int, skin: str) -> sb.Model:
    builder = sb.ModelBuilder()
    mesh = sb.icosphere(subdivisions, radius=1.0, center=(0.0, 2.0, 0.0))
    if skin == "springs":
        builder.add_soft_body(mesh, mass=1.0, stiffness=K, damping=C,
                              gas=sb.Gas.isothermal(300.0))  # fmt: skip
    else:
        builder.add_soft_body(mesh, mass=1.0, gas=sb.Gas.isothermal(300.0),
                              membrane=sb.Membrane.neo_hookean(MU, H, damping=1e-3))  # fmt: skip
    builder.add_collider(sb.ColliderPlane(restitution=0.5, friction=0.1))
    return builder.finalize()


def rate(model: sb.Model, sim: sb.Simulator) -> float:
    """Vertex-steps per second over at least MIN_SECONDS."""
    state = model.state()
    sim.run(state, 2)
    steps, elapsed = 4, 0.0
    while elapsed < MIN_SECONDS:
        steps *= 2
        state = model.state()
        start = time.perf_counter()
        sim.run(state, steps)
        elapsed = time.perf_counter() - start
    return model.particle_count * steps / elapsed


def explicit(max_subdivisions: int) -> list[dict]:
    rows = []
    for subdivisions in range(4, max_subdivisions + 1):
        cases = {}
        for skin in ("springs", "membrane"):
            model = ball(subdivisions, skin)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", sb.StabilityWarning)
                cases[skin] = model, sb.Simulator(model, integrator="symplectic_euler", dt=DT)
        best = {skin: 0.0 for skin in cases}
        ratios = []
        for _ in range(ROUNDS):
            got = {skin: rate(*cases[skin]) for skin in cases}
            for skin in cases:
                best[skin] = max(best[skin], got[skin])
            ratios.append(got["membrane"] / got["springs"])
        row = {
            "vertices": cases["springs"][0].particle_count,
            "mvps": {skin: best[skin] / 1e6 for skin in best},
            "membrane_over_springs": [min(ratios), max(ratios)],
        }
        rows.append(row)
        print(f"explicit {row['vertices']:6d}: springs {best['springs'] / 1e6:6.2f}, membrane "
              f"{best['membrane'] / 1e6:6.2f} M vertex-steps/s, ratio "
              f"{min(ratios):.2f}-{max(ratios):.2f}", flush=True)  # fmt: skip
    return rows


def implicit(subdivisions: int = 5, seconds: float = 2.0) -> dict:
    model = ball(subdivisions, "membrane")
    sim = sb.Simulator(model, integrator="implicit_euler", dt=1 / 60, implicit_tolerance=1e-4)
    state = model.state()
    v0 = sb.body_volume(model, state)[0]
    steps = round(seconds * 60)
    heights, volumes, iterations = [], [], []
    start = time.perf_counter()
    for _ in range(steps):
        sim.run(state, 1)
        iterations.append(sim.solver.iterations[0])
        heights.append(float(np.mean(state.particle_q[:, 1])))
        volumes.append(float(sb.body_volume(model, state)[0] / v0))
    wall = time.perf_counter() - start
    low = int(np.argmin(heights))
    row = {
        "vertices": model.particle_count,
        "realtime_factor": seconds / wall,
        "cg_iterations_mean": float(np.mean(iterations)),
        "cg_iterations_most": float(np.max(iterations)),
        "rebound_m": float(max(heights[low:]) - heights[low]),
        "volume_range": [min(volumes), max(volumes)],
        "heights": heights,
    }
    print(f"implicit {row['vertices']}: {row['realtime_factor']:.2f}x real time, CG "
          f"{row['cg_iterations_mean']:.1f} mean / {row['cg_iterations_most']:.0f} most per "
          f"step, rebound {row['rebound_m']:.2f} m, volume {min(volumes):.2f}-"
          f"{max(volumes):.2f}", flush=True)  # fmt: skip
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-subdivisions", type=int, default=6)
    args = parser.parse_args()
    rows = explicit(args.max_subdivisions)
    drop = implicit()
    write_json(
        RESULTS / "membranes.json",
        run_record(
            "membranes",
            machine=f"{platform.machine()}, {platform.processor() or 'cpu'}",
            command="python benchmarks/membranes.py",
            dt_explicit=DT,
            membrane={"model": "neo_hookean", "shear_modulus": MU, "thickness": H},
            springs={"stiffness": K, "damping": C},
            units="million vertex-steps per second (mvps), one thread",
            explicit=rows,
            implicit=drop,
        ),
    )
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    v = [r["vertices"] for r in rows]
    for skin in ("springs", "membrane"):
        left.plot(v, [r["mvps"][skin] for r in rows], "o-", label=skin)
    left.set_xscale("log")
    left.set_xticks(v, [f"{x:,}" for x in v])
    left.minorticks_off()
    left.set_xlabel("vertices")
    left.set_ylabel("million vertex-steps / s (symplectic Euler)")
    left.legend()
    t = np.arange(1, len(drop["heights"]) + 1) / 60
    right.plot(t, drop["heights"])
    right.set_xlabel("time [s]")
    right.set_ylabel("centre height [m]")
    right.set_title(f"implicit Euler 1/60 s, {drop['vertices']:,} vertices: "
                    f"{drop['realtime_factor']:.2f}x real time", fontsize=10)  # fmt: skip
    fig.tight_layout()
    save_figure(fig, RESULTS / "membranes.png")


if __name__ == "__main__":
    main()
