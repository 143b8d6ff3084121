"""This version against an earlier one, case by case: is a change free?

The engine benchmark's ball (``ball_drop.ball_drop``, 2,562 to 40,962 vertices) stepped by
symplectic Euler and midpoint at 1e-5 s (as ``engine.py``), implicit Euler at 1/60 s
(multigrid, CG 1e-3) and projective dynamics with 2 iterations at 1/60 s; and the
five-ball scene (each of ``five_balls.py``'s runs, its integrator, step and options).
Both versions run in worker processes of their own (``versions.py``), new ones every round
(a process's memory layout alone moves a case's speed by several per cent), called in
alternation, each case once a round for ``ROUNDS`` rounds; each call is the best of
``REPEATS`` timed runs of at least ``MIN_SECONDS``. Reported per case: each version's best
rate and the median over rounds of this version's rate over the baseline's in the same
round (ratios are what this shared machine measures reliably; >= 0.97 is "no slowdown"
within its noise).

Writes results/paired.{json,png}. Usage, for the commit before a change:

    git worktree add /tmp/before COMMIT && (cd /tmp/before && python tools/build_core.py)
    python benchmarks/paired.py --baseline /tmp/before/src
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

import softbody as sb
from ball_drop import ball_drop
from results_io import RESULTS, run_record, save_figure, write_json
from versions import versions

ROUNDS = 5
REPEATS = 3
MIN_SECONDS = 0.2
BALL_CASES = [
    ("symplectic_euler", 1e-5, {}),
    ("midpoint", 1e-5, {}),
    ("implicit_euler", 1.0 / 60.0, {"implicit_preconditioner": "multigrid",
                                    "implicit_tolerance": 1e-3}),
    ("projective", 1.0 / 60.0, {"projective_iterations": 2}),
]  # fmt: skip

_CACHE: dict = {}


def build(kind: str, case: int, subdivisions: int = 4) -> tuple[sb.Model, sb.Simulator]:
    """The model and simulator of a case (cached): ``"ball"``, BALL_CASES[case] on the
    ball of ``subdivisions``; ``"five"``, five_balls.RUNS[case] (its step and options)."""
    key = (kind, case, subdivisions)
    if key in _CACHE:
        return _CACHE[key]
    if kind == "ball":
        integrator, dt, options = BALL_CASES[case]
        model = ball_drop(subdivisions)
    else:
        import five_balls

        integrator, step, options = five_balls.RUNS[case]
        model, dt, options = five_balls.setup(integrator, step, options)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        _CACHE[key] = model, sb.Simulator(model, integrator=integrator, dt=dt, **options)
    return _CACHE[key]


def rate(kind: str, case: int, subdivisions: int = 4) -> float:
    """The case's speed: vertex-steps per second for a ball, simulated seconds per wall
    second for the five balls; the best of REPEATS runs of at least MIN_SECONDS each."""
    model, sim = build(kind, case, subdivisions)
    per_step = model.particle_count if kind == "ball" else sim.dt
    sim.run(model.state(), 2)  # buffers and caches warm
    steps = 4
    while True:  # steps for one timed run of MIN_SECONDS
        state = model.state()
        start = time.perf_counter()
        sim.run(state, steps)
        if time.perf_counter() - start >= MIN_SECONDS:
            break
        steps *= 2
    best = 0.0
    for _ in range(REPEATS):
        state = model.state()
        start = time.perf_counter()
        sim.run(state, steps)
        best = max(best, per_step * steps / (time.perf_counter() - start))
    return best


def case_name(kind: str, case: int, subdivisions: int) -> str:
    if kind == "ball":
        integrator, dt, _ = BALL_CASES[case]
        return f"ball {ball_drop(subdivisions).particle_count}: {integrator} at {dt:.3g} s"
    import five_balls

    integrator, step, options = five_balls.RUNS[case]
    extra = ", ".join(f"{k}={v}" for k, v in options.items())
    return f"five balls: {integrator} at {step}" + (f" ({extra})" if extra else "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--baseline", type=Path, required=True,
        help="the src folder of the earlier version, its core built in place",
    )  # fmt: skip
    parser.add_argument("--max-subdivisions", type=int, default=6)
    parser.add_argument("--rounds", type=int, default=ROUNDS, help="rounds per case")
    parser.add_argument("--only", default="", help="only the cases whose name contains this")
    parser.add_argument("--out", default="paired", help="results/OUT.{json,png}")
    args = parser.parse_args()
    import five_balls

    cases = [("ball", k, s) for s in range(4, args.max_subdivisions + 1)
             for k in range(len(BALL_CASES))]  # fmt: skip
    cases += [("five", k, 4) for k in range(len(five_balls.RUNS))]
    cases = [c for c in cases if args.only in case_name(*c)]
    rows = []
    ratios = {c: [] for c in cases}
    best = {c: {"this": 0.0, "baseline": 0.0} for c in cases}
    for r in range(args.rounds):
        # fresh worker processes every round: a process's memory layout alone moves a
        # case's speed by several per cent, so each round samples new ones
        this, baseline = versions(args.baseline)
        for kind, case, subdivisions in cases:
            order = [this, baseline] if r % 2 == 0 else [baseline, this]
            rates = {v.name: v.call("paired:rate", kind=kind, case=case,
                                    subdivisions=subdivisions) for v in order}  # fmt: skip
            ratios[(kind, case, subdivisions)].append(rates["this"] / rates["baseline"])
            for v in ("this", "baseline"):
                best[(kind, case, subdivisions)][v] = max(best[(kind, case, subdivisions)][v],
                                                          rates[v])  # fmt: skip
        for v in (this, baseline):
            v.close()
        print(f"round {r + 1} of {args.rounds} done", flush=True)
    for c in cases:
        row = {"case": case_name(*c), **best[c], "ratio": float(np.median(ratios[c])),
               "ratios": ratios[c]}  # fmt: skip
        rows.append(row)
        print(f"{row['case']:70s} {row['ratio']:.3f}  {np.round(ratios[c], 3)}", flush=True)
    record = run_record("paired", baseline=str(args.baseline), rounds=args.rounds, cases=rows)
    write_json(RESULTS / f"{args.out}.json", record)
    plot(rows, "this version's speed / the baseline's", RESULTS / f"{args.out}.png")


def plot(rows: list[dict], label: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 0.28 * len(rows) + 1.4))
    y = np.arange(len(rows))
    for k, row in enumerate(rows):
        if "ratios" in row:
            ax.plot(row["ratios"], [k] * len(row["ratios"]), "o", color="0.7", markersize=3)
    ax.plot([r["ratio"] for r in rows], y, "D", color="C0")
    ax.axvline(1.0, color="k", linewidth=0.8)
    ax.axvline(0.97, color="C3", linewidth=0.8, linestyle="--")
    ax.set_yticks(y, [r["case"] for r in rows], fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel(f"{label}\nrounds (grey), their median (blue); dashed: 0.97")
    ax.set_title("This version against the baseline, case by case", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)


if __name__ == "__main__":
    main()
