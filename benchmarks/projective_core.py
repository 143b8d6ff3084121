"""Projective dynamics in the engine core against the Numba loop it replaced: step time.

The case: the ball drop's ball (``ball_drop.ball_drop``: an icosphere of radius 1 m,
inflated, over the ground) at 10,242 and 40,962 vertices, projective dynamics at 1/60 s
with 2 local-global iterations (the Simulator's default). For each size the C++ core (on
the instruction set in use) and the Numba loop of the baseline version (``--baseline
SRC``: the last with Numba, commit 91e398b, in a worker process of its own,
``versions.py``) step the same drop from its start, alternating, ``ROUNDS`` times, each
timing ``STEPS`` steps (the first half second of the drop: the fall and the first
contact). Reported: milliseconds per step, best of the rounds, and the core's speed-up
over Numba in each round (ratios are what a shared machine measures reliably).

Writes results/projective_core.{json,png}. Usage (engine.py's docstring makes the baseline):

    python benchmarks/projective_core.py --baseline /tmp/numba/src
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

import softbody as sb
from ball_drop import ball_drop
from results_io import RESULTS, plot_core_against_numba, run_record, write_json
from softbody import core
from versions import softbody_version, versions

DT = 1 / 60
ITERATIONS = 2
STEPS = 30
ROUNDS = 5


_SIMULATORS: dict = {}


def step_time(subdivisions: int) -> dict:
    """Seconds per step over STEPS steps of the drop from its start, in the version this
    process runs (the baseline: its Numba loop), and the factor's size."""
    if subdivisions not in _SIMULATORS:
        model = ball_drop(subdivisions)
        sim = sb.Simulator(model, integrator="projective", dt=DT,
                           projective_iterations=ITERATIONS)  # fmt: skip
        if softbody_version() == "baseline":
            from softbody import _kernel_cache

            _kernel_cache.ensure_compiled()
            sim._core = None  # the Numba loop
        sim.run(model.state(), 1)  # the factor, buffers and kernels warm
        _SIMULATORS[subdivisions] = model, sim
    model, sim = _SIMULATORS[subdivisions]
    state = model.state()
    start = time.perf_counter()
    sim.run(state, STEPS)
    seconds = (time.perf_counter() - start) / STEPS
    factor = sim.solver.factor(DT) if hasattr(sim, "solver") else sim._projective
    return {"seconds": seconds, "vertices": model.particle_count,
            "factor_nonzeros": int(factor.factor_nonzeros)}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subdivisions", type=int, nargs="+", default=[5, 6])
    parser.add_argument("--baseline", type=Path, required=True,
                        help="the src folder of the Numba version")  # fmt: skip
    args = parser.parse_args()
    this, baseline = versions(args.baseline)
    sizes = []
    for sub in args.subdivisions:
        times = {"core": [], "numba": []}
        for _ in range(ROUNDS):
            for engine, worker in (("core", this), ("numba", baseline)):
                out = worker.call("projective_core:step_time", subdivisions=sub)
                times[engine].append(out["seconds"])
        ratios = [n / c for c, n in zip(times["core"], times["numba"], strict=True)]
        row = {
            "vertex_count": out["vertices"],
            "factor_nonzeros": out["factor_nonzeros"],
            "core_ms_per_step": 1e3 * min(times["core"]),
            "numba_ms_per_step": 1e3 * min(times["numba"]),
            "speedup_per_round": ratios,
            "speedup_median": float(np.median(ratios)),
        }
        sizes.append(row)
        print(
            f"{row['vertex_count']:>7} vertices: core {row['core_ms_per_step']:.2f} ms/step, "
            f"numba {row['numba_ms_per_step']:.2f} ms/step, speed-up median "
            f"{row['speedup_median']:.2f} (rounds {', '.join(f'{r:.2f}' for r in ratios)})",
            flush=True,
        )
    this.close()
    baseline.close()
    record = run_record(
        "projective_core",
        dt=DT,
        iterations=ITERATIONS,
        steps_per_round=STEPS,
        rounds=ROUNDS,
        baseline="the Numba loop of commit 91e398b",
        command="python benchmarks/projective_core.py --baseline NUMBA_VERSION/src",
        simd_path=core.simd_path(),
        machine=platform.machine(),
        sizes=sizes,
    )
    write_json(RESULTS / "projective_core.json", record)
    plot(sizes)


def plot(sizes: list[dict]) -> None:
    """results/projective_core.png: ms per step, core beside Numba, per size."""
    plot_core_against_numba(
        RESULTS / "projective_core.png",
        [f"{s['vertex_count']:,}" for s in sizes],
        [s["core_ms_per_step"] for s in sizes],
        [s["numba_ms_per_step"] for s in sizes],
        f"projective dynamics, dt = 1/60 s, {ITERATIONS} iterations, one thread",
    )


if __name__ == "__main__":
    main()
