"""Reproduce the paper's Figure 6 and measure full-step throughput.

* Pressure-force time (the paper's steps 2 and 3: body volume, gas pressure, P A n / 3
  on each face corner) in ms against vertex count, icospheres of 162 to 163,842 vertices,
  with a least-squares trend line, as the paper plots it.
* Full-step throughput in vertex-steps per second for each integrator (springs on every
  edge, exact volume, pressure, integration, blow-up checks), single thread, float64;
  and symplectic Euler again with ``threads=2`` (opt-in), timed in alternation with the
  serial run so that both see the same machine load.

Speed is measured, never asserted. Each number is the best of several repeats (the
machine is shared; the minimum is the least disturbed run), and all sizes run in one
process so ratios compare like with like. Writes results/pressure_scaling.json and
results/pressure_scaling.png.

Usage: python benchmarks/pressure_scaling.py [--max-subdivisions 7] [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import warnings
from pathlib import Path

import numpy as np

import softbody as sb
from results_io import RESULTS, save_figure, write_json
from softbody import _core
from softbody.core import core_model
from softbody.sim.control import control_data

INTEGRATORS = ["symplectic_euler", "velocity_verlet", "midpoint", "rk4", "euler"]


def ball(subdivisions: int) -> sb.Model:
    """The paper's ball at a given refinement: radius 1 m, 1 kg, inflated, no gravity."""
    builder = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    builder.add_soft_body(
        sb.icosphere(subdivisions),
        mass=1.0,
        stiffness=500.0,
        damping=0.5,
        gas=sb.Gas.isothermal(300.0),
    )
    return builder.finalize()


def best_time(fn, *, min_seconds: float, repeats: int) -> float:
    """Best per-call time [s] over ``repeats`` batches lasting >= ``min_seconds`` each."""
    fn()
    t0 = time.perf_counter()
    fn()
    once = max(time.perf_counter() - t0, 1e-7)
    calls = max(1, int(min_seconds / once))
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - t0) / calls)
    return float(best)


def pressure_time(model: sb.Model, repeats: int) -> float:
    """Seconds for the paper's steps 2-3 once: body volumes, the gas pressure and the
    pressure force on every face corner, P dV/dx (the core measures the volumes, dV/dx
    and the pressures in one call; the product is NumPy's). Timed per call, so Python's
    call overhead (a few microseconds) is counted, which matters only below 1,000
    vertices."""
    core, control = core_model(model), control_data(model)
    q = model.particle_q.copy()

    def passes():
        _, pressure, gradient = _core.eval_volumes(core, control, 0.0, q)
        return (pressure[0] - model.body_ambient_pressure[0]) * gradient

    return best_time(passes, min_seconds=0.05, repeats=repeats)


def stepper(model: sb.Model, integrator: str, threads: int = 1):
    """A function running a batch of full steps in one compiled call, and the batch size."""
    with warnings.catch_warnings():
        # throughput does not depend on dt; a tiny dt keeps the ball near rest
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator=integrator, dt=1e-7, threads=threads)
    state = model.state()
    steps = max(1, int(2e5 / model.particle_count))
    return (lambda: sim.run(state, steps)), steps


def step_time(model: sb.Model, integrator: str, repeats: int) -> float:
    """Seconds per full step, timed over batches of steps in one compiled call each."""
    run, steps = stepper(model, integrator)
    return best_time(run, min_seconds=0.1, repeats=repeats) / steps


#: opt-in threads timed against serial (this machine has two cores)
THREADS = 2


def paired_step_times(model: sb.Model, integrator: str, repeats: int) -> tuple[float, float]:
    """Seconds per full step serially and on THREADS threads, the two timed in
    alternation (best of 3 x ``repeats`` each) so that both see the same load."""
    runs = [stepper(model, integrator, threads) for threads in (1, THREADS)]
    best = [np.inf, np.inf]
    for run, _ in runs:
        run()  # compile and warm up
    for _ in range(3 * repeats):
        for k, (run, steps) in enumerate(runs):
            t0 = time.perf_counter()
            run()
            best[k] = min(best[k], (time.perf_counter() - t0) / steps)
    return best[0], best[1]


