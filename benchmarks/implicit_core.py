"""The engine core's implicit Euler against the Numba solver it replaces: time per step.

The case: the ball drop's ball (``ball_drop.ball_drop``) at 2,562 and 10,242 vertices,
dropped at 1/60 s by implicit Euler (CG tolerance 1e-6, the default), with the multigrid
and the Jacobi preconditioner. The C++ core (the best instruction set this CPU runs) and
the Numba solver run in the same process, alternating, each over the same 30 steps of the
drop (the same CG work: the iteration counts are reported), best of ``ROUNDS``. Reported:
milliseconds per step and the core's speed-up over Numba in each round (ratios are what a
shared machine measures reliably).

Writes results/implicit_core.json. Usage: python benchmarks/implicit_core.py
"""

from __future__ import annotations

import argparse
import platform
import time

import softbody as sb
from ball_drop import ball_drop
from results_io import RESULTS, plot_core_against_numba, run_record, write_json
from softbody import _kernel_cache, core

DT = 1.0 / 60.0
STEPS = 30
ROUNDS = 3


def _step_time(model: sb.Model, preconditioner: str, engine: str) -> tuple[float, tuple]:
    """Seconds per step of STEPS implicit Euler steps of the drop, and the CG iterations
    (mean, most)."""
    sim = sb.Simulator(model, integrator="implicit_euler", dt=DT,
                       implicit_preconditioner=preconditioner)  # fmt: skip
    if engine == "numba":
        sim._core = None  # the previous engine's solver, same arithmetic
    sim.run(model.state(), 1)  # buffers warm
    state = model.state()
    start = time.perf_counter()
    sim.run(state, STEPS)
    return (time.perf_counter() - start) / STEPS, sim.solver_iterations


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subdivisions", type=int, nargs="+", default=[4, 5])
    args = parser.parse_args()
    _kernel_cache.ensure_compiled()
    results = []
    for subdivisions in args.subdivisions:
        model = ball_drop(subdivisions)
        for preconditioner in ("multigrid", "jacobi"):
            best = {"core": float("inf"), "numba": float("inf")}
            ratios, iterations = [], {}
            for _ in range(ROUNDS):
                times = {}
                for engine in ("core", "numba"):
                    times[engine], iterations[engine] = _step_time(model, preconditioner, engine)
                    best[engine] = min(best[engine], times[engine])
                ratios.append(times["numba"] / times["core"])
            row = {
                "vertices": model.particle_count,
                "preconditioner": preconditioner,
                "ms_per_step": {e: 1e3 * t for e, t in best.items()},
                "speedup_over_numba": [min(ratios), max(ratios)],
                "cg_iterations_mean_most": iterations,
            }
            results.append(row)
            print(
                f"{model.particle_count:6d} {preconditioner:9s} core {1e3 * best['core']:7.2f} ms"
                f"  numba {1e3 * best['numba']:7.2f} ms  x{min(ratios):.2f}-{max(ratios):.2f}"
                f"  CG {iterations}",
                flush=True,
            )
    write_json(
        RESULTS / "implicit_core.json",
        run_record(
            "implicit_core",
            machine=f"{platform.machine()}, {platform.processor() or 'cpu'}",
            command="python benchmarks/implicit_core.py",
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
