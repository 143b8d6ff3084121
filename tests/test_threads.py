"""Opt-in threads: the chunk partition and the threaded force terms against the serial ones."""

from __future__ import annotations

import numba
import numpy as np
import pytest

import softbody as sb
from conftest import deformed
from softbody.diagnostics import body_volume_by
from softbody.forces.evaluate import eval_forces
from softbody.integrators.workspace import Workspace
from softbody.partition import build_partition, face_chunks, pack_partition, spring_chunks
from softbody.sim.control import control_data


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


@pytest.mark.parametrize("chunk_count", [1, 2, 3, 5])
def test_partition_gives_every_spring_and_face_one_owner(chunk_count):
    """Definition: chunk c owns the springs and faces whose every particle lies in its
    range; each spring and face appears exactly once, the rest in the crossing slot."""
    model = two_bodies()
    part = build_partition(model, chunk_count)
    start = part.particle_start
    assert start[0] == 0 and start[-1] == model.particle_count and np.all(np.diff(start) > 0)
    chunk_of = np.searchsorted(start, np.arange(model.particle_count), side="right") - 1
    m = model.data
    for ptr, rows, model_rows in (
        (part.spring_start, part.spring_indices, m.spring_indices),
        (part.tri_start, part.tri_indices, m.tri_indices),
    ):
        # the same rows as the model's, each once
        key = np.sort(rows, axis=1).tolist()
        assert sorted(map(tuple, key)) == sorted(map(tuple, np.sort(model_rows, axis=1)))
        for c in range(chunk_count + 1):
            owners = chunk_of[rows[ptr[c] : ptr[c + 1]]]
            if c < chunk_count:
                assert np.all(owners == c)
            else:
                assert np.all(owners.min(axis=1) != owners.max(axis=1))
    # the parameters travel with their springs
    order = {tuple(r): s for s, r in enumerate(m.spring_indices.tolist())}
    s = np.array([order[tuple(r)] for r in part.spring_indices.tolist()])
    assert np.array_equal(part.spring_rest_length, m.spring_rest_length[s])
    assert np.array_equal(part.spring_stiffness, m.spring_stiffness[s])
    assert np.array_equal(part.spring_damping, m.spring_damping[s])
    # one chunk: everything in it, nothing crossing, and nothing packed for the kernels
    if chunk_count == 1:
        assert part.spring_start.tolist() == [0, model.spring_count, model.spring_count]
        assert part.tri_start.tolist() == [0, model.tri_count, model.tri_count]
        index, value = pack_partition(part)
        assert index.tolist() == [1] and value.shape == (0,)


@pytest.mark.parametrize("chunk_count", [2, 3])
def test_packed_partition_views_are_the_partition(chunk_count):
    """The kernels' views of the two packed arrays are exactly the partition's arrays."""
    model = two_bodies()
    part = build_partition(model, chunk_count)
    index, value = pack_partition(part)
    s, f, b = model.spring_count, model.tri_count, model.body_count
    springs = spring_chunks(index, value, s)
    faces = face_chunks(index, value, s, f, b)
    expected_springs = (
        part.spring_start,
        part.spring_indices,
        part.spring_rest_length,
        part.spring_stiffness,
        part.spring_damping,
    )
    expected_faces = (
        part.particle_start,
        part.tri_start,
        part.tri_indices,
        part.tri_body,
        part.six_volume,
    )
    for got, want in zip(springs + faces, expected_springs + expected_faces, strict=True):
        assert got.shape == want.shape and np.array_equal(got, want)


@pytest.mark.parametrize("chunk_count", [2, 3, 5])
def test_threaded_forces_equal_serial_forces(chunk_count):
    """The same sums in another order: forces, volumes and dV/dx agree with the serial
    kernels to round-off (a few ulps of the largest term), on two bodies of which one
    uses the paper's bounding ellipsoid."""
    model = two_bodies()
    state = deformed(model, seed=3, amplitude=0.03)
    state.particle_qd[:] = np.random.default_rng(4).normal(0.0, 0.5, state.particle_qd.shape)
    c = control_data(model)
    out = []
    for chunks in (1, chunk_count):
        w = Workspace.for_model(model, chunk_count=chunks)
        f = np.zeros((model.particle_count, 3))
        eval_forces(model.data, c, 0.0, state.particle_q, state.particle_qd, w, f)
        out.append((f, w.body_volume.copy(), w.volume_gradient.copy()))
    (f1, v1, g1), (f2, v2, g2) = out
    assert np.allclose(f2, f1, rtol=0, atol=1e-12 * np.abs(f1).max())
    assert np.allclose(v2, v1, rtol=1e-13, atol=0)
    assert np.allclose(g2, g1, rtol=0, atol=1e-13 * np.abs(g1).max())
    # the bounding ellipsoid replaced the exact volume of body 1 in both
    exact = body_volume_by(model, state, "exact")
    assert abs(v2[0] - exact[0]) < 1e-12 and abs(v2[1] - exact[1]) > 1e-4


def drop(threads: int, steps: int, integrator: str = "symplectic_euler", dt=2e-4) -> sb.State:
    model = two_bodies()
    sim = sb.Simulator(model, integrator=integrator, dt=dt, threads=threads)
    state = model.state()
    sim.run(state, steps)
    return state


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two threads")
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


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two threads")
@pytest.mark.parametrize(("integrator", "dt"), [("midpoint", 2e-4), ("implicit_euler", 1 / 60)])
def test_threaded_forces_serve_every_integrator(integrator, dt):
    """Midpoint (two force evaluations per step) and implicit Euler (forces, then a CG
    solve at tolerance 1e-6) on two threads follow the serial run through the fall and
    the ground contact: 1 s of simulated time, agreement to 1e-8 m. Round-off alone
    made 4e-15 m here; the margin covers a CG solve that stops one iteration apart on
    some step (its error is ~1e-6 of dv ~ g dt, times dt: ~3e-9 m)."""
    steps = round(1.0 / dt)
    serial, threaded = drop(1, steps, integrator, dt), drop(2, steps, integrator, dt)
    # the balls hit the ground: it took an impulse of several N s (1.5 kg at ~3 m/s)
    assert abs(serial.collider_impulse[0, 1]) > 1.0
    assert np.abs(threaded.particle_q - serial.particle_q).max() < 1e-8


@pytest.mark.parametrize("threads", [0, -1, 1.5, True, "2", 10**6])
def test_bad_thread_counts_are_refused(threads):
    """threads must be an integer from 1 to NUMBA_NUM_THREADS."""
    with pytest.raises(ValueError, match="threads must be an integer from 1 to"):
        sb.Simulator(two_bodies(), integrator="midpoint", dt=1e-4, threads=threads)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two threads")
@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4"])
def test_core_threads_repeat_exactly_and_match_serial(integrator):
    """The compiled core's force pass on two threads: each thread takes a fixed run of
    particle groups and keeps its own volume sums, added in thread order. Reference: the
    serial run, to round-off (the sums are grouped differently: 1e-12 m per step at most
    at this scale), and the same two-thread run again, to the bit."""
    model = two_bodies()
    runs = []
    for threads in (1, 2, 2):
        sim = sb.Simulator(model, integrator=integrator, dt=1e-4, threads=threads)
        assert sim._core is not None and sim._core.threads == threads
        state = model.state()
        sim.run(state, 300)
        runs.append(state)
    serial, first, second = runs
    np.testing.assert_array_equal(first.particle_q, second.particle_q)
    np.testing.assert_array_equal(first.particle_qd, second.particle_qd)
    np.testing.assert_allclose(first.particle_q, serial.particle_q, rtol=0, atol=300 * 1e-12)
