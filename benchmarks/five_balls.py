"""The paper's five-ball scene (``bouncing-balls``): simulated seconds per wall second.

Five 162-vertex balls in a box spinning about a horizontal axis (paper, Figures 1 and 7),
10 s of simulated time per integrator: the scene's own midpoint step (0.5 ms), symplectic
Euler and velocity Verlet at 0.9 of their stability estimate, implicit Euler at 1/60 s
with either preconditioner and BDF2 at 1/60 s (CG tolerance 1e-3; the multigrid runs
again at 1e-2), projective dynamics with 1, 2 and 4 iterations at 0.9 of its estimate
(the gas's, 1 / omega_gas), and XPBD with small steps at 1/60 s frames (its default
substeps, and 16). Each run is timed inside one compiled call
(kernels compiled before, best of 3) and checked; a run that blows up is recorded as
failed. The checks: every ball keeps its volume within [0.6, 1.6] of its rest volume,
at the end and in samples every 0.1 s of a separate untimed run, and stays inside the
box; the kinetic energy, sampled in that run, averages within 1.5x of RK4's at 0.5 ms
(an unstable step passed the first two checks while its balls shook with 17x the
reference's kinetic energy).

Writes results/five_balls.{json,png}. ``--runs xpbd`` measures only the runs of the
integrators named and merges them into results/five_balls.json (a run of the same name
replaced, every other run and the file's date kept; the date of the merge recorded).
Usage: python benchmarks/five_balls.py [--runs INTEGRATOR ...]
"""

from __future__ import annotations

import argparse
import json
import time
import warnings

import numpy as np

import softbody as sb
from results_io import RESULTS, run_record, save_figure, write_json
from softbody.scenes.loader import load_scene

DURATION = 10.0
SAMPLE = 0.1
ENERGY_RATIO = 1.5
RUNS = [
    ("midpoint", "scene dt", {}),
    ("symplectic_euler", "0.9 x stable", {}),
    ("symplectic_euler", "0.9 x stable", {"force_precision": "float32"}),
    ("velocity_verlet", "0.9 x stable", {}),
    ("velocity_verlet", "0.9 x stable", {"force_precision": "float32"}),
    ("implicit_euler", "1/60 s", {"implicit_preconditioner": "jacobi"}),
    ("implicit_euler", "1/60 s", {"implicit_preconditioner": "multigrid"}),
    ("bdf2", "1/60 s", {"implicit_preconditioner": "multigrid"}),
    (
        "implicit_euler",
        "1/60 s",
        {"implicit_preconditioner": "multigrid", "implicit_tolerance": 1e-2},
    ),
    ("bdf2", "1/60 s", {"implicit_preconditioner": "multigrid", "implicit_tolerance": 1e-2}),
    ("projective", "0.9 x stable", {"projective_iterations": 1}),
    ("projective", "0.9 x stable", {"projective_iterations": 2}),
    ("projective", "0.9 x stable", {"projective_iterations": 4}),
    ("xpbd", "1/60 s frames", {}),
    ("xpbd", "1/60 s frames", {"xpbd_substeps": 16}),
]


def sampled_run(model, sim: sb.Simulator) -> tuple[float, float, float]:
    """Kinetic energy [J] averaged over samples every SAMPLE seconds of DURATION, and the
    smallest and largest volume / rest volume of any ball in those samples."""
    state, energy, ratios = model.state(), [], []
    per_sample = round(SAMPLE / sim.dt)
    for _ in range(round(DURATION / SAMPLE)):
        sim.run(state, per_sample)
        energy.append(sb.energies(model, state).kinetic)
        ratios.append(sb.body_volume(model, state) / model.body_rest_volume)
    return float(np.mean(energy)), float(np.min(ratios)), float(np.max(ratios))


def setup(integrator: str, step: str, options: dict) -> tuple[sb.Model, float, dict]:
    """The scene's model, the step [s] a run of RUNS takes (the scene's, 1/60 s, a 1/60 s
    frame of substeps, or 0.9 of the integrator's stability estimate) and its Simulator
    options."""
    scene = load_scene("bouncing-balls")
    model = scene.model
    if step == "scene dt":
        dt = scene.dt
    elif step == "1/60 s frames":
        dt = 1.0 / 60.0
    elif step == "1/60 s":
        dt = 1.0 / 60.0
        options = {"implicit_tolerance": 1e-3, **options}
    else:
        dt = 0.9 * sb.Simulator(model, integrator=integrator, dt=1e-6).stable_dt
    return model, dt, options


