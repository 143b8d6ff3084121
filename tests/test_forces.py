"""Forces: pressure and spring forces against energy gradients, conservation laws."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import softbody as sb
from conftest import ball_model, deformed, forces

EPS = np.finfo(float).eps


@settings(max_examples=30)
@given(
    seed=st.integers(0, 2**31 - 1),
    amplitude=st.floats(0.0, 0.3),
    method=st.sampled_from(
        ["exact", "bounding_box", "bounding_sphere", "bounding_ellipsoid", "monte_carlo"]
    ),
)
def test_pressure_force_has_zero_net_force_and_torque(seed, amplitude, method):
    """Sum_t n_t = 0 and sum_t sum_corners x x n_t = 0 on any closed surface, so pressure
    forces (P A n / 3 per corner) add to zero force and zero torque, whatever P is.
    Tolerance: summation round-off, F * eps * |f|max (and * |x|max for torque)."""
    model = ball_model(
        stiffness=0.0,
        gas=500.0,
        volume_method=method,
        center=(2.0, -1.0, 3.0),
        monte_carlo_samples=256,
    )
    state = deformed(model, seed, amplitude)
    f = forces(model, state)
    scale = model.tri_count * EPS * np.abs(f).max()
    assert np.all(np.abs(f.sum(axis=0)) <= 10 * scale)
    torque = np.cross(state.particle_q, f).sum(axis=0)
    assert np.all(np.abs(torque) <= 10 * scale * np.abs(state.particle_q).max())


@settings(max_examples=20)
@given(seed=st.integers(0, 2**31 - 1))
def test_internal_forces_cancel_total_is_weight(seed):
    """Newton's third law: springs (with damping), bending springs and pressure are internal,
    so the total force on a free body is its weight M g, for any positions and velocities."""
    g = np.array([0.3, -9.81, 1.2])
    model = ball_model(
        gravity=g, damping=2.0, bend_stiffness=50.0, bend_damping=0.5, mass_distribution="area"
    )
    state = deformed(model, seed, 0.2)
    state.particle_qd[:] = np.random.default_rng(seed + 1).normal(size=state.particle_qd.shape)
    f = forces(model, state)
    assert np.allclose(
        f.sum(axis=0),
        model.particle_mass.sum() * g,
        rtol=0,
        atol=model.spring_count * EPS * np.abs(f).max() * 10,
    )


def numeric_gradient(energy, q, h):
    """Central differences of energy(q) (N, 3): error O(h^2 E''') + O(eps E / h)."""
    grad = np.zeros_like(q)
    for i in range(q.shape[0]):
        for k in range(3):
            qp, qm = q.copy(), q.copy()
            qp[i, k] += h
            qm[i, k] -= h
            grad[i, k] = (energy(qp) - energy(qm)) / (2 * h)
    return grad


@pytest.mark.parametrize(
    "gas",
    [
        sb.Gas.isothermal(400.0),
        sb.Gas.isothermal(400.0, ambient_pressure=30.0),
        sb.Gas.adiabatic(400.0, gamma=1.4),
        sb.Gas.adiabatic(250.0, gamma=5 / 3, reference_volume=3.0, ambient_pressure=10.0),
        sb.Gas.fixed_pressure(120.0, ambient_pressure=20.0),
    ],
    ids=["isothermal", "isothermal-ambient", "adiabatic", "adiabatic-ref", "fixed"],
)
def test_pressure_force_is_minus_gradient_of_gas_energy(gas):
    """With the exact volume, F_pressure = -dE_gas/dx (e.g. E = -nRT ln V), checked by
    central differences with h = 1e-5 m: truncation h^2 |E'''| ~ 1e-10 and round-off
    eps |E| / h ~ 1e-10 relative to the force scale, so 1e-7 is a safe bound."""
    model = ball_model(subdivisions=1, stiffness=0.0, gas=gas)
    state = deformed(model, 3, 0.15)
    f = forces(model, state) - model.particle_mass[:, None] * model.gravity

    def gas_energy(q):
        return sb.energies(model, sb.State(q, state.particle_qd)).gas

    grad = numeric_gradient(gas_energy, state.particle_q, 1e-5)
    assert np.allclose(f, -grad, rtol=0, atol=1e-7 * np.abs(f).max())


def test_spring_force_is_minus_gradient_of_spring_energy():
    """Edge, bending and attachment springs (no damping): F = -d/dx sum 1/2 k (L - L0)^2."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    b = builder.add_soft_body(
        sb.icosphere(1),
        mass=1.0,
        stiffness=300.0,
        damping=0.0,
        gas=sb.Gas.fixed_pressure(0.0),
        bend_stiffness=40.0,
    )
    p = builder.body_particles(b)
    builder.add_attachment(p[0], (0.5, 2.0, 0.0), stiffness=80.0, rest_length=0.4)
    builder.add_attachment(p[5], (0.0, -1.0, 0.2), stiffness=20.0)
    model = builder.finalize()
    state = deformed(model, 11, 0.2)
    f = forces(model, state)

    def spring_energy(q):
        return sb.energies(model, sb.State(q, state.particle_qd)).spring

    grad = numeric_gradient(spring_energy, state.particle_q, 1e-5)
    assert np.allclose(f, -grad, rtol=0, atol=1e-7 * np.abs(f).max())


