"""The engine core's implicit Euler against the Numba solver it replaced: time per step.

The case: the ball drop's ball (``ball_drop.ball_drop``) at 2,562 and 10,242 vertices,
dropped at 1/60 s by implicit Euler (CG tolerance 1e-6, the default), with the multigrid
and the Jacobi preconditioner. The C++ core (the best instruction set this CPU runs) and
the Numba solver of the baseline version (``--baseline SRC``: the last with Numba, commit
91e398b, in a worker process of its own, ``versions.py``) run alternating, each over the
same 30 steps of the drop (the same CG work: the iteration counts are reported), best of
``ROUNDS``. Reported: milliseconds per step and the core's speed-up over Numba in each
round (ratios are what a shared machine measures reliably).

Writes results/implicit_core.{json,png}. Usage (engine.py's docstring makes the baseline):

    python benchmarks/implicit_core.py --baseline /tmp/numba/src
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import softbody as sb
from ball_drop import ball_drop
from results_io import RESULTS, plot_core_against_numba, run_record, write_json
from softbody import core
from versions import softbody_version, versions

DT = 1.0 / 60.0
STEPS = 30
ROUNDS = 3


_MODELS: dict = {}


def step_time(subdivisions: int, preconditioner: str) -> tuple[float, tuple, int]:
    """Seconds per step of STEPS implicit Euler steps of the drop, the CG iterations
    (mean, most), and the vertex count, in the version this process runs (the
    baseline: its Numba solver)."""
    if subdivisions not in _MODELS:
        _MODELS[subdivisions] = ball_drop(subdivisions)
    model = _MODELS[subdivisions]
    sim = sb.Simulator(model, integrator="implicit_euler", dt=DT,
                       implicit_preconditioner=preconditioner)  # fmt: skip
    if softbody_version() == "baseline":
        from softbody import _kernel_cache

        _kernel_cache.ensure_compiled()
        sim._core = None  # the Numba solver
    sim.run(model.state(), 1)  # buffers warm
    state = model.state()
    start = time.perf_counter()
    sim.run(state, STEPS)
    return (time.perf_counter() - start) / STEPS, sim.solver_iterations, model.particle_count


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subdivisions", type=int, nargs="+", default=[4, 5])
    parser.add_argument("--baseline", type=Path, required=True,
                        help="the src folder of the Numba version")  # fmt: skip
    args = parser.parse_args()
    this, baseline = versions(args.baseline)
    results = []
    for subdivisions in args.subdivisions:
        for preconditioner in ("multigrid", "jacobi"):
            best = {"core": float("inf"), "numba": float("inf")}
            ratios, iterations = [], {}
            for _ in range(ROUNDS):
                times = {}
                for engine, worker in (("core", this), ("numba", baseline)):
                    times[engine], iterations[engine], vertices = worker.call(
                        "implicit_core:step_time", subdivisions=subdivisions,
                        preconditioner=preconditioner,
                    )  # fmt: skip
                    best[engine] = min(best[engine], times[engine])
                ratios.append(times["numba"] / times["core"])
            row = {
                "vertices": vertices,
                "preconditioner": preconditioner,
                "ms_per_step": {e: 1e3 * t for e, t in best.items()},
                "speedup_over_numba": [min(ratios), max(ratios)],
                "cg_iterations_mean_most": iterations,
            }
            results.append(row)
            print(
                f"{vertices:6d} {preconditioner:9s} core {1e3 * best['core']:7.2f} ms"
                f"  numba {1e3 * best['numba']:7.2f} ms  x{min(ratios):.2f}-{max(ratios):.2f}"
                f"  CG {iterations}",
                flush=True,
            )
    this.close()
    baseline.close()
    write_json(
        RESULTS / "implicit_core.json",
        run_record(
            "implicit_core",
            machine=f"{platform.machine()}, {platform.processor() or 'cpu'}",
            command="python benchmarks/implicit_core.py --baseline NUMBA_VERSION/src",
            baseline="the Numba solver of commit 91e398b",
            dt=DT,
            steps=STEPS,
            simd_path=core.simd_path(),
            units="milliseconds per implicit Euler step, one thread",
            results=results,
        ),
    )
    plot(results)


def plot(results: list[dict]) -> None:
    """results/implicit_core.png: ms per step, core beside Numba, per size and
    preconditioner."""
    plot_core_against_numba(
        RESULTS / "implicit_core.png",
        [f"{r['vertices']:,}\n{r['preconditioner']}" for r in results],
        [r["ms_per_step"]["core"] for r in results],
        [r["ms_per_step"]["numba"] for r in results],
        "implicit Euler, dt = 1/60 s, ball drop, one thread",
    )


if __name__ == "__main__":
    main()
