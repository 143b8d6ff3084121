"""The float32 force pass (``force_precision="float32"``) against float64: speed and drift.

Speed: symplectic Euler steps per second on the ball drop's ball (``ball_drop``) at
2,562, 10,242 and 40,962 vertices, float64 and float32 in this process, alternating,
best of ``ROUNDS``, at each instruction set this CPU has.

Drift: each case runs three ways: float64; float32; and float64 from a start state whose
positions are moved by up to 2^-24 of the body's size (uniform, fixed seed), the rounding
float32 applies to every row. Chaotic scenes part from any such rounding: the third run
says how fast, so float32's drift is judged against it, not against zero.
- the ball drop (2 s, symplectic Euler at 0.9 of its stable step, 2,562 and 10,242
  vertices): the centre of mass's height every 0.02 s, the rebound, the volume range;
- the paper's five balls (``bouncing-balls``, 10 s; symplectic Euler and velocity Verlet
  at 0.9 of their stable step, midpoint at the scene's 0.5 ms): each ball's centre of mass
  every 0.1 s, the volume ranges, the mean kinetic energy (``five_balls.py``'s checks).

Writes results/float32.{json,png}. Usage: python benchmarks/float32.py
"""

from __future__ import annotations

import platform
import time
import warnings

import numpy as np

import softbody as sb
from ball_drop import ball_drop
from results_io import RESULTS, run_record, save_figure, write_json
from softbody import core
from softbody.scenes.loader import load_scene

EPS32 = 2.0**-24
ROUNDS = 3
MIN_SECONDS = 0.3
VARIANTS = ("float64", "float32", "float64, start rounded")


def simulator(model, integrator: str, dt: float | None, precision: str) -> sb.Simulator:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        if dt is None:
            dt = 0.9 * sb.Simulator(model, integrator=integrator, dt=1e-6).stable_dt
        return sb.Simulator(model, integrator=integrator, dt=dt, force_precision=precision)


def start_state(model, variant: str) -> sb.State:
    """The model's start, with every position moved by up to EPS32 of its body's size for
    the third variant."""
    state = model.state()
    if variant == VARIANTS[2]:
        rng = np.random.default_rng(0)
        for b in range(model.body_count):
            p0, p1 = model.body_particle_range[b]
            q = state.particle_q[p0:p1]
            size = np.abs(q - q[0]).max()
            q += rng.uniform(-1.0, 1.0, q.shape) * EPS32 * size
    return state


def rate(model, sim) -> float:
    state = model.state()
    sim.run(state, 2)
    steps, elapsed = 4, 0.0
    while elapsed < MIN_SECONDS:
        steps *= 2
        state = model.state()
        t0 = time.perf_counter()
        sim.run(state, steps)
        elapsed = time.perf_counter() - t0
    return model.particle_count * steps / elapsed / 1e6


def speed() -> list[dict]:
    rows = []
    for subdivisions in (4, 5, 6):
        model = ball_drop(subdivisions)
        sims = {p: simulator(model, "symplectic_euler", 1e-5, p) for p in ("float64", "float32")}
        for simd in core.simd_paths():
            core.use_simd(simd)
            best = {p: 0.0 for p in sims}
            ratios = []
            for _ in range(ROUNDS):
                r = {p: rate(model, sim) for p, sim in sims.items()}
                ratios.append(r["float32"] / r["float64"])
                best = {p: max(best[p], r[p]) for p in sims}
            rows.append({"vertices": model.particle_count, "simd": simd, "mvps": best,
                         "float32_over_float64": [min(ratios), max(ratios)]})  # fmt: skip
            print(f"{model.particle_count:6d} {simd:7s} float64 {best['float64']:6.1f} "
                  f"float32 {best['float32']:6.1f} M vertex-steps/s, "
                  f"x{min(ratios):.2f}-{max(ratios):.2f}", flush=True)  # fmt: skip
        core.use_simd("auto")
    return rows


def trace(model, sim, state, duration: float, sample: float):
    """Centres of mass (samples, B, 3) every `sample` s, volume ratios (samples, B), kinetic
    energy (samples,), and the wall time."""
    per = max(1, round(sample / sim.dt))
    com, ratio, kinetic = [], [], []
    wall = 0.0
    while state.time < duration - 1e-9:
        t0 = time.perf_counter()
        sim.run(state, per)
        wall += time.perf_counter() - t0
        com.append(sb.body_center_of_mass(model, state))
        ratio.append(sb.body_volume(model, state) / model.body_rest_volume)
        kinetic.append(sb.energies(model, state).kinetic)
    return np.array(com), np.array(ratio), np.array(kinetic), wall


