"""The engine core against the Numba loop it replaced: explicit steps per second.

The case: the ball drop's ball (``ball_drop.ball_drop``: an icosphere of radius 1 m,
inflated, over the ground) at 2,562 to 40,962 vertices, stepped by symplectic Euler and
by midpoint at 1e-5 s. For each size and scheme the C++ core runs on each instruction set
this CPU has (scalar, AVX2, AVX-512; the SIMD ones also with the float32 force pass,
``-f32``), and with ``--baseline SRC`` the Numba loop of an
earlier version (the last with Numba: commit 91e398b, its core built in place) runs in a
worker process beside this one (``versions.py``); the runs alternate, each timed over at
least ``MIN_SECONDS`` of wall time, best of ``ROUNDS``. Reported: million vertex-steps
per second, and each path's speed-up over Numba in the same round (ratios are what this
shared 2-core machine measures reliably).

Writes results/engine.{json,png}. Usage:

    git worktree add /tmp/numba 91e398b && (cd /tmp/numba && python tools/build_core.py)
    python benchmarks/engine.py --baseline /tmp/numba/src [--max-subdivisions 6]

``--gas-flows`` runs the gas-flow case instead (issue 31's target: the flows cost under 2%
of a step at 10,242 vertices): the ball at 10,242 vertices holding an adiabatic ideal gas,
with a vent, an inflator and a leak, with a vent and an inflator only (the flows that are
per body), and with none, stepped by the same scheme at the same dt, alternated in each
of ``FLOW_ROUNDS`` rounds in this process; each round's CPU time per step with flows over
that without, their median and range. Writes results/engine_gas_flows.{json,png}.
"""

from __future__ import annotations

import argparse
import platform
import time
import warnings
from pathlib import Path

import numpy as np

import softbody as sb
from ball_drop import ball_drop
from results_io import RESULTS, run_record, save_figure, write_json
from softbody import core
from versions import softbody_version, versions

SCHEMES = ["symplectic_euler", "midpoint"]
DT = 1e-5
MIN_SECONDS = 0.3
ROUNDS = 3


def _rate(sim: sb.Simulator, model: sb.Model) -> float:
    """Vertex-steps per second of ``sim`` over at least MIN_SECONDS."""
    state = model.state()
    sim.run(state, 2)  # first call: buffers warm
    steps, elapsed = 4, 0.0
    while elapsed < MIN_SECONDS:
        steps *= 2
        state = model.state()
        start = time.perf_counter()
        sim.run(state, steps)
        elapsed = time.perf_counter() - start
    return model.particle_count * steps / elapsed


_SIMULATORS: dict = {}


def rate(subdivisions: int, scheme: str, simd: str | None, precision: str = "float64") -> float:
    """Vertex-steps per second of ``scheme`` on the ball of ``subdivisions``, in the
    version this process runs: this one's core on instruction set ``simd`` with its force
    pass in ``precision``, or the baseline's Numba loop (its Simulator's core set aside, as
    that version allowed)."""
    key = (subdivisions, scheme, precision)
    if key not in _SIMULATORS:
        model = ball_drop(subdivisions)
        options = {} if precision == "float64" else {"force_precision": precision}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sb.StabilityWarning)
            sim = sb.Simulator(model, integrator=scheme, dt=DT, **options)
        if softbody_version() == "baseline":
            from softbody import _kernel_cache

            _kernel_cache.ensure_compiled()
            sim._core = None  # the Numba loop
        _SIMULATORS[key] = model, sim
    model, sim = _SIMULATORS[key]
    if simd is not None:
        core.use_simd(simd)
    return _rate(sim, model)


FLOW_ROUNDS = 41
FLOW_SECONDS = 0.1  # per measurement: many short alternations average out the other jobs
FLOW_SUBDIVISIONS = 5  # 10,242 vertices
FLOW_CASES = ("none", "vent+inflator", "vent+inflator+leak")


