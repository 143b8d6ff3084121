"""The paper's five-ball scene (``bouncing-balls``): simulated seconds per wall second.

Five 162-vertex balls in a box spinning about a horizontal axis (paper, Figures 1 and 7),
10 s of simulated time per integrator: the scene's own midpoint step (0.5 ms), symplectic
Euler and velocity Verlet at 0.9 of their stability estimate, implicit Euler at 1/60 s
with either preconditioner and BDF2 at 1/60 s (CG tolerance 1e-3; the multigrid runs
again at 1e-2). Each run is timed inside one compiled call (kernels compiled before,
best of 3) and checked: every ball
keeps its volume within [0.6, 1.6] of its rest volume and stays inside the box, and the
kinetic energy, sampled every 0.1 s in a separate untimed run, averages within 1.5x of
RK4's at 0.5 ms (an unstable step passed the first two checks while its balls shook
with 17x the reference's kinetic energy).

Writes results/five_balls.{json,png}.
Usage: python benchmarks/five_balls.py
"""

from __future__ import annotations

import time

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
    ("velocity_verlet", "0.9 x stable", {}),
    ("implicit_euler", "1/60 s", {"implicit_preconditioner": "jacobi"}),
    ("implicit_euler", "1/60 s", {"implicit_preconditioner": "multigrid"}),
    ("bdf2", "1/60 s", {"implicit_preconditioner": "multigrid"}),
    (
        "implicit_euler",
        "1/60 s",
        {"implicit_preconditioner": "multigrid", "implicit_tolerance": 1e-2},
    ),
    ("bdf2", "1/60 s", {"implicit_preconditioner": "multigrid", "implicit_tolerance": 1e-2}),
]


def mean_kinetic_energy(model, sim: sb.Simulator) -> float:
    """Kinetic energy [J] averaged over samples every SAMPLE seconds of DURATION."""
    state, samples = model.state(), []
    per_sample = round(SAMPLE / sim.dt)
    for _ in range(round(DURATION / SAMPLE)):
        sim.run(state, per_sample)
        samples.append(sb.energies(model, state).kinetic)
    return float(np.mean(samples))


def run(integrator: str, step: str, options: dict, reference_energy: float) -> dict:
    scene = load_scene("bouncing-balls")
    model = scene.model
    if step == "scene dt":
        dt = scene.dt
    elif step == "1/60 s":
        dt = 1.0 / 60.0
        options = {"implicit_tolerance": 1e-3, **options}
    else:
        dt = 0.9 * sb.Simulator(model, integrator=integrator, dt=1e-6).stable_dt
    sim = sb.Simulator(model, integrator=integrator, dt=dt, **options)
    steps = round(DURATION / dt)
    sim.run(model.state(), 2)  # compile
    best = np.inf
    for _ in range(3):
        state = model.state()
        t0 = time.perf_counter()
        sim.run(state, steps)
        best = min(best, time.perf_counter() - t0)
    energy_ratio = mean_kinetic_energy(model, sim) / reference_energy
    ratios = sb.body_volume(model, state) / model.body_rest_volume
    # the box's half extents are 1.3 x 1.3 x 0.6 m about the origin; it rotates about z,
    # so every vertex stays within the box's circumscribed cylinder
    radius = np.hypot(state.particle_q[:, 0], state.particle_q[:, 1]).max()
    inside = radius <= np.hypot(1.3, 1.3) + 1e-6 and np.abs(state.particle_q[:, 2]).max() <= 0.6
    name = integrator
    if "implicit_preconditioner" in options:
        name += f" ({options['implicit_preconditioner']}, cg {options['implicit_tolerance']:g})"
    return {
        "name": name,
        "dt_s": dt,
        "steps": steps,
        "wall_s": best,
        "simulated_per_wall_second": DURATION / best,
        "cg_iterations_mean": sim.solver_iterations[0],
        "volume_ratio_range": [float(ratios.min()), float(ratios.max())],
        "kinetic_energy_ratio": energy_ratio,
        "ok": bool(
            0.6 < ratios.min()
            and ratios.max() < 1.6
            and inside
            and 1 / ENERGY_RATIO < energy_ratio < ENERGY_RATIO
        ),
    }


def main() -> None:
    model = load_scene("bouncing-balls").model
    reference_energy = mean_kinetic_energy(model, sb.Simulator(model, integrator="rk4", dt=5e-4))
    rows = []
    for integrator, step, options in RUNS:
        row = run(integrator, step, options, reference_energy)
        rows.append(row)
        print(
            f"{row['name']:36s} dt {row['dt_s']:.2e} s  {row['wall_s']:7.3f} s wall  "
            f"{row['simulated_per_wall_second']:7.1f}x real time  "
            f"kinetic energy {row['kinetic_energy_ratio']:.2f}x RK4's  ok={row['ok']}",
            flush=True,
        )
    result = run_record(
        "five_balls",
        threads=1,
        dtype="float64",
        duration_s=DURATION,
        reference_kinetic_energy_j=reference_energy,
        runs=rows,
    )
    write_json(RESULTS / "five_balls.json", result)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4), dpi=110)
    names = [f"{r['name']}\ndt {r['dt_s'] * 1e3:.2g} ms" for r in rows]
    speeds = [r["simulated_per_wall_second"] for r in rows]
    bars = ax.barh(names, speeds, color=["C0" if r["ok"] else "C3" for r in rows])
    ax.bar_label(bars, labels=[f"{s:.1f}x" for s in speeds], padding=3, fontsize=8)
    ax.axvline(1.0, color="k", lw=1, ls=":")
    ax.set_xscale("log")
    ax.set_xlabel("simulated seconds per wall second (10 s of the scene)")
    ax.set_title("Five-ball scene (810 vertices), one thread, float64", fontsize=10)
    ax.invert_yaxis()
    fig.tight_layout()
    save_figure(fig, RESULTS / "five_balls.png")
    print(f"wrote {RESULTS / 'five_balls.json'} and .png")


if __name__ == "__main__":
    main()