def drift_case(name, model, integrator, dt, duration, sample) -> dict:
    runs = {}
    for variant in VARIANTS:
        precision = "float32" if variant == "float32" else "float64"
        sim = simulator(model, integrator, dt, precision)
        com, ratio, kinetic, wall = trace(model, sim, start_state(model, variant),
                                          duration, sample)  # fmt: skip
        runs[variant] = {"com": com, "ratio": ratio, "kinetic": kinetic, "wall": wall,
                         "dt": sim.dt}  # fmt: skip
    base = runs["float64"]["com"]
    out = {"case": name, "integrator": integrator, "dt_s": runs["float64"]["dt"],
           "duration_s": duration, "sample_s": sample, "variants": {}}  # fmt: skip
    for variant, r in runs.items():
        gap = np.linalg.norm(r["com"] - base, axis=2).max(axis=1)  # (samples,)
        heights = r["com"][:, 0, 1]
        bottom = int(np.argmin(heights))
        out["variants"][variant] = {
            "com_gap_m": gap.tolist(),
            "largest_com_gap_m": float(gap.max()),
            "volume_ratio_range": [float(r["ratio"].min()), float(r["ratio"].max())],
            "mean_kinetic_energy_j": float(r["kinetic"].mean()),
            "rebound_m": float(heights[bottom:].max() - heights[bottom]),
            "wall_s": r["wall"],
        }
    f32, rounded = out["variants"]["float32"], out["variants"][VARIANTS[2]]
    print(f"{name:22s} {integrator:17s} largest centre-of-mass gap: float32 "
          f"{f32['largest_com_gap_m']:.2e} m, rounded start {rounded['largest_com_gap_m']:.2e} m;"
          f" rebound {out['variants']['float64']['rebound_m']:.4f} / {f32['rebound_m']:.4f} m",
          flush=True)  # fmt: skip
    return out


def drift() -> list[dict]:
    cases = []
    for subdivisions in (4, 5):
        model = ball_drop(subdivisions)
        cases.append(drift_case(f"ball drop {model.particle_count}", model,
                                "symplectic_euler", None, 2.0, 0.02))  # fmt: skip
    five = load_scene("bouncing-balls")
    for integrator, dt in (("symplectic_euler", None), ("velocity_verlet", None),
                           ("midpoint", five.dt)):  # fmt: skip
        cases.append(drift_case("five balls", five.model, integrator, dt, 10.0, 0.1))
    return cases


def plot(cases: list[dict], speeds: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    ax = axes[0]
    for case, colour in zip(cases, plt.cm.tab10.colors, strict=False):
        label = f"{case['case']}, {case['integrator']}"
        t = case["sample_s"] * np.arange(1, len(case["variants"]["float32"]["com_gap_m"]) + 1)
        ax.semilogy(t, np.maximum(case["variants"]["float32"]["com_gap_m"], 1e-17),
                    color=colour, label=label)  # fmt: skip
        ax.semilogy(t, np.maximum(case["variants"][VARIANTS[2]]["com_gap_m"], 1e-17),
                    color=colour, linestyle=":")  # fmt: skip
    ax.set_xlabel("simulated time [s]")
    ax.set_ylabel("largest centre-of-mass gap to float64 [m]")
    ax.set_title("float32 (solid) against a float64 start rounded to float32 (dotted)")
    ax.legend(fontsize=7)
    ax = axes[1]
    simds = sorted({r["simd"] for r in speeds}, key=["scalar", "avx2", "avx512"].index)
    width = 0.8 / (2 * len(simds))
    sizes = sorted({r["vertices"] for r in speeds})
    for k, simd in enumerate(simds):
        for j, precision in enumerate(("float64", "float32")):
            values = [next(r["mvps"][precision] for r in speeds
                           if r["vertices"] == v and r["simd"] == simd) for v in sizes]  # fmt: skip
            ax.bar(np.arange(len(sizes)) + (2 * k + j - len(simds) + 0.5) * width, values,
                   width, label=f"{simd} {precision}", hatch="" if j == 0 else "//")  # fmt: skip
    ax.set_xticks(np.arange(len(sizes)), [f"{v:,}" for v in sizes])
    ax.set_xlabel("vertices")
    ax.set_ylabel("million vertex-steps per second (one thread)")
    ax.set_title("symplectic Euler, ball drop")
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, RESULTS / "float32.png")


def main() -> None:
    speeds = speed()
    cases = drift()
    write_json(
        RESULTS / "float32.json",
        run_record(
            "float32",
            machine=f"{platform.machine()}, {platform.processor() or 'cpu'}",
            command="python benchmarks/float32.py",
            units="mvps: million vertex-steps per second, one thread; gaps in m",
            speed=speeds,
            drift=cases,
        ),
    )
    plot(cases, speeds)


if __name__ == "__main__":
    main()