def machine() -> dict:
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "simd": sb.core.simd_path(),
        "softbody": sb.__version__,
        "threads": f"1 (and {THREADS} for the threaded series)",
        "dtype": "float64",
    }


def plot(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["sizes"]
    n = np.array([r["vertex_count"] for r in rows])
    ms = np.array([r["pressure_ms"] for r in rows])
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), dpi=110)
    ax = axes[0]
    ax.plot(n, ms, "o", label="softbody (C++ core, 1 thread)")
    slope, intercept = (
        result["pressure_trend_ms"]["slope"],
        result["pressure_trend_ms"]["intercept"],
    )
    xs = np.linspace(0, n.max(), 100)
    ax.plot(xs, intercept + slope * xs, "--", label=f"trend: {slope * 1e6:.3g} ns per vertex")
    ax.set_xlabel("vertices")
    ax.set_ylabel("pressure force time [ms]")
    ax.set_title("Pressure force (volume + P + P A n / 3), cf. paper Fig. 6")
    ax.grid(alpha=0.3)
    ax.legend()
    ax = axes[1]
    for k, name in enumerate(INTEGRATORS):
        ax.plot(
            n,
            [r["vertex_steps_per_second"][name] / 1e6 for r in rows],
            "o-",
            color=f"C{k}",
            label=name,
        )
    ax.plot(
        n,
        [r["threads"]["threaded_vertex_steps_per_second"] / 1e6 for r in rows],
        "s--",
        color="C0",
        label=f"symplectic_euler, {THREADS} threads (opt-in)",
    )
    ax.set_xscale("log")
    ax.set_xlabel("vertices")
    ax.set_ylabel("million vertex-steps per second")
    ax.set_title("Full step throughput (float64; 1 thread unless marked)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.text(0.01, 0.01, result["machine"]["cpu"] + f", {result['date']}", fontsize=7, color="0.4")
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--min-subdivisions", type=int, default=2)
    parser.add_argument("--max-subdivisions", type=int, default=7)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for s in range(args.min_subdivisions, args.max_subdivisions + 1):
        model = ball(s)
        row = {
            "subdivisions": s,
            "vertex_count": model.particle_count,
            "tri_count": model.tri_count,
            "spring_count": model.spring_count,
            "pressure_ms": pressure_time(model, args.repeats) * 1e3,
            "step_us": {},
            "vertex_steps_per_second": {},
        }
        for name in INTEGRATORS:
            t = step_time(model, name, args.repeats)
            row["step_us"][name] = t * 1e6
            row["vertex_steps_per_second"][name] = model.particle_count / t
        serial, threaded = paired_step_times(model, "symplectic_euler", args.repeats)
        row["threads"] = {
            "integrator": "symplectic_euler",
            "threads": THREADS,
            "serial_step_us": serial * 1e6,
            "threaded_step_us": threaded * 1e6,
            "serial_vertex_steps_per_second": model.particle_count / serial,
            "threaded_vertex_steps_per_second": model.particle_count / threaded,
            "speedup": serial / threaded,
        }
        rows.append(row)
        print(
            f"{row['vertex_count']:>7} vertices: pressure {row['pressure_ms']:.4f} ms; "
            + ", ".join(f"{k} {v / 1e6:.1f} M" for k, v in row["vertex_steps_per_second"].items())
            + f" vertex-steps/s; symplectic Euler on {THREADS} threads "
            + f"{row['threads']['threaded_vertex_steps_per_second'] / 1e6:.1f} M "
            + f"({row['threads']['speedup']:.2f}x its paired serial run)",
            flush=True,
        )
    n = np.array([r["vertex_count"] for r in rows], dtype=float)
    ms = np.array([r["pressure_ms"] for r in rows])
    slope, intercept = np.polyfit(n, ms, 1)
    result = {
        "benchmark": "pressure_scaling",
        "date": time.strftime("%Y-%m-%d"),
        "machine": machine(),
        "sizes": rows,
        "pressure_trend_ms": {"slope": float(slope), "intercept": float(intercept)},
    }
    json_path = args.out / "pressure_scaling.json"
    write_json(json_path, result)
    plot(result, args.out / "pressure_scaling.png")
    print(f"wrote {json_path} and {args.out / 'pressure_scaling.png'}")


if __name__ == "__main__":
    main()
