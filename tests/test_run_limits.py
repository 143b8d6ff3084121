"""What a run accepts at the boundary of the compiled loop: step counts within its
integers, state arrays of any layout (converted), and states of the right size only."""

from __future__ import annotations

import numpy as np
import pytest

import softbody as sb
from softbody.sim.simulator import MAX_STEPS


def small_ball(gravity=(0.0, 0.0, 0.0)) -> sb.Model:
    """A 42-vertex ball with damped springs and gas."""
    builder = sb.ModelBuilder(gravity=gravity)
    builder.add_soft_body(sb.icosphere(1), mass=1.0, stiffness=300.0, damping=1.0, gas=100.0)
    return builder.finalize()


def test_odd_state_arrays_are_conformed_at_the_boundary():
    """A state whose arrays a user set to read-only, float32 or strided arrays is
    converted at the boundary (``State.conform``) to writable, C-contiguous float64, and
    the run gives the same positions as from ordinary arrays, to float32's rounding of
    the start (1e-6 m here)."""
    model = small_ball(gravity=(0.0, -9.81, 0.0))
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-4)
    reference = model.state()
    sim.run(reference, 20)

    odd = model.state()
    readonly = odd.particle_q.copy()
    readonly.setflags(write=False)
    odd.particle_q = readonly
    odd.particle_qd = np.zeros((model.particle_count, 6))[:, ::2]  # strided
    sim.run(odd, 10)
    odd.particle_q = odd.particle_q.astype(np.float32)
    sim.run(odd, 10)
    assert odd.particle_q.dtype == np.float64 and odd.particle_q.flags.writeable
    assert np.allclose(odd.particle_q, reference.particle_q, rtol=0, atol=1e-6)


@pytest.mark.parametrize("steps", [2**63, 10**20, MAX_STEPS + 1, -1, 1.5, float("nan"), True])
def test_step_counts_outside_the_loops_integers_are_refused(steps):
    """``run(state, 2**63)`` once returned at once with t = 9.2e15 s: counts must be
    integers in [0, MAX_STEPS] (a 64-bit signed integer in the loop), refused with a
    ValueError otherwise, before any step."""
    model = small_ball()
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-4)
    state = model.state()
    with pytest.raises(ValueError, match="steps"):
        sim.run(state, steps)
    assert state.time == 0.0 and state.step_count == 0


def test_advancing_past_the_step_limit_is_a_value_error():
    """``advance(1e20)`` once raised an internal typing error (1e23 steps do not fit the
    loop's integer): the number of substeps is checked first, and the error names the
    limit."""
    model = small_ball()
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-3)
    state = model.state()
    with pytest.raises(ValueError, match="over the limit"):
        sim.advance(state, 1e20)
    assert state.time == 0.0
    sim.advance(state, 0.01)  # a sane duration still runs: 10 steps of 1 ms
    assert state.step_count == 10 and state.time == pytest.approx(0.01, rel=1e-12)


def test_state_of_the_wrong_size_is_refused_by_name():
    """A state made for another model is refused naming the array, before any kernel
    reads past its end."""
    model = small_ball()
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-4)
    state = model.state()
    state.particle_qd = np.zeros((3, 3))
    with pytest.raises(ValueError, match="particle_qd"):
        sim.run(state, 1)
    with pytest.raises(ValueError, match="particle_qd"):
        sb.energies(model, state)
