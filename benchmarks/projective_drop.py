"""Projective dynamics on the ball drop: speed, and what its few iterations cost.

The ball-drop case of ``ball_drop.py`` (1 m, 1 kg, k = 500 N/m, nRT = 300 J, dropped
from 1 m) at 1/60 s under projective dynamics with 1, 2 and 4 local-global iterations,
against backward Euler at CG tolerance 1e-2 (the fastest valid scheme of
``ball_drop.py``) in the same run, from 642 to 163,842 vertices: simulated seconds per
wall second, and, wherever the 2 s drop takes at most ``CHECK_BUDGET``, the checked drop
of ``ball_drop.check_drop`` (round, bouncing, not shaking) with its rebound and the
centre of mass's height at the end (one radius, about 1.0 m, when the ball rests
unsquashed).

Writes results/projective_drop.{json,png}. Usage: python benchmarks/projective_drop.py
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import softbody as sb
from ball_drop import LOOSE_TOLERANCE, ball_drop, check_drop, steps_per_second
from results_io import RESULTS, run_record, save_figure, write_json

#: run name -> Simulator keywords besides the model and dt = 1/60 s
RUNS = {
    "projective, 1 iteration": {"integrator": "projective", "projective_iterations": 1},
    "projective, 2 iterations": {"integrator": "projective", "projective_iterations": 2},
    "projective, 4 iterations": {"integrator": "projective", "projective_iterations": 4},
    "implicit_euler cg 1e-2": {
        "integrator": "implicit_euler",
        "implicit_tolerance": LOOSE_TOLERANCE,
    },
}
#: skip the 2 s check of a run that would take longer than this [s]
CHECK_BUDGET = 60.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--min-subdivisions", type=int, default=3)
    parser.add_argument("--max-subdivisions", type=int, default=7)
    args = parser.parse_args()
    sizes = []
    for sub in range(args.min_subdivisions, args.max_subdivisions + 1):
        model = ball_drop(sub)
        row = {"vertex_count": model.particle_count, "runs": {}}
        for name, options in RUNS.items():
            t0 = time.perf_counter()
            sim = sb.Simulator(model, dt=1 / 60, **options)
            sim.run(model.state(), 1)  # builds the factor or the multigrid hierarchy
            entry = {"setup_s": time.perf_counter() - t0}
            rate = steps_per_second(model, sim)
            entry["simulated_per_wall_second"] = rate * sim.dt
            if sim.integrator == sb.Integrator.PROJECTIVE:
                entry["factor_nonzeros"] = sim.solver.factor(sim.dt).factor_nonzeros
            if 2.0 / entry["simulated_per_wall_second"] <= CHECK_BUDGET:
                entry["full_drop"] = check_drop(model, sim)
            row["runs"][name] = entry
            drop = entry.get("full_drop")
            print(
                f"{model.particle_count:>7} {name:26s} {entry['simulated_per_wall_second']:8.3f}x"
                + (
                    f"  ok={drop['ok']} rebound {drop['rebound_m']:.2f} m, end height "
                    f"{drop['final_height_m']:.2f} m, volume {drop['volume_ratio_range'][0]:.2f}"
                    f"-{drop['volume_ratio_range'][1]:.2f}, real time "
                    f"{drop['simulated_per_wall_second']:.2f}x"
                    if drop
                    else ""
                ),
                flush=True,
            )
        sizes.append(row)
    realtime = {
        name: max(
            [
                r["vertex_count"]
                for r in sizes
                if r["runs"][name].get("full_drop", {}).get("ok")
                and r["runs"][name]["full_drop"]["simulated_per_wall_second"] >= 1.0
            ],
            default=0,
        )
        for name in RUNS
    }
    print("largest real-time checked drop (vertices):", realtime)
    result = run_record(
        "projective_drop",
        threads=1,
        dtype="float64",
        dt_s=1 / 60,
        sizes=sizes,
        largest_realtime_vertex_count=realtime,
    )
    write_json(RESULTS / "projective_drop.json", result)
    plot(result)
    print(f"wrote {RESULTS / 'projective_drop.json'} and .png")


def plot(result: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_s, ax_h) = plt.subplots(1, 2, figsize=(11, 4.5), dpi=110)
    for k, name in enumerate(RUNS):
        xs = np.array([r["vertex_count"] for r in result["sizes"]])
        runs = [r["runs"][name] for r in result["sizes"]]
        speed = np.array([e["simulated_per_wall_second"] for e in runs])
        ok = np.array([e.get("full_drop", {}).get("ok", False) for e in runs])
        ax_s.plot(xs, speed, "-", color=f"C{k}", label=name)
        ax_s.plot(xs[ok], speed[ok], "o", color=f"C{k}")
        ax_s.plot(xs[~ok], speed[~ok], "o", mfc="none", color=f"C{k}")
        checked = [(x, e["full_drop"]) for x, e in zip(xs, runs, strict=True) if "full_drop" in e]
        if checked:
            cx = [x for x, _ in checked]
            ax_h.plot(
                cx,
                [d["rebound_m"] for _, d in checked],
                "-o",
                color=f"C{k}",
                label=f"{name}: rebound",
            )
            ax_h.plot(
                cx,
                [d["final_height_m"] for _, d in checked],
                "--s",
                color=f"C{k}",
                label=f"{name}: height at 2 s",
            )
    ax_s.axhline(1.0, color="k", lw=0.8)
    ax_s.set_yscale("log")
    ax_s.set_ylabel("simulated seconds per wall second")
    ax_s.set_title("Ball drop at 1/60 s (filled: checked drop passed; black: real time)")
    ax_h.axhline(1.0, color="k", lw=0.8, ls=":")
    ax_h.set_ylabel("[m]")
    ax_h.set_title("Rebound, and centre height at 2 s (dotted: one radius)")
    for ax in (ax_s, ax_h):
        ax.set_xscale("log")
        ax.set_xlabel("vertices")
        ax.grid(alpha=0.3, which="both")
    ax_s.legend(fontsize=7)
    ax_h.legend(fontsize=6)
    fig.tight_layout()
    save_figure(fig, RESULTS / "projective_drop.png")


if __name__ == "__main__":
    main()