def gas_flow_ball(flows: str) -> sb.Model:
    """The ball drop's ball at 10,242 vertices holding adiabatic air at 1 atm over an
    ambient 1 atm, with the ``flows`` of FLOW_CASES: a vent open from the start (1 cm^2),
    an inflator (1 g/s at 600 K), a fabric leak (1e-9 kg/(s m^2 Pa))."""
    builder = sb.ModelBuilder()
    mesh = sb.icosphere(FLOW_SUBDIVISIONS, radius=1.0, center=(0.0, 2.0, 0.0))
    moles = 101325.0 * 4.18 / (sb.gas.GAS_CONSTANT * 293.15)
    gas = sb.Gas.ideal(moles, 293.15, process="adiabatic", ambient_pressure=101325.0)
    body = builder.add_soft_body(mesh, mass=1.0, stiffness=500.0, damping=0.5, gas=gas)
    if flows != "none":
        builder.add_vent(body, area=1e-4)
        builder.add_inflator(body, mass_flow=1e-3, temperature=600.0)
    if flows.endswith("leak"):
        builder.add_leak(body, coefficient=1e-9)
    builder.add_collider(sb.ColliderPlane(restitution=0.5, friction=0.1))
    return builder.finalize()


def _seconds_per_step(sim: sb.Simulator, model: sb.Model, steps: int) -> float:
    """CPU seconds of this process per step (one thread: less swayed than wall time by
    the other jobs on this shared machine)."""
    state = model.state()
    sim.run(state, 2)
    start = time.process_time()
    sim.run(state, steps)
    return (time.process_time() - start) / steps


def gas_flows() -> None:
    """The gas-flow case (module docstring): results/engine_gas_flows.{json,png}."""
    results = []
    for scheme in SCHEMES:
        sims = {}
        for case in FLOW_CASES:
            model = gas_flow_ball(case)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", sb.StabilityWarning)
                sims[case] = model, sb.Simulator(model, integrator=scheme, dt=DT)
        # steps for about FLOW_SECONDS a measurement
        probe = _seconds_per_step(sims["none"][1], sims["none"][0], 20)
        steps = max(20, int(FLOW_SECONDS / probe))
        times = {case: [] for case in FLOW_CASES}
        for k in range(FLOW_ROUNDS):
            order = FLOW_CASES if k % 2 == 0 else FLOW_CASES[::-1]  # alternate the order
            for case in order:
                model, sim = sims[case]
                times[case].append(_seconds_per_step(sim, model, steps))
        base = np.array(times["none"])
        ratios = {c: (np.array(times[c]) / base).tolist() for c in FLOW_CASES if c != "none"}
        row = {
            "scheme": scheme,
            "vertices": sims["none"][0].particle_count,
            "steps_per_measurement": steps,
            "seconds_per_step": {c: float(np.median(t)) for c, t in times.items()},
            "seconds_per_step_rounds": times,
            "ratio_to_none": {c: r for c, r in ratios.items()},
            "median_ratio": {c: float(np.median(r)) for c, r in ratios.items()},
            # the least disturbed measurement of each case (best of the rounds)
            "best_ratio": {c: float(min(times[c]) / min(times["none"])) for c in ratios},
        }
        results.append(row)
        print(
            f"{scheme:17s} {row['vertices']:,} vertices, "
            f"{row['seconds_per_step']['none'] * 1e3:.3f} ms a step without flows; "
            + ", ".join(
                f"{c}: x{np.median(r):.4f} ({min(r):.3f}-{max(r):.3f}), "
                f"best x{row['best_ratio'][c]:.4f}"
                for c, r in ratios.items()
            ),
            flush=True,
        )
    write_json(
        RESULTS / "engine_gas_flows.json",
        run_record(
            "engine_gas_flows",
            machine=f"{platform.machine()}, {platform.processor() or 'cpu'}",
            command="python benchmarks/engine.py --gas-flows",
            dt=DT,
            rounds=FLOW_ROUNDS,
            units="CPU time per step with the flows over without them (same scheme, dt, mesh)",
            results=results,
        ),
    )
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.2))
    for k, row in enumerate(results):
        for j, (case, r) in enumerate(row["ratio_to_none"].items()):
            x = k * 3 + j
            ax.plot([x] * len(r), r, "o", color=f"C{j}", alpha=0.5,
                    label=case if k == 0 else None)  # fmt: skip
            ax.plot([x - 0.3, x + 0.3], [np.median(r)] * 2, color=f"C{j}", lw=2.5)
    ax.axhline(1.02, color="k", ls="--", lw=1, label="target: +2%")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xticks([k * 3 + 0.5 for k in range(len(results))], [r["scheme"] for r in results])
    ax.set_ylabel("time per step / without flows")
    ax.set_title(f"Gas flows at {results[0]['vertices']:,} vertices, dt = {DT:g} s, "
                 f"{FLOW_ROUNDS} alternating rounds (bars: medians)")  # fmt: skip
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, RESULTS / "engine_gas_flows.png")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-subdivisions", type=int, default=6)
    parser.add_argument("--baseline", type=Path, help="the src folder of the Numba version")
    parser.add_argument("--gas-flows", action="store_true", help="the gas-flow case instead")
    args = parser.parse_args()
    if args.gas_flows:
        gas_flows()
        return
    workers = versions(args.baseline)
    paths = core.simd_paths()
    engines = {f"core-{p}": (workers[0], p, "float64") for p in paths}
    # the float32 force pass (force_precision="float32") on the SIMD paths
    engines.update({f"core-{p}-f32": (workers[0], p, "float32") for p in paths if p != "scalar"})
    if args.baseline:
        engines["numba"] = (workers[1], None, "float64")
    results = []
    for subdivisions in range(4, args.max_subdivisions + 1):
        vertices = ball_drop(subdivisions).particle_count
        for scheme in SCHEMES:
            best = {e: 0.0 for e in engines}
            ratios = {e: [] for e in engines if e != "numba"}
            for _ in range(ROUNDS):
                rates = {}
                for e, (worker, simd, precision) in engines.items():
                    options = {} if precision == "float64" else {"precision": precision}
                    rates[e] = worker.call("engine:rate", subdivisions=subdivisions,
                                           scheme=scheme, simd=simd, **options)  # fmt: skip
                    best[e] = max(best[e], rates[e])
                for e in ratios:
                    if "numba" in rates:
                        ratios[e].append(rates[e] / rates["numba"])
            row = {
                "vertices": vertices,
                "scheme": scheme,
                "mvps": {e: best[e] / 1e6 for e in engines},
            }
            if args.baseline:
                row["speedup_over_numba"] = {e: [min(r), max(r)] for e, r in ratios.items()}
            results.append(row)
            print(
                f"{vertices:6d} {scheme:17s} "
                + " ".join(f"{e}={best[e] / 1e6:6.1f}" for e in engines)
                + "  x"
                + " ".join(f"{e}:{min(r):.2f}-{max(r):.2f}" for e, r in ratios.items() if r),
                flush=True,
            )
    for worker in workers:
        worker.close()
    write_json(
        RESULTS / "engine.json",
        run_record(
            "engine",
            machine=f"{platform.machine()}, {platform.processor() or 'cpu'}",
            command="python benchmarks/engine.py"
            + (" --baseline NUMBA_VERSION/src" if args.baseline else ""),
            baseline="the Numba loop of commit 91e398b" if args.baseline else None,
            dt=DT,
            simd_paths=paths,
            units="million vertex-steps per second (mvps), one thread",
            results=results,
        ),
    )
    _plot(results, list(engines))
    print(markdown_table(results, list(engines)))


