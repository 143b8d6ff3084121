"""Record reference trajectories: every built-in scene and a model with every term, each
run 200 steps with each of the eight integrators, saved as one compressed .npz per case
under tests/data/trajectories/ (the final positions, velocities, collider poses and
impulses, the step count, and the blow-up message when a run stops).

tests/test_trajectories.py runs the same cases and compares. The committed files were
recorded by the Numba time loop of the engine before its port to the C++ core (this
script's first version, with ``--engine numba``, at commit 91e398b), so the test holds
the core to the engine the physics tests validated; rerun it to record the current
engine only when a change of the physics is intended, and say so in the commit.

    python tools/record_trajectories.py [--out DIR]
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the cases live with the test that replays them

import softbody as sb  # noqa: E402
from trajectory_cases import CASES, STEPS, build_case  # noqa: E402


def record(name: str, integrator: str) -> dict:
    model, control, dt = build_case(name, integrator)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    out: dict = {"dt": np.array(dt)}
    error = ""
    try:
        sim.run(state, STEPS, control)
    except sb.SimulationError as e:
        error = str(e)
    out["error"] = np.array(error)
    out["step_count"] = np.array(state.step_count)
    out["particle_q"] = state.particle_q.copy()
    out["particle_qd"] = state.particle_qd.copy()
    out["collider_q"] = state.collider_q.copy()
    out["collider_rotation"] = state.collider_rotation.copy()
    out["collider_impulse"] = state.collider_impulse.copy()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "tests/data/trajectories")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for name, integrator in CASES:
        data = record(name, integrator)
        path = args.out / f"{name}--{integrator}.npz"
        np.savez_compressed(path, **data)
        print(f"{path.name}: {int(data['step_count'])} steps {str(data['error'])[:60]}")


if __name__ == "__main__":
    main()
