"""How much energy each integrator keeps: an undamped, weightless ball vibrating about its
inflated equilibrium, total energy over 2 s, explicit schemes at their estimated stable
step, backward Euler at that step and at 1/240 and 1/60 s, BDF2 at 1/240 and 1/60 s.
The implicit schemes are stable at any step but damp vibration (more at larger steps,
backward Euler far more than BDF2 in the slow modes); this plot shows by how much.

Writes results/implicit_energy.{json,png}. Usage: python benchmarks/implicit_energy.py
"""

from __future__ import annotations

import time
import warnings

import numpy as np

import softbody as sb
from results_io import RESULTS, run_record, save_figure, write_json


def vibrating_ball(damping: float) -> sb.Model:
    builder = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    builder.add_soft_body(
        sb.icosphere(2), mass=1.0, stiffness=500.0, damping=damping, gas=sb.Gas.isothermal(300.0)
    )
    return builder.finalize()


def main() -> None:
    # start from the equilibrium (settled with damping), then kick every vertex
    settled = vibrating_ball(1.0)
    state0 = settled.state()
    sb.Simulator(settled, integrator="rk4", dt=5e-4).run(state0, 8000)
    model = vibrating_ball(0.0)
    rng = np.random.default_rng(0)
    kick = rng.normal(scale=0.3, size=state0.particle_qd.shape)
    kick -= kick.mean(axis=0)
    explicit_dt = 0.9 * sb.Simulator(model, integrator="symplectic_euler", dt=1e-4).stable_dt
    runs = [
        ("symplectic_euler", explicit_dt),
        ("velocity_verlet", explicit_dt),
        ("rk4", explicit_dt),
        ("implicit_euler", explicit_dt),
        ("implicit_euler", 1 / 240),
        ("implicit_euler", 1 / 60),
        ("bdf2", 1 / 240),
        ("bdf2", 1 / 60),
    ]
    out = []
    for integrator, dt in runs:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sb.StabilityWarning)
            sim = sb.Simulator(model, integrator=integrator, dt=dt)
        state = sb.State(state0.particle_q.copy(), kick.copy())
        e0 = sb.energies(model, state).total
        steps = max(1, round(0.02 / dt))
        times, energy = [0.0], [0.0]
        t0 = time.perf_counter()
        while state.time < 2.0 - 1e-9:
            sim.run(state, steps)
            times.append(state.time)
            energy.append(sb.energies(model, state).total - e0)
        wall = time.perf_counter() - t0
        kinetic0 = sb.energies(model, sb.State(state0.particle_q, kick)).kinetic
        out.append(
            {
                "integrator": integrator,
                "dt_s": dt,
                "wall_s": wall,
                "time_s": times,
                "energy_change_J": energy,
                "final_fraction_of_kick_energy_lost": -energy[-1] / kinetic0,
            }
        )
        print(
            f"{integrator:17s} dt = {dt:.2e} s: energy change after 2 s = {energy[-1]:+.3g} J "
            f"({-100 * energy[-1] / kinetic0:.1f}% of the {kinetic0:.3g} J kick lost)",
            flush=True,
        )
    write_json(
        RESULTS / "implicit_energy.json",
        run_record("implicit_energy", kick_energy_J=float(kinetic0), runs=out),
    )

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 5), dpi=110)
    for k, run in enumerate(out):
        ax.plot(
            run["time_s"],
            np.array(run["energy_change_J"]) / kinetic0,
            color=f"C{k}",
            label=f"{run['integrator']}, dt = {run['dt_s'] * 1e3:.3g} ms",
        )
    ax.set_xlabel("time [s]")
    ax.set_ylabel("(E(t) - E(0)) / kick energy")
    ax.set_title("Energy of an undamped vibrating ball (162 vertices)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, RESULTS / "implicit_energy.png")
    print(f"wrote {RESULTS / 'implicit_energy.json'} and .png")


if __name__ == "__main__":
    main()
