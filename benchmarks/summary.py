"""The headline figures in one table and one plot, taken from the result files already in
results/ (nothing is measured again): each figure with its scene and size, the integrator
and step it ran at, the file it came from with that file's date, and the command that
measures it again. The README's speed figures and the benchmarks index quote this table.

The machine is the one the result files were written on (each file's page says which):
the project's 2-core AMD EPYC (Zen 4), one thread.

Writes results/summary.{json,png}.
Usage: python benchmarks/summary.py
"""

from __future__ import annotations

import json
from pathlib import Path

from results_io import RESULTS, save_figure, write_json

MACHINE = "the project's 2-core AMD EPYC (Zen 4), one thread, shared with other jobs"
REAL_TIME = "x real time"


def _load(results: Path, name: str) -> dict:
    return json.loads((results / f"{name}.json").read_text())


def _ms(dt: float) -> str:
    return f"{1e3 * dt:.3g} ms"


def five_balls(data: dict) -> list[dict]:
    """The paper's five balls (``bouncing-balls``, 5 x 162 vertices): the scene's own
    midpoint step, which ``softbody run`` uses, and the fastest valid run of each family."""
    runs = {r["name"]: r for r in data["runs"]}
    source = {"source": "five_balls.json", "date": data["date"],
              "command": "python benchmarks/five_balls.py"}  # fmt: skip
    picks = [
        ("five-balls-scene-step", "midpoint", "midpoint",
         "the scene's step, as `softbody run bouncing-balls` runs it"),
        ("five-balls-symplectic", "symplectic_euler", "symplectic Euler",
         "0.9 x its stability estimate"),
        ("five-balls-symplectic-f32", "symplectic_euler (float32 forces)",
         "symplectic Euler, float32 forces", "0.9 x its stability estimate"),
        ("five-balls-verlet", "velocity_verlet", "velocity Verlet",
         "0.9 x its stability estimate"),
        ("five-balls-implicit", "implicit_euler (multigrid, cg 0.01)",
         "implicit Euler, multigrid CG 1e-2", "1/60 s"),
    ]  # fmt: skip
    rows = []
    for key, name, integrator, why in picks:
        run = runs[name]
        if not run["ok"]:
            raise ValueError(f"five_balls.json: the run {name!r} failed its checks")
        rows.append({
            "key": key, "case": "five balls in the spinning box", "vertices": 810,
            "integrator": integrator, "dt_s": run["dt_s"], "step": f"{_ms(run['dt_s'])} ({why})",
            "value": run["simulated_per_wall_second"], "unit": REAL_TIME, **source,
            "check": f"kinetic energy {run['kinetic_energy_ratio']:.2f} x RK4's, volumes kept",
        })  # fmt: skip
    return rows


def ball_drop(data: dict) -> list[dict]:
    """The 10,242-vertex ball drop: implicit Euler at 1/60 s (the fastest valid run),
    velocity Verlet at its stable step, and Bullet's soft body on the same check; and
    implicit Euler on the 40,962-vertex ball (the real-time target's size)."""
    largest = next(s for s in data["sizes"] if s["vertex_count"] == 40962)
    size = next(s for s in data["sizes"] if s["vertex_count"] == 10242)
    source = {"source": "ball_drop.json", "date": data["date"],
              "command": "python benchmarks/ball_drop.py"}  # fmt: skip
    case = {"case": "ball drop", "vertices": 10242}
    implicit = size["integrators"]["implicit_euler cg 1e-2"]
    verlet = size["integrators"]["velocity_verlet"]
    bullet = size["bullet"]
    rebound = verlet["full_drop"]["rebound_m"]
    big = largest["integrators"]["implicit_euler cg 1e-2"]
    return [
        {"key": "ball-drop-implicit", **case, "integrator": "implicit Euler, CG 1e-2",
         "dt_s": implicit["dt_s"], "step": f"{_ms(implicit['dt_s'])} (1/60 s)",
         "value": implicit["simulated_per_wall_second"], "unit": REAL_TIME, **source,
         "check": f"rebound {implicit['full_drop']['rebound_m']:.2f} m "
                  f"(velocity Verlet's {rebound:.2f} m)"},
        {"key": "ball-drop-verlet", **case, "integrator": "velocity Verlet",
         "dt_s": verlet["dt_s"], "step": f"{_ms(verlet['dt_s'])} (0.9 x its stability estimate)",
         "value": verlet["simulated_per_wall_second"], "unit": REAL_TIME, **source,
         "check": f"rebound {rebound:.2f} m"},
        {"key": "ball-drop-bullet", **case,
         "integrator": f"Bullet soft body, {bullet['position_iterations']} iterations, "
                       f"kPR {bullet['kPR']:g}",
         "dt_s": bullet["dt_s"], "step": f"{_ms(bullet['dt_s'])} (1/60 s)",
         "value": bullet["simulated_per_wall_second"], "unit": REAL_TIME, **source,
         "check": f"rebound {bullet['full_drop']['rebound_m']:.2f} m; softbody's fastest "
                  f"valid run is {size['softbody_over_bullet']:.1f}x faster"},
        {"key": "ball-drop-40962-implicit", "case": "ball drop", "vertices": 40962,
         "integrator": "implicit Euler, CG 1e-2",
         "dt_s": big["dt_s"], "step": f"{_ms(big['dt_s'])} (1/60 s)",
         "value": big["simulated_per_wall_second"], "unit": REAL_TIME, **source,
         "check": f"rebound {big['full_drop']['rebound_m']:.2f} m (velocity Verlet's "
                  f"{rebound:.2f} m at 10,242 vertices)"},
    ]  # fmt: skip


