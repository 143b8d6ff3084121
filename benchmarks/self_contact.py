"""Self-contact's cost, and the vacuum-packed ball (issue 32).

1. The ball drop of benchmarks/ball_drop.py (an icosphere of radius 1 m, 1 kg, nRT = 300 J,
   springs 500 N/m, dropped from 1 m onto the ground) with and without
   ``set_soft_contact("surface", self_contact=True)`` (thickness 0.2 x the median edge),
   symplectic Euler at 0.9 x its stable step and implicit Euler at 1/60 s (CG tolerance
   1e-3): steps per second over the release (the first 0.1 s of the fall, while the ball,
   released with its springs at rest length, inflates and rings), over the fall after it
   (0.15 s to 0.40 s) and over the impact (0.40 s to 0.60 s: the ball meets the ground
   at 0.45 s), best of ``--rounds``, and the ratio on / off of each.
2. The vacuum-packed ball: radius 0.5 m, its gas drawn down to 2 % over 0.3 s under a
   500 Pa ambient pressure (no gravity), self-contact on, implicit Euler at 1/240 s for
   0.6 s: wall time against simulated time, the volume at the end against the start,
   and softbody.collision.crossings.edge_crossings (every edge against every triangle) at
   every 0.05 s frame. Where its time goes: at every 0.1 s frame, 4 steps from a copy of
   the state with self-contact (the run's own simulator, its pair list warm) and 4 without
   (the same ball and settings, contacts off), best of 2: the contact stage's share of a
   step is 1 - off / on, beside the CG iterations per step of each.

Writes results/self_contact.json (a whole run; ``--only drop|vacuum`` runs and prints one
part). Usage:
python benchmarks/self_contact.py [--subdivisions 5] [--vacuum-subdivisions 5] [--rounds 2]
[--only drop|vacuum]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import softbody as sb
from ball_drop import ball_drop
from results_io import RESULTS, run_record, write_json
from softbody.collision.crossings import edge_crossings
from softbody.diagnostics import body_volume
from softbody.mesh.topology import unique_edges

# the drop's phases [s]: "fall" is the release (the inflation's ringing), "late_fall" the
# fall after it
PHASES = {"fall": (0.0, 0.1), "late_fall": (0.15, 0.4), "impact": (0.4, 0.6)}


def simulator(model: sb.Model, integrator: str) -> sb.Simulator:
    if integrator == "implicit_euler":
        return sb.Simulator(model, integrator=integrator, dt=1 / 60, implicit_tolerance=1e-3)
    probe = sb.Simulator(model, integrator=integrator, dt=1e-6)
    return sb.Simulator(model, integrator=integrator, dt=0.9 * probe.stable_dt)


def rate(
    model: sb.Model, integrator: str, t0: float, t1: float, rounds: int, start: sb.State
) -> float:
    """Steps per second over simulated time [t0, t1] from `start` (the state at t0), best of
    rounds."""
    sim = simulator(model, integrator)
    best = 0.0
    for _ in range(rounds):
        state = start.copy()
        steps = max(1, round((t1 - t0) / sim.dt))
        clock = time.perf_counter()
        sim.run(state, steps)
        best = max(best, steps / (time.perf_counter() - clock))
    return best


def vacuum_ball(subdivisions: int, self_contact: bool = True) -> sb.Model:
    ambient = 500.0
    nrt = ambient * 4.0 / 3.0 * np.pi * 0.5**3
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    if self_contact:
        builder.set_soft_contact("surface", self_contact=True, restitution=0.0, friction=0.1)
    builder.add_soft_body(
        sb.icosphere(subdivisions, radius=0.5),
        mass=1.0,
        stiffness=200.0,
        damping=0.5,
        gas=sb.Gas.isothermal(
            nrt, ambient_pressure=ambient, schedule=[(0.0, nrt), (0.3, 0.02 * nrt)]
        ),
    )
    return builder.finalize()


def step_time(sim: sb.Simulator, state: sb.State, steps: int = 4) -> tuple[float, float]:
    """Seconds per step over `steps` steps from copies of `state` (best of 2), and the
    mean CG iterations per step."""
    best, iterations = np.inf, 0.0
    for _ in range(2):
        copy = state.copy()
        start = time.perf_counter()
        try:
            sim.run(copy, steps)
        except sb.SimulationError:  # without contacts a folded ball may cross and invert
            return np.nan, np.nan
        best = min(best, (time.perf_counter() - start) / steps)
        iterations = sim.solver_iterations[0]
    return best, iterations


def vacuum(subdivisions: int) -> dict:
    model = vacuum_ball(subdivisions)
    sim = sb.Simulator(model, integrator="implicit_euler", dt=1 / 240)
    plain = sb.Simulator(vacuum_ball(subdivisions, self_contact=False),
                         integrator="implicit_euler", dt=1 / 240)  # fmt: skip
    state = model.state()
    edges = unique_edges(model.tri_indices)
    v0 = body_volume(model, state)[0]
    wall, crossings, frames, split = 0.0, 0, 0, []
    for frame in range(12):
        start = time.perf_counter()
        sim.run(state, 12)
        wall += time.perf_counter() - start
        crossings += len(edge_crossings(state.particle_q, model.tri_indices, edges))
        frames += 1
        if frame % 2 == 1:  # where the time goes, every 0.1 s
            on, cg_on = step_time(sim, state)
            off, cg_off = step_time(plain, state)
            split.append({"t": state.time, "ms_per_step_on": 1e3 * on,
                          "ms_per_step_off": 1e3 * off, "stage_share": 1.0 - off / on,
                          "cg_iterations_on": cg_on, "cg_iterations_off": cg_off})  # fmt: skip
            print(split[-1], flush=True)
    return {
        "vertices": model.particle_count,
        "simulated_s": state.time,
        "wall_s": wall,
        "x_real_time": state.time / wall,
        "volume_ratio_end": float(body_volume(model, state)[0] / v0),
        "frames_checked": frames,
        "crossings": crossings,
        "split": split,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subdivisions", type=int, default=5)
    parser.add_argument("--vacuum-subdivisions", type=int, default=5)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--only", choices=("drop", "vacuum"), default=None,
                        help="run one part and print it (results/self_contact.json is "
                        "written only by a whole run)")  # fmt: skip
    args = parser.parse_args()
    if args.only == "vacuum":
        print(vacuum(args.vacuum_subdivisions), flush=True)
        return
    rows = []
    for integrator in ("symplectic_euler", "implicit_euler"):
        for phase, (t0, t1) in PHASES.items():
            # the same start for both: the drop without self-contact up to t0
            plain = ball_drop(args.subdivisions)
            start = plain.state()
            first = simulator(plain, integrator)
            first.run(start, round(t0 / first.dt))
            off = rate(plain, integrator, t0, t1, args.rounds, start)
            touching = ball_drop(args.subdivisions, self_contact=True)
            on = rate(touching, integrator, t0, t1, args.rounds, start)
            row = {"integrator": integrator, "phase": phase, "steps_per_s_off": off,
                   "steps_per_s_on": on, "ratio": on / off}  # fmt: skip
            print(row, flush=True)
            rows.append(row)
    if args.only == "drop":
        return
    vac = vacuum(args.vacuum_subdivisions)
    print(vac, flush=True)
    model = ball_drop(args.subdivisions)
    write_json(
        RESULTS / "self_contact.json",
        run_record("self_contact", vertices=model.particle_count, drop=rows, vacuum=vac),
    )


if __name__ == "__main__":
    main()
