"""Opt-in threads: every solver's force pass on threads against the serial run, and the
same bits on every run."""

from __future__ import annotations

import numpy as np
import pytest

import softbody as sb
from softbody.core import available_threads

two_cores = pytest.mark.skipif(available_threads() < 2, reason="needs two cores")


def two_bodies() -> sb.Model:
    """Two balls (one with a bounding-ellipsoid volume, as the paper) on the ground."""
    builder = sb.ModelBuilder()
    builder.add_soft_body(
        sb.icosphere(3, radius=0.5, center=(0.0, 1.0, 0.0)),
        mass=1.0,
        stiffness=400.0,
        damping=0.5,
        gas=sb.Gas.isothermal(80.0),
    )
    builder.add_soft_body(
        sb.icosphere(2, radius=0.4, center=(1.2, 1.5, 0.0)),
        mass=0.5,
        stiffness=300.0,
        damping=0.3,
        gas=sb.Gas.isothermal(40.0),
        volume_method="bounding_ellipsoid",
    )
    builder.add_collider(sb.ColliderPlane(restitution=0.5, friction=0.1))
    return builder.finalize()


def drop(threads: int, steps: int, integrator: str = "symplectic_euler", dt=2e-4) -> sb.State:
    model = two_bodies()
    sim = sb.Simulator(model, integrator=integrator, dt=dt, threads=threads)
    state = model.state()
    sim.run(state, steps)
    return state


@two_cores
def test_threaded_run_matches_serial_and_repeats_exactly():
    """A drop with ground contact on two threads: the same trajectory as serial up to
    round-off grown over 2,000 steps, and bit for bit the same on a second run (each
    particle's sum runs in a fixed order, whatever the threads' timing)."""
    serial = drop(1, 2000)
    first, second = drop(2, 2000), drop(2, 2000)
    assert np.array_equal(first.particle_q, second.particle_q)
    assert np.array_equal(first.particle_qd, second.particle_qd)
    # the balls fell about g t^2 / 2 = 0.78 m and touched down; round-off only since
    assert serial.particle_q[:, 1].min() < 0.01
    assert np.abs(first.particle_q - serial.particle_q).max() < 1e-9


@two_cores
@pytest.mark.parametrize(
    ("integrator", "dt"),
    [("midpoint", 2e-4), ("implicit_euler", 1 / 60), ("bdf2", 1 / 60), ("projective", 1 / 240)],
)
def test_threaded_forces_serve_every_integrator(integrator, dt):
    """Midpoint (two force evaluations per step), implicit Euler and BDF2 (forces, then a
    CG solve at tolerance 1e-6) and projective dynamics (dV/dx and the volumes at each
    iterate) on two threads follow the serial run through the fall and the ground
    contact: 1 s of simulated time, agreement to 1e-8 m. Round-off alone made 4e-15 m
    here; the margin covers a CG solve that stops one iteration apart on some step (its
    error is ~1e-6 of dv ~ g dt, times dt: ~3e-9 m)."""
    steps = round(1.0 / dt)
    serial, threaded = drop(1, steps, integrator, dt), drop(2, steps, integrator, dt)
    # the balls hit the ground: it took an impulse of several N s (1.5 kg at ~3 m/s)
    assert abs(serial.collider_impulse[0, 1]) > 1.0
    assert np.abs(threaded.particle_q - serial.particle_q).max() < 1e-8


@pytest.mark.parametrize("threads", [0, -1, 1.5, True, "2", 10**6])
def test_bad_thread_counts_are_refused(threads):
    """threads must be an integer from 1 to the cores this process may use."""
    with pytest.raises(ValueError, match="threads must be an integer from 1 to"):
        sb.Simulator(two_bodies(), integrator="midpoint", dt=1e-4, threads=threads)


@two_cores
@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4", "implicit_euler", "projective"])
def test_core_threads_repeat_exactly_and_match_serial(integrator):
    """The compiled core's force pass on two threads: each thread takes a fixed run of
    particle groups and keeps its own volume sums, added in thread order. Reference: the
    serial run, to round-off (the sums are grouped differently: 1e-12 m per step at most
    at this scale), and the same two-thread run again, to the bit."""
    model = two_bodies()
    runs = []
    for threads in (1, 2, 2):
        sim = sb.Simulator(model, integrator=integrator, dt=1e-4, threads=threads)
        assert sim.solver._core.threads == threads
        state = model.state()
        sim.run(state, 300)
        runs.append(state)
    serial, first, second = runs
    np.testing.assert_array_equal(first.particle_q, second.particle_q)
    np.testing.assert_array_equal(first.particle_qd, second.particle_qd)
    np.testing.assert_allclose(first.particle_q, serial.particle_q, rtol=0, atol=300 * 1e-12)