def engine(data: dict) -> list[dict]:
    """The explicit step's throughput at 40,962 vertices (symplectic Euler), float64 and
    float32 forces on the AVX-512 path, and the scalar path."""
    row = next(r for r in data["results"]
               if r["vertices"] == 40962 and r["scheme"] == "symplectic_euler")  # fmt: skip
    source = {"source": "engine.json", "date": data["date"],
              "command": data.get("command", "python benchmarks/engine.py")}  # fmt: skip
    step = f"{_ms(data['dt'])} (fixed, below the stable step)"
    numba = row["mvps"]["numba"]
    variants = [
        ("explicit-step", "core-avx512", "symplectic Euler, AVX-512, float64"),
        ("explicit-step-f32", "core-avx512-f32", "symplectic Euler, AVX-512, float32 forces"),
        ("explicit-step-scalar", "core-scalar", "symplectic Euler, scalar path, float64"),
    ]
    return [
        {"key": key, "case": "explicit step, ball", "vertices": 40962, "integrator": what,
         "dt_s": data["dt"], "step": step, "value": row["mvps"][path],
         "unit": "M vertex-steps/s", **source,
         "check": f"{row['mvps'][path] / numba:.2f}x the previous Numba loop ({numba:.1f} M)"}
        for key, path, what in variants
    ]  # fmt: skip


def startup(data: dict) -> list[dict]:
    """Seconds from a fresh process to the first steps, the slowest of the three solver
    families (this version, a cold cache)."""
    runs = [c for c in data["compile"] if c["version"] == "this"]
    worst = max(runs, key=lambda c: c["cold"]["process_s"])
    spread = ", ".join(f"{c['integrator']} {c['cold']['process_s']:.2f} s" for c in runs)
    return [{
        "key": "startup", "case": "fresh process to the first steps", "vertices": 162,
        "integrator": worst["integrator"] + " (the slowest family)", "dt_s": None,
        "step": "3 steps", "value": worst["cold"]["process_s"], "unit": "s",
        "source": "startup.json", "date": data["date"], "command": "python benchmarks/startup.py",
        "check": spread,
    }]  # fmt: skip


def membranes(data: dict) -> list[dict]:
    """Issue 30's targets: the explicit step with a neo-Hookean skin at 40,962 vertices
    against the spring skin's in the same rounds, and implicit Euler at 1/60 s on the
    10,242-vertex membrane ball drop (CPU time of its one thread)."""
    row = next(r for r in data["explicit"] if r["vertices"] == 40962)
    source = {"source": "membranes.json", "date": data["date"],
              "command": data.get("command", "python benchmarks/membranes.py")}  # fmt: skip
    lo, hi = row["membrane_over_springs"]
    drop = data["implicit"]
    return [
        {"key": "membrane-explicit-step", "case": "explicit step, membrane ball",
         "vertices": 40962, "integrator": "symplectic Euler, neo-Hookean skin",
         "dt_s": data["dt_explicit"], "step": f"{_ms(data['dt_explicit'])} (fixed)",
         "value": row["mvps"]["membrane"], "unit": "M vertex-steps/s", **source,
         "check": f"{lo:.2f}-{hi:.2f} of the spring skin's rate in the same rounds "
                  "(target >= 0.5)"},
        {"key": "membrane-implicit-drop", "case": "membrane ball drop",
         "vertices": drop["vertices"],
         "integrator": f"implicit Euler, multigrid CG {drop['tolerance']:g}",
         "dt_s": 1 / 60, "step": "1/60 s", "value": drop["realtime_factor"],
         "unit": REAL_TIME, "clock": "cpu", **source,
         "check": f"CPU seconds of its thread; {drop['cg_iterations_mean']:.1f} CG iterations "
                  f"per step, rebound {drop['rebound_m']:.2f} m"},
    ]  # fmt: skip


def _fastest_passing(softbody: dict) -> tuple[str, dict]:
    """The race's fastest softbody run that passes with the bounce kept: (name, entry)."""
    passing = [(name, e) for name, e in softbody.items() if e.get("ok")]
    return max(passing, key=lambda item: item[1]["simulated_per_wall_second"])


