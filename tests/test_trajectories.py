"""The engine against its reference trajectories: every built-in scene (but the drag
scene, newer than the reference), a model with every term, and surface contacts, each
with all eight integrators, 200 steps (tests/trajectory_cases.py).

Reference: tests/data/trajectories/, recorded by the Numba time loop before the port to
the C++ core (tools/record_trajectories.py), the engine the physics tests validated
against closed forms. The core computes each term with the same operations but sums them
per particle (vertex-major) instead of per spring and face, so the forces differ in their
last bits (1e-16 relative) and the difference grows over the run; 1e-10 relative to the
motion's scale (the largest |x| or |v|, at least 1) over 200 steps leaves that growth a
factor of 1e4 and fails on any change of the physics. A run that blew up must blow up at
the same step with the same message.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import softbody as sb
from trajectory_cases import CASES, STEPS, build_case

DATA = Path(__file__).parent / "data" / "trajectories"
RELATIVE = 1e-10


def _replay(name: str, integrator: str, threads: int = 1) -> tuple[sb.State, str]:
    model, control, dt = build_case(name, integrator)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator=integrator, dt=dt, threads=threads)
    state = model.state()
    try:
        sim.run(state, STEPS, control)
    except sb.SimulationError as e:
        return state, str(e)
    return state, ""


def _check(state: sb.State, error: str, ref) -> None:
    assert error == str(ref["error"])
    assert state.step_count == int(ref["step_count"])
    for name in ("particle_q", "particle_qd", "collider_q", "collider_rotation",
                 "collider_impulse"):  # fmt: skip
        expected = ref[name]
        scale = max(1.0, float(np.abs(expected).max(initial=0.0)))
        np.testing.assert_allclose(getattr(state, name), expected, rtol=0,
                                   atol=RELATIVE * scale, err_msg=name)  # fmt: skip


@pytest.mark.parametrize(("name", "integrator"), CASES, ids=[f"{n}-{i}" for n, i in CASES])
def test_trajectory_matches_the_reference(name, integrator):
    """Positions, velocities, collider poses and impulses after 200 steps agree with the
    recorded trajectory to 1e-10 of their scale; a blow-up at the same step."""
    state, error = _replay(name, integrator)
    _check(state, error, np.load(DATA / f"{name}--{integrator}.npz"))


@pytest.mark.parametrize("integrator", ["midpoint", "implicit_euler", "projective"])
def test_trajectory_on_two_threads_matches_the_reference(integrator):
    """The same on two threads (the force pass cut into two fixed chunks): the every-term
    model and the two balls' surface contacts."""
    for name in ("every-term", "surface-two-balls"):
        state, error = _replay(name, integrator, threads=2)
        _check(state, error, np.load(DATA / f"{name}--{integrator}.npz"))
