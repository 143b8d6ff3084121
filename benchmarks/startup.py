"""Start-up: compiling the kernels, and setting a simulation up, against mesh size.

Two parts, one run:

* **Compile** (cold and warm start): for each integrator family (explicit, implicit,
  projective; represented by midpoint, implicit Euler and projective dynamics), a fresh
  Python process with an empty kernel cache imports softbody, builds a 162-vertex ball,
  a simulator, and runs 3 steps; then a second process does the same again. The C++ core
  compiles nothing at run time, so both are its start-up; a version with Numba kernels
  (``--baseline OLD/src``, timed alternately in the same run) compiled them into the
  empty cache first.
* **Set-up against size** (cache warm, this process): for the ball drop's ball
  (``ball_drop.ball_drop``) from 162 to 163,842 vertices, the time to build the model,
  and for velocity Verlet (its stability estimate), implicit Euler (its multigrid
  hierarchy) and projective dynamics (its factored matrix) the set-up: building the
  simulator plus its first step less its second (a step's own cost), best of
  ``REPEATS``.

Writes results/startup.{json,png}. Usage: python benchmarks/startup.py [--baseline SRC]
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
import tempfile
import time
import warnings
from pathlib import Path

import softbody as sb
from ball_drop import ball_drop
from results_io import RESULTS, run_record, save_figure, write_json

FAMILIES = {"explicit": "midpoint", "implicit": "implicit_euler", "projective": "projective"}
SUBDIVISIONS = [2, 3, 4, 5, 6, 7]
SETUP_RUNS = {
    "velocity_verlet": {"dt": 1e-5},
    "implicit_euler": {"dt": 1 / 60},
    "projective": {"dt": 1 / 60, "projective_iterations": 1},
}
REPEATS = 2

CHILD = """
import json, sys, time
t0 = time.perf_counter()
import softbody as sb
t1 = time.perf_counter()
builder = sb.ModelBuilder()
builder.add_soft_body(sb.icosphere(2), mass=1.0, stiffness=500.0, damping=0.5, gas=300.0)
model = builder.finalize()
t2 = time.perf_counter()
sim = sb.Simulator(model, integrator=sys.argv[1], dt=1e-4)
t3 = time.perf_counter()
sim.run(model.state(), 3)
t4 = time.perf_counter()
print(json.dumps({"import_s": t1 - t0, "model_s": t2 - t1, "simulator_s": t3 - t2,
                  "first_steps_s": t4 - t3, "total_s": t4 - t0}))