def test_spring_damping_force_closed_form():
    """Two particles separating at relative speed w along their line: the damping force is
    c w on each, pulling them together; sideways relative motion is not damped."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    i = builder.add_particle((0, 0, 0), mass=1.0, velocity=(-1.0, 0.5, 0.0))
    j = builder.add_particle((2, 0, 0), mass=1.0, velocity=(1.0, -0.5, 0.3))
    builder.add_spring(i, j, stiffness=0.0, damping=3.0)
    model = builder.finalize()
    f = forces(model, model.state())
    assert np.allclose(f, [[6.0, 0, 0], [-6.0, 0, 0]], atol=1e-15)


@settings(max_examples=10)
@given(seed=st.integers(0, 2**31 - 1))
def test_compiled_pressure_kernel_matches_the_papers_face_force(seed):
    """The compiled core's pressure force equals the readable NumPy version (P area n / 3
    per corner) to round-off (1e-13 relative)."""
    model = ball_model(subdivisions=2, stiffness=0.0, gas=sb.Gas.fixed_pressure(350.0))
    state = deformed(model, seed, 0.2)
    f = forces(model, state)
    # the paper's form for one body: P * area * unit normal / 3 on each corner
    q, faces = state.particle_q, model.tri_indices
    n = np.cross(q[faces[:, 1]] - q[faces[:, 0]], q[faces[:, 2]] - q[faces[:, 0]])
    ref = np.zeros_like(q)
    for k in range(3):
        np.add.at(ref, faces[:, k], 350.0 * n / 6.0)  # area * unit normal = n / 2
    assert np.allclose(f, ref, rtol=0, atol=1e-13 * np.abs(ref).max())


def test_grab_spring_force_and_equilibrium():
    """Control's grab spring on one particle: f = k (target - x) - c v exactly, and a
    particle hanging from it under gravity settles at x = target + m g / k."""
    builder = sb.ModelBuilder()
    builder.add_particle((0.0, 0.0, 0.0), mass=0.5, velocity=(0.2, 0.0, 0.0))
    model = builder.finalize()
    control = model.control()
    control.grab_particle = 0
    control.grab_target = np.array([0.0, 1.0, 0.0])
    control.grab_stiffness, control.grab_damping = 40.0, 3.0
    f = forces(model, model.state(), control)
    assert np.allclose(
        f[0],
        40.0 * np.array([0.0, 1.0, 0.0]) - 3.0 * np.array([0.2, 0, 0]) + 0.5 * model.gravity,
        atol=1e-14,
    )
    state = model.state()
    sb.Simulator(model, integrator="rk4", dt=1e-3).run(state, 20_000, control)
    assert np.allclose(state.particle_q[0], [0.0, 1.0 - 0.5 * 9.81 / 40.0, 0.0], atol=1e-9)
    control.grab_particle = 3
    with pytest.raises(ValueError, match="grab_particle must be -1 or a particle index"):
        sb.Simulator(model, dt=1e-3).step(model.state(), control)