def markdown_table(results: list[dict], engines: list[str]) -> str:
    """The results as the README's table: rate per path, and the range of each core path's
    ratio to Numba over the rounds."""
    head = (
        "| vertices | scheme | "
        + " | ".join(engines)
        + " | "
        + " | ".join(f"{e} / numba" for e in engines if e != "numba")
    )
    lines = [head + " |", "|" + "---|" * (2 + len(engines) + len(engines) - 1)]
    for r in results:
        rates = " | ".join(f"{r['mvps'][e]:.1f}" for e in engines)
        spans = r.get("speedup_over_numba", {}).values()
        ratios = " | ".join(f"{lo:.2f}-{hi:.2f}" for lo, hi in spans)
        lines.append(f"| {r['vertices']:,} | {r['scheme']} | {rates} | {ratios} |")
    return "\n".join(lines)


def _plot(results: list[dict], engines: list[str]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(SCHEMES), figsize=(11, 4.2), sharey=True)
    for ax, scheme in zip(np.atleast_1d(axes), SCHEMES, strict=True):
        rows = [r for r in results if r["scheme"] == scheme]
        x = [r["vertices"] for r in rows]
        for e in engines:
            style = "k--o" if e == "numba" else "-o"
            ax.plot(x, [r["mvps"][e] for r in rows], style, label=e)
        ax.set_xscale("log")
        ax.set_xticks(x, [f"{v:,}" for v in x])
        ax.minorticks_off()
        ax.set_title(f"{scheme}, dt = {DT:g} s, one thread")
        ax.set_xlabel("vertices")
        ax.grid(True, alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("million vertex-steps / s")
    np.atleast_1d(axes)[0].legend()
    fig.suptitle("Engine core (C++) against the Numba loop, ball drop, alternating")
    fig.tight_layout()
    save_figure(fig, RESULTS / "engine.png")


if __name__ == "__main__":
    main()