def run(integrator: str, step: str, options: dict, reference_energy: float) -> dict:
    model, dt, options = setup(integrator, step, options)
    with warnings.catch_warnings():
        # a step past the (conservative) projective estimate warns; the checks decide
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator=integrator, dt=dt, **options)
    steps = round(DURATION / dt)
    name = integrator
    if "implicit_preconditioner" in options:
        name += f" ({options['implicit_preconditioner']}, cg {options['implicit_tolerance']:g})"
    if "projective_iterations" in options:
        name += f" ({options['projective_iterations']} it.)"
    if "force_precision" in options:
        name += f" ({options['force_precision']} forces)"
    if sim.integrator == sb.Integrator.XPBD:
        name += f" ({sim.solver.substeps} substeps)"
    sim.run(model.state(), 2)  # compile
    best = np.inf
    try:
        for _ in range(3):
            state = model.state()
            t0 = time.perf_counter()
            sim.run(state, steps)
            best = min(best, time.perf_counter() - t0)
        energy, low, high = sampled_run(model, sim)
    except sb.SimulationError as error:
        return {"name": name, "dt_s": dt, "steps": steps, "error": str(error), "ok": False}
    ratios = sb.body_volume(model, state) / model.body_rest_volume
    low, high = min(low, ratios.min()), max(high, ratios.max())
    energy_ratio = energy / reference_energy
    # the box's half extents are 1.3 x 1.3 x 0.6 m about the origin; it rotates about z,
    # so every vertex stays within the box's circumscribed cylinder
    radius = np.hypot(state.particle_q[:, 0], state.particle_q[:, 1]).max()
    inside = radius <= np.hypot(1.3, 1.3) + 1e-6 and np.abs(state.particle_q[:, 2]).max() <= 0.6
    return {
        "name": name,
        "dt_s": dt,
        "steps": steps,
        "wall_s": best,
        "simulated_per_wall_second": DURATION / best,
        "cg_iterations_mean": sim.solver_iterations[0],
        "volume_ratio_range": [float(low), float(high)],
        "kinetic_energy_ratio": energy_ratio,
        "ok": bool(
            0.6 < low and high < 1.6 and inside and 1 / ENERGY_RATIO < energy_ratio < ENERGY_RATIO
        ),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--runs", nargs="+", choices=sorted({r[0] for r in RUNS}), default=None,
        help="measure only the runs of these integrators and merge them into five_balls.json",
    )  # fmt: skip
    args = parser.parse_args()
    model = load_scene("bouncing-balls").model
    reference_energy, low, high = sampled_run(model, sb.Simulator(model, integrator="rk4", dt=5e-4))
    rows = []
    for integrator, step, options in RUNS:
        if args.runs is not None and integrator not in args.runs:
            continue
        row = run(integrator, step, options, reference_energy)
        rows.append(row)
        if "error" in row:
            print(f"{row['name']:36s} dt {row['dt_s']:.2e} s  failed: {row['error']}", flush=True)
            continue
        print(
            f"{row['name']:36s} dt {row['dt_s']:.2e} s  {row['wall_s']:7.3f} s wall  "
            f"{row['simulated_per_wall_second']:7.1f}x real time  "
            f"kinetic energy {row['kinetic_energy_ratio']:.2f}x RK4's  ok={row['ok']}",
            flush=True,
        )
    if args.runs is not None:
        result = json.loads((RESULTS / "five_balls.json").read_text())
        by_name = {r["name"]: k for k, r in enumerate(result["runs"])}
        for row in rows:
            if row["name"] in by_name:
                result["runs"][by_name[row["name"]]] = row
            else:
                result["runs"].append(row)
        result[f"{'+'.join(args.runs)} measured"] = time.strftime("%Y-%m-%d")
        write_json(RESULTS / "five_balls.json", result)
        plot(result["runs"])
        print(f"merged {args.runs} into {RESULTS / 'five_balls.json'} and .png")
        return
    result = run_record(
        "five_balls",
        threads=1,
        dtype="float64",
        duration_s=DURATION,
        reference_kinetic_energy_j=reference_energy,
        reference_volume_ratio_range=[low, high],
        runs=rows,
    )
    write_json(RESULTS / "five_balls.json", result)
    plot(rows)
    print(f"wrote {RESULTS / 'five_balls.json'} and .png")


def plot(rows: list[dict]) -> None:
    """Bars of simulated seconds per wall second, red where a check failed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 1.2 + 0.42 * len(rows)), dpi=110)
    names = [f"{r['name']}\ndt {r['dt_s'] * 1e3:.2g} ms" for r in rows]
    speeds = [r.get("simulated_per_wall_second", 0.0) for r in rows]
    bars = ax.barh(names, speeds, color=["C0" if r["ok"] else "C3" for r in rows])
    labels = [f"{s:.1f}x" if s else "blew up" for s in speeds]
    ax.bar_label(bars, labels=labels, padding=3, fontsize=8)
    ax.axvline(1.0, color="k", lw=1, ls=":")
    ax.set_xscale("log")
    ax.set_xlabel("simulated seconds per wall second (10 s of the scene)")
    ax.set_xlim(right=2.0 * max(speeds))
    ax.set_title(
        "Five-ball scene (810 vertices), one thread, float64\n"
        "red: failed a check (a ball's volume, the box or the kinetic energy)",
        fontsize=10,
    )
    ax.invert_yaxis()
    fig.tight_layout()
    save_figure(fig, RESULTS / "five_balls.png")


if __name__ == "__main__":
    main()