"""


def start(integrator: str, cache: Path, source: Path | None = None) -> dict:
    """One fresh process's start-up phases [s] with a kernel cache in ``cache``; with
    ``source``, softbody is imported from that folder (another version's ``src``)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    flags = []
    if source is not None:
        # -S: no site hooks, so an editable install's import redirect cannot swap this
        # version back in; the environment's packages come through PYTHONPATH
        site = sysconfig.get_paths()
        env["PYTHONPATH"] = os.pathsep.join([str(source), site["purelib"], site["platlib"]])
        flags = ["-S"]
    t = time.perf_counter()
    out = subprocess.run(
        [sys.executable, *flags, "-c", CHILD, integrator],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return {**json.loads(out.stdout.strip().splitlines()[-1]), "process_s": time.perf_counter() - t}


def compile_times(baseline: Path | None) -> list[dict]:
    """Cold and warm start per family, for this version and, alternating with it in the
    same run, the ``baseline`` version's sources when given."""
    versions = {"this": None} | ({"baseline": baseline} if baseline else {})
    rows = []
    for name, integrator in FAMILIES.items():
        for version, source in versions.items():
            with tempfile.TemporaryDirectory() as cache:
                cold = start(integrator, Path(cache), source)
                warm = start(integrator, Path(cache), source)
            rows.append(
                {
                    "family": name,
                    "integrator": integrator,
                    "version": version,
                    "cold": cold,
                    "warm": warm,
                }
            )
            print(
                f"{name:10s} ({integrator}, {version}): cold start {cold['process_s']:6.1f} s, "
                f"warm {warm['process_s']:5.2f} s",
                flush=True,
            )
    return rows


def setup_time(model: sb.Model, integrator: str, options: dict) -> float:
    """Building the simulator plus its first step less its second [s]."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        t0 = time.perf_counter()
        sim = sb.Simulator(model, integrator=integrator, **options)
        state = model.state()
        sim.run(state, 1)
        t1 = time.perf_counter()
        sim.run(state, 1)
        t2 = time.perf_counter()
    return (t1 - t0) - (t2 - t1)


def setup_times() -> list[dict]:
    small = ball_drop(1)
    for integrator, options in SETUP_RUNS.items():
        setup_time(small, integrator, options)  # load the kernels first
    rows = []
    for sub in SUBDIVISIONS:
        model_s = []
        for _ in range(REPEATS):
            t = time.perf_counter()
            model = ball_drop(sub)
            model_s.append(time.perf_counter() - t)
        row = {"vertices": model.particle_count, "model_s": min(model_s)}
        for integrator, options in SETUP_RUNS.items():
            row[f"{integrator}_s"] = min(
                setup_time(model, integrator, options) for _ in range(REPEATS)
            )
        rows.append(row)
        print(
            f"{row['vertices']:7d} vertices: model {row['model_s']:6.2f} s  "
            + "  ".join(f"{k} {row[f'{k}_s']:6.2f} s" for k in SETUP_RUNS),
            flush=True,
        )
    return rows


def main() -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--baseline",
        type=Path,
        help="another version's src folder, timed alternately with this one (cold starts)",
    )
    args = parser.parse_args()
    compiled = compile_times(args.baseline)
    sizes = setup_times()
    result = run_record(
        "startup",
        threads=1,
        python=sys.version.split()[0],
        baseline=str(args.baseline) if args.baseline else None,
        compile=compiled,
        setup=sizes,
    )
    write_json(RESULTS / "startup.json", result)
    plot(result)
    print(f"wrote {RESULTS / 'startup.json'} and .png")


def plot(result: dict) -> None:
    """Cold and warm starts per family; set-up seconds against vertices."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 4.2), dpi=110)
    rows = result["compile"]
    y = np.arange(len(rows))
    cold = [r["cold"]["process_s"] for r in rows]
    warm = [r["warm"]["process_s"] for r in rows]
    bars = ax0.barh(y - 0.2, cold, height=0.4, color="C3", label="first process")
    ax0.bar_label(bars, labels=[f"{v:.1f} s" for v in cold], padding=3, fontsize=8)
    bars = ax0.barh(y + 0.2, warm, height=0.4, color="C0", label="second process")
    ax0.bar_label(bars, labels=[f"{v:.1f} s" for v in warm], padding=3, fontsize=8)
    ax0.set_yticks(
        y, [f"{r['family']} ({r['integrator']})\n{r.get('version', 'this')}" for r in rows]
    )
    ax0.invert_yaxis()
    ax0.set_xlim(right=1.25 * max(cold + warm))
    ax0.set_xlabel("seconds from a fresh process to 3 steps (162 vertices)")
    ax0.set_title("Start-up per integrator family", fontsize=10)
    ax0.legend(fontsize=8, loc="lower right")
    sizes = result["setup"]
    v = [r["vertices"] for r in sizes]
    ax1.loglog(v, [r["model_s"] for r in sizes], "o-", color="k", label="model (mesh checks)")
    for i, integrator in enumerate(SETUP_RUNS):
        what = {
            "velocity_verlet": "stability estimate",
            "implicit_euler": "multigrid",
            "projective": "factored matrix",
        }[integrator]
        ax1.loglog(
            v,
            [max(r[f"{integrator}_s"], 1e-4) for r in sizes],
            "s-",
            color=f"C{i}",
            label=f"{integrator} ({what})",
        )
    ax1.set_xlabel("vertices")
    ax1.set_ylabel("seconds")
    ax1.set_title("Set-up against mesh size", fontsize=10)
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(fontsize=8)
    fig.suptitle(f"softbody start-up, {result['date']}, {result['cores']} cores", fontsize=10)
    fig.tight_layout()
    save_figure(fig, RESULTS / "startup.png")


if __name__ == "__main__":
    main()
