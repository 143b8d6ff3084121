"""What a large step costs in bounce: the ball-drop case's rebound against the step.

The implicit schemes are stable at any step but damp: at 1/60 s the ball drop of
``ball_drop.py`` rebounds about 0.6 m under them and about 1.1 m under the explicit
schemes at their small stable steps. This benchmark measures how the rebound converges
as the implicit step shrinks (1/60 to 1/960 s), for backward Euler and BDF2 (CG tolerance
1e-3, as in ``ball_drop.py``), against velocity Verlet at 0.9 of its stable step, and
what each step costs in simulated seconds per wall second, on the 642-, 2,562- and
10,242-vertex balls: the trade between speed and a believable bounce. Every run is the
full 2 s drop checked by ``ball_drop.check_drop`` (rebound: the centre of mass's rise
after its lowest point).

Writes results/implicit_rebound.{json,png}. Usage: python benchmarks/implicit_rebound.py
"""

from __future__ import annotations

import warnings

import numpy as np

import softbody as sb
from ball_drop import IMPLICIT_TOLERANCE, ball_drop, check_drop
from results_io import RESULTS, run_record, save_figure, write_json

SUBDIVISIONS = (3, 4, 5)
STEPS_PER_SECOND = (60, 120, 240, 480, 960)
IMPLICIT = ("implicit_euler", "bdf2")


def drop(model: sb.Model, integrator: str, dt: float) -> dict:
    """The checked 2 s drop of one scheme at one step (each from the model's start)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(
            model, integrator=integrator, dt=dt, implicit_tolerance=IMPLICIT_TOLERANCE
        )
    sim.run(model.state(), 2)  # compile and load before timing
    result = check_drop(model, sim)
    return {"integrator": integrator, "dt_s": dt, **result}


def main() -> None:
    sizes = []
    for sub in SUBDIVISIONS:
        model = ball_drop(sub)
        vertices = model.particle_count
        stable = sb.Simulator(model, integrator="velocity_verlet", dt=1e-6).stable_dt
        reference = drop(model, "velocity_verlet", 0.9 * stable)
        print(
            f"{vertices} vertices: velocity_verlet dt = {reference['dt_s']:.2e} s "
            f"rebound {reference['rebound_m']:.3f} m "
            f"({reference['simulated_per_wall_second']:.2f} simulated s per s)",
            flush=True,
        )
        runs = []
        for integrator in IMPLICIT:
            for per_second in STEPS_PER_SECOND:
                run = drop(model, integrator, 1.0 / per_second)
                runs.append(run)
                print(
                    f"  {integrator:15s} dt = 1/{per_second} s: rebound "
                    f"{run['rebound_m']:.3f} m, {run['simulated_per_wall_second']:.2f} "
                    f"simulated s per s, ok {run['ok']}",
                    flush=True,
                )
        sizes.append({"vertex_count": vertices, "reference": reference, "runs": runs})
    write_json(
        RESULTS / "implicit_rebound.json",
        run_record(
            "implicit_rebound",
            threads=1,
            dtype="float64",
            implicit_tolerance=IMPLICIT_TOLERANCE,
            sizes=sizes,
        ),
    )

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_r, ax_s) = plt.subplots(1, 2, figsize=(11, 4.5), dpi=110)
    for k, size in enumerate(sizes):
        label = f"{size['vertex_count']:,} vertices"
        ref = size["reference"]
        for name, style in zip(IMPLICIT, ("-o", "--s"), strict=True):
            runs = [r for r in size["runs"] if r["integrator"] == name]
            dts = np.array([r["dt_s"] for r in runs])
            ax_r.plot(
                dts, [r["rebound_m"] for r in runs], style, color=f"C{k}", label=f"{name}, {label}"
            )
            ax_s.plot(
                dts,
                [r["simulated_per_wall_second"] for r in runs],
                style,
                color=f"C{k}",
                label=f"{name}, {label}",
            )
        ax_r.axhline(
            ref["rebound_m"],
            color=f"C{k}",
            lw=0.8,
            ls=":",
            label=f"velocity Verlet, {label}, dt = {ref['dt_s'] * 1e3:.2g} ms",
        )
        ax_s.axhline(ref["simulated_per_wall_second"], color=f"C{k}", lw=0.8, ls=":")
    ax_s.axhline(1.0, color="k", lw=0.8)
    for ax in (ax_r, ax_s):
        ax.set_xscale("log")
        ax.set_xlabel("step dt [s]")
        ax.grid(alpha=0.3, which="both")
    ax_r.set_ylabel("rebound of the centre of mass [m]")
    ax_r.set_title("Bounce after a 1 m drop (dotted: explicit reference)")
    ax_s.set_yscale("log")
    ax_s.set_ylabel("simulated seconds per wall second")
    ax_s.set_title("Speed (dotted: explicit reference; black: real time)")
    ax_r.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, RESULTS / "implicit_rebound.png")
    print(f"wrote {RESULTS / 'implicit_rebound.json'} and .png")


if __name__ == "__main__":
    main()