def _xpbd_setting(name: str, entry: dict) -> str:
    """How a race run of XPBD was set: its substeps, and its passes where relaxed."""
    if "relaxed" in name:
        return f"xpbd, {entry['xpbd_substeps']} substeps of 4 passes, the last 3 x 1.9"
    if "xpbd_substeps" in entry:
        return f"xpbd, {entry['xpbd_substeps']} substeps of one pass"
    return name.replace("_", " ")


def jolt_peer(data: dict) -> list[dict]:
    """Issue 33's targets from the race against Jolt Physics: the 40,962-vertex drop with
    the bounce kept (softbody's fastest passing run there), and at each size softbody's
    fastest passing run's rate over Jolt's (median of the paired timing rounds where the
    drops were short enough to have them, else of the best times)."""
    source = {"source": "jolt_peer.json", "date": data["date"],
              "command": "python benchmarks/jolt_peer.py"}  # fmt: skip
    workers = data["threads"]["jolt_workers"]
    rows = []
    for size in data["sizes"]:
        n = size["vertex_count"]
        name, run = _fastest_passing(size["softbody"])
        dt = run["dt_s"] / run.get("xpbd_substeps", 1)
        step = (f"{_ms(dt)} ({run['xpbd_substeps']} substeps of the 1/60 s frame)"
                if "xpbd_substeps" in run else _ms(dt))  # fmt: skip
        setting = {"integrator": _xpbd_setting(name, run), "dt_s": dt, "step": step}
        if n == 40962:
            rows.append({"key": "ball-drop-40962-xpbd", "case": "ball drop", "vertices": n,
                         **setting, "value": run["simulated_per_wall_second"],
                         "unit": REAL_TIME, **source,
                         "check": f"rebound {run['rebound_m']:.2f} m, volume "
                                  f"{run['volume_ratio_range'][0]:.2f}-"
                                  f"{run['volume_ratio_range'][1]:.2f} of its start"})
        rounds = size.get("softbody_over_jolt_rounds") or []
        rows.append({"key": f"jolt-race-{n}", "case": "ball drop against Jolt Physics",
                     "vertices": n, **setting, "value": size["softbody_over_jolt"],
                     "unit": "x Jolt's rate", **source,
                     "check": f"Jolt at {size['jolt']['iterations']} iterations on {workers} "
                              "workers, both keeping the bounce; "
                              + (f"median of {len(rounds)} paired timing rounds" if rounds
                                 else "best times (drops too long for the rounds)")
                              + " (target >= 4)"})  # fmt: skip
    return rows


def summarise(results: Path = RESULTS) -> dict:
    """The summary record from the result files in ``results``."""
    rows = [
        *five_balls(_load(results, "five_balls")),
        *ball_drop(_load(results, "ball_drop")),
        *engine(_load(results, "engine")),
        *startup(_load(results, "startup")),
        *membranes(_load(results, "membranes")),
        *jolt_peer(_load(results, "jolt_peer")),
    ]
    return {
        "benchmark": "summary",
        "machine": MACHINE,
        "command": "python benchmarks/summary.py",
        "note": "taken from the result files named in each row; nothing is measured again",
        "rows": rows,
    }


def plot(summary: dict, path: Path) -> None:
    """The real-time figures as bars of simulated seconds per wall second (log scale); rows
    timed in CPU time (``clock`` "cpu") say so in their label."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in summary["rows"] if r["unit"] == REAL_TIME][::-1]
    labels = [f"{r['case']} ({r['vertices']:,} vertices)\n{r['integrator']}, dt {_ms(r['dt_s'])}"
              + (" (softbody run's)" if r["key"] == "five-balls-scene-step" else "")
              + (" (CPU time)" if r.get("clock") == "cpu" else "")
              for r in rows]  # fmt: skip
    colours = ["C1" if r["case"] == "ball drop" else "C0" for r in rows]
    fig, ax = plt.subplots(figsize=(9.0, 0.62 * len(rows) + 1.4))
    bars = ax.barh(labels, [r["value"] for r in rows], color=colours)
    ax.bar_label(bars, labels=[f"{r['value']:.3g}x" for r in rows], padding=3, fontsize=9)
    ax.axvline(1.0, color="k", lw=1, ls="--")
    ax.text(1.05, -0.6, "real time", fontsize=8, va="bottom")
    ax.set_xscale("log")
    ax.set_xlim(0.1, 400)
    ax.set_xlabel("simulated seconds per wall second, or per CPU second where marked\n"
                  "(one thread of a 2-core AMD EPYC, Zen 4)")
    ax.tick_params(axis="y", labelsize=8)
    ax.set_title("Speed by scene, integrator and step (benchmarks/results/summary.json)",
                 fontsize=10)  # fmt: skip
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def main() -> None:
    summary = summarise()
    write_json(RESULTS / "summary.json", summary)
    plot(summary, RESULTS / "summary.png")
    for row in summary["rows"]:
        print(f"{row['key']:28s} {row['value']:9.3g} {row['unit']:18s} {row['source']}")


if __name__ == "__main__":
    main()
