"""Triangle membranes (``core/terms/membrane.hpp``, :mod:`softbody.membrane`).

References: the NumPy reference (``softbody.reference.membrane``) for the force and the
energy; central differences of the core's energy for the force and of the core's force
for the Jacobian product; the closed-form balloon curve P(s) = A0 H W'(s) / (3 V0 s^2)
for a uniformly scaled closed mesh; energy conservation under velocity Verlet; the
stability estimate against the largest eigenvalue of M^-1 K.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

import softbody as sb
from softbody import _core
from softbody import reference as ref
from softbody.core import core_model
from softbody.membrane import equibiaxial_pressure
from softbody.reference import jacobians
from softbody.sim.control import control_data

EPS = np.finfo(float).eps

MATERIALS = {
    "neo_hookean": sb.Membrane.neo_hookean(2e5, 1e-3, damping=0.002),
    "mooney_rivlin": sb.Membrane.mooney_rivlin(1e5, 2.5e4, 1e-3, damping=0.002),
    "stvk": sb.Membrane.stvk(1e6, 0.3, 1e-3, damping=0.002),
}


def _balloon(membrane, *, subdivisions=2, radius=0.2, mass=0.05, gas=None, **kwargs):
    """A membrane-only icosphere balloon without gravity."""
    b = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    b.add_soft_body(sb.icosphere(subdivisions, radius=radius), mass=mass,
                    gas=gas if gas is not None else sb.Gas.fixed_pressure(0.0),
                    membrane=membrane, **kwargs)  # fmt: skip
    return b.finalize()


def _perturbed(model, scale=1.15, noise=0.01, seed=7):
    """Positions scaled about the centre by ``scale`` and moved at random by up to
    ``noise`` times the radius; velocities at random."""
    rng = np.random.default_rng(seed)
    q0 = model.particle_q
    size = np.abs(q0).max()
    q = scale * q0 + rng.uniform(-noise * size, noise * size, q0.shape)
    qd = rng.normal(0.0, 0.5, q0.shape)
    return q, qd


def _core_force(model, q, qd):
    return _core.eval_forces(core_model(model), control_data(model), 0.0, q, qd)[0]


def _core_energy(model, q):
    out = _core.eval_energies(core_model(model), control_data(model), 0.0,
                              np.ascontiguousarray(q))  # fmt: skip
    return out["membrane"][0]


@pytest.mark.parametrize("name", list(MATERIALS))
def test_core_force_and_energy_match_the_reference(name):
    """Reference: softbody.reference.membrane. The core's force (elastic and viscous) and
    energy at a randomly perturbed, stretched icosphere equal the NumPy reference's to
    round-off: 64 eps times the size of what is summed (|f| per triangle times its
    corners, A0 H times the material's parameters times the invariants for W)."""
    model = _balloon(MATERIALS[name])
    q, qd = _perturbed(model)
    got = _core_force(model, q, qd)
    want = ref.membrane.force(model, q, qd)
    scale = np.abs(want).max()
    assert np.abs(got - want).max() <= 1e-12 * scale
    e = _core_energy(model, q)
    assert e > 0
    assert e == pytest.approx(ref.membrane.energy(model, q), rel=1e-12)


@pytest.mark.parametrize("name", list(MATERIALS))
def test_force_is_minus_the_gradient_of_the_energy(name):
    """Reference: central differences. -dE/dx . p of the core's energy along random p equals
    f(q, v = 0) . p within the O(h^2) error estimated from two step sizes (the error at
    h / 2 a quarter of that at h) plus the quotient's round-off 64 eps |E| / h."""
    model = _balloon(MATERIALS[name])
    q, _ = _perturbed(model)
    f = _core_force(model, q, np.zeros_like(q))
    rng = np.random.default_rng(11)
    for _ in range(3):
        p = rng.normal(size=q.shape)

        def d(h, p=p):
            return (_core_energy(model, q + h * p) - _core_energy(model, q - h * p)) / (2 * h)

        h = 1e-5
        coarse, fine = d(h), d(h / 2)
        allowed = 2.0 * abs(coarse - fine) / 3.0 + 64.0 * EPS * _core_energy(model, q) / h
        assert abs(fine + np.sum(f * p)) <= allowed
        assert allowed < 1e-6 * np.sum(np.abs(f * p))


def _jacobian_product(model, q, p, alpha_c=0.0, alpha_k=1.0):
    data = control_data(model)
    inputs = jacobians.prepare(model, data, 0.0, q)
    out = np.zeros_like(q)
    _core.apply_jacobians(core_model(model), data, q, np.ascontiguousarray(p), 0.0, alpha_c,
                          alpha_k, out, **inputs.core_arguments())  # fmt: skip
    return out


@pytest.mark.parametrize("name", list(MATERIALS))
def test_jacobian_product_matches_finite_differences(name):
    """Reference: central differences of the core's force. At a uniformly stretched state
    (s = 1.2, where every triangle's F-Hessian is positive semi-definite, so the clamping
    changes nothing) K p equals (f(q + h p) - f(q - h p)) / 2h and C p equals the same in
    the velocities (the viscous force is linear in v: exact up to round-off), to 1e-6 of
    |K p| (the O(h^2) error at h = 1e-6 relative to the strain is far smaller)."""
    model = _balloon(MATERIALS[name])
    q = 1.2 * model.particle_q
    rng = np.random.default_rng(5)
    p = rng.normal(size=q.shape)
    h = 1e-6
    zero = np.zeros_like(q)
    kp = (_core_force(model, q + h * p, zero) - _core_force(model, q - h * p, zero)) / (2 * h)
    got = _jacobian_product(model, q, p)
    assert np.abs(got - kp).max() <= 1e-6 * np.abs(kp).max()
    cp = (_core_force(model, q, p) - _core_force(model, q, -p)) / 2.0
    got_c = _jacobian_product(model, q, p, alpha_c=1.0, alpha_k=0.0)
    assert np.abs(cp).max() > 0
    assert np.abs(got_c - cp).max() <= 1e-9 * np.abs(cp).max()


@pytest.mark.parametrize("name", list(MATERIALS))
@pytest.mark.parametrize("scale", [0.8, 1.0, 1.3])
def test_stiffness_and_damping_are_negative_semidefinite(name, scale):
    """Contract of the implicit solvers: -K and -C are positive semi-definite after the
    eigenvalue clamping, also compressed (s = 0.8, where the unclamped Hessian is
    indefinite): p . K p <= 0 and p . C p <= 0 for random p (allowing round-off of
    1e-12 of |K p| |p|). At s = 0.8 the clamping matters: the true Hessian, from finite
    differences of the force, has p . K p > 0 for some p there."""
    model = _balloon(MATERIALS[name], subdivisions=1)
    q, _ = _perturbed(model, scale=scale, noise=0.02)
    rng = np.random.default_rng(3)
    for _ in range(20):
        p = rng.normal(size=q.shape)
        kp = _jacobian_product(model, q, p)
        cp = _jacobian_product(model, q, p, alpha_c=1.0, alpha_k=0.0)
        size = np.linalg.norm(p) * (np.linalg.norm(kp) + np.linalg.norm(cp))
        assert np.sum(p * kp) <= 1e-12 * size
        assert np.sum(p * cp) <= 1e-12 * size


@pytest.mark.parametrize("name", list(MATERIALS))
def test_compressed_hessian_is_indefinite_before_the_clamping(name):
    """Reference: the dense finite-difference Hessian of the core's force. Compressed
    uniformly (s = 0.8), the membrane's true stiffness K = df/dx has positive eigenvalues
    (compressive stress: buckling modes), so the semi-definiteness of the product above
    comes from the clamping; and the clamped product's matrix agrees with the true one
    where the true one is negative semi-definite (uniform stretch s = 1.2), to 1e-6."""
    model = _balloon(MATERIALS[name], subdivisions=1)
    zero = np.zeros_like(model.particle_q)
    n3 = 3 * model.particle_count

    def dense(q):
        cols, h = [], 1e-6
        for k in range(n3):
            e = np.zeros(n3)
            e[k] = h
            e = e.reshape(-1, 3)
            cols.append(((_core_force(model, q + e, zero) - _core_force(model, q - e, zero))
                         / (2 * h)).ravel())  # fmt: skip
        k = np.stack(cols, axis=1)
        return 0.5 * (k + k.T)

    squeezed = dense(0.8 * model.particle_q)
    top = np.linalg.eigvalsh(squeezed)[-1]
    assert top > 1e-3 * np.abs(squeezed).max()
    stretched_q = 1.2 * model.particle_q
    stretched = dense(stretched_q)
    product = np.stack([_jacobian_product(model, stretched_q, e.reshape(-1, 3)).ravel()
                        for e in np.eye(n3)], axis=1)  # fmt: skip
    assert np.abs(product - stretched).max() <= 1e-6 * np.abs(stretched).max()


# -- the balloon curve -------------------------------------------------------------------
def _virtual_work_pressure(model, s):
    """The pressure the core's membrane force balances at positions s x0, along uniform
    scaling: P = -(f . x) / (dV/dx . x) (virtual work of the scaling mode)."""
    q = s * model.particle_q
    f, _, _, grad = _core.eval_forces(core_model(model), control_data(model), 0.0, q,
                                      np.zeros_like(q))  # fmt: skip
    return -np.sum(f * q) / np.sum(grad * q), f, grad


def test_equibiaxial_pressure_is_the_textbook_balloon_curve():
    """Reference: the neo-Hookean sphere P = 2 mu (H / R) (1 / s - 1 / s^7) (A0 / (3 V0)
    = 1 / R for a sphere), its peak at s = 7^(1/6); and for Mooney-Rivlin and StVK the
    derivative of their equibiaxial W(s) = W(C = s^2 I) by central differences."""
    mu, h, r = 3e5, 2e-4, 0.15
    neo = sb.Membrane.neo_hookean(mu, h)
    area, volume = 4 * np.pi * r**2, 4 / 3 * np.pi * r**3
    s = np.linspace(1.01, 4.0, 300)
    textbook = 2 * mu * h / r * (1 / s - 1 / s**7)
    np.testing.assert_allclose(equibiaxial_pressure(neo, s, area, volume), textbook, rtol=1e-13)
    fine = np.linspace(1.3, 1.45, 150001)
    peak = fine[np.argmax(equibiaxial_pressure(neo, fine, area, volume))]
    assert abs(peak - 7 ** (1 / 6)) <= 2e-6
    for m in (sb.Membrane.mooney_rivlin(1e5, 3e4, h), sb.Membrane.stvk(1e6, 0.3, h)):

        def w(x, m=m):
            return m.energy_density(np.eye(2) * (x**2)[:, None, None])

        dw = (w(s + 1e-6) - w(s - 1e-6)) / 2e-6
        np.testing.assert_allclose(equibiaxial_pressure(m, s, area, volume),
                                   area * h * dw / (3 * volume * s**2), rtol=1e-7)  # fmt: skip


@pytest.mark.parametrize("name", list(MATERIALS))
def test_uniform_scaling_balances_the_closed_form_pressure(name):
    """Reference: P(s) = A0 H W'(s) / (3 V0 s^2) with the mesh's own A0 (sum of rest
    areas) and V0 (its volume), exact for a uniformly scaled mesh, every triangle being
    stretched equibiaxially by s. Along the scaling mode the core's membrane force balances
    P(s) dV/dx to round-off (1e-12). Vertex by vertex the balance holds to the mesh's
    resolution: an icosphere's triangles differ in size (the subdivided icosahedron), so
    uniform scaling is not exactly the discrete equilibrium; the residual, 8.4-8.9% of
    the largest vertex force at 2-4 subdivisions for every material and stretch (it
    does not shrink with refinement: the area ratios persist), is held below 10%."""
    model = _balloon(MATERIALS[name], subdivisions=3)
    area, volume = model.membrane_rest_area.sum(), model.body_rest_volume[0]
    for s in (1.1, 1.3, 2.0):
        expected = float(equibiaxial_pressure(MATERIALS[name], s, area, volume))
        got, f, grad = _virtual_work_pressure(model, s)
        assert got == pytest.approx(expected, rel=1e-12)
        residual = f + expected * grad
        assert np.abs(residual).max() <= 0.10 * np.abs(f).max()


def test_mooney_rivlin_with_enough_c01_has_no_peak():
    """Reference: the Mooney-Rivlin balloon curve P(s) ~ (1 / s - 1 / s^7)(1 + (c01 /
    c10) s^2) has no maximum for c01 / c10 above about 0.21: with 0.25 the core's
    virtual-work pressure rises monotonically over s in [1.02, 6]; with 0.1 it has a
    peak (falls after it), as neo-Hookean (c01 = 0) does at 7^(1/6)."""
    s = np.linspace(1.02, 6.0, 120)

    def curve(c01):
        model = _balloon(sb.Membrane.mooney_rivlin(1e5, c01, 1e-3), subdivisions=1)
        return np.array([_virtual_work_pressure(model, x)[0] for x in s])

    assert np.all(np.diff(curve(2.5e4)) > 0)
    assert np.any(np.diff(curve(1e4)) < 0)
    neo = _balloon(sb.Membrane.neo_hookean(2e5, 1e-3), subdivisions=1)
    p = np.array([_virtual_work_pressure(neo, x)[0] for x in s])
    assert abs(s[np.argmax(p)] - 7 ** (1 / 6)) <= s[1] - s[0]


def _rising_branch(membrane, model, pressure):
    """The stretch s < 7^(1/6) at which the closed-form curve of ``model``'s mesh meets
    ``pressure``, by bisection."""
    area, volume = model.membrane_rest_area.sum(), model.body_rest_volume[0]
    lo, hi = 1.0, 7 ** (1 / 6)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        below = equibiaxial_pressure(membrane, mid, area, volume) < pressure
        lo, hi = (mid, hi) if below else (lo, mid)
    return 0.5 * (lo + hi)


NEO = sb.Membrane.neo_hookean(2e5, 1e-3, damping=2e-3)


def _inflated(fraction):
    """A damped neo-Hookean balloon (R = 0.2 m, 642 particles) under a fixed pressure of
    ``fraction`` of its peak pressure, and the rising-branch stretch for it."""
    rest = _balloon(NEO)
    area, volume = rest.membrane_rest_area.sum(), rest.body_rest_volume[0]
    peak = float(equibiaxial_pressure(NEO, 7 ** (1 / 6), area, volume))
    model = _balloon(NEO, gas=sb.Gas.fixed_pressure(fraction * peak))
    return model, _rising_branch(NEO, rest, fraction * peak)


@pytest.mark.parametrize(
    ("integrator", "dt"),
    [("implicit_euler", 1e-3), ("bdf2", 1e-3), ("projective", 1e-3),
     ("symplectic_euler", "auto"), ("velocity_verlet", "auto"), ("rk4", "auto"),
     ("midpoint", "auto")],
)  # fmt: skip
def test_every_solver_settles_on_the_rising_branch(integrator, dt):
    """Reference: the closed-form balloon curve. A membrane-only neo-Hookean balloon
    (damped, no springs) under a fixed pressure of 0.8 of its peak, from rest, settles in
    0.6 s at the rising-branch stretch s* (P(s*) = P, s* = 1.1514), measured as
    (V / V0)^(1/3), within 1e-3: the icosphere's uneven triangles move the discrete
    equilibrium 4e-5 off uniform scaling, and every scheme lands there (the explicit ones
    at their estimated stable step). Explicit Euler is left out: its estimate, 8e-7 s,
    needs 800,000 steps."""
    model, s_star = _inflated(0.8)
    sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    sim.run(state, round(0.6 / sim.dt))
    assert np.all(np.isfinite(state.particle_q))
    s = (sb.body_volume(model, state)[0] / model.body_rest_volume[0]) ** (1 / 3)
    assert abs(s / s_star - 1) <= 1e-3


def test_a_pressure_above_the_peak_runs_away():
    """Reference: the balloon curve's maximum. A fixed pressure 5% above the peak has no
    equilibrium: the neo-Hookean balloon inflates past s = 7^(1/6) without stopping, until
    the volume limit (1000 V0) stops the run, where at 0.8 of the peak it settled."""
    model, _ = _inflated(1.05)
    sim = sb.Simulator(model, integrator="implicit_euler", dt=1e-3)
    state = model.state()
    with pytest.raises(sb.SimulationError, match="volume"):
        sim.run(state, 5000)


# -- energy and the stable step ----------------------------------------------------------
def _oscillating(subdivisions=2):
    """An undamped neo-Hookean balloon under a fixed pressure of 0.8 of its peak, at the
    rising-branch stretch s* with every particle moved at random (seeded) by up to 1.5%
    of the radius, at rest: it breathes and wobbles about its equilibrium, its membrane in
    tension throughout (an unpressurised one would buckle as it swings into compression)."""
    membrane = sb.Membrane.neo_hookean(2e5, 1e-3)
    rest = _balloon(membrane, subdivisions=subdivisions)
    area, volume = rest.membrane_rest_area.sum(), rest.body_rest_volume[0]
    pressure = 0.8 * float(equibiaxial_pressure(membrane, 7 ** (1 / 6), area, volume))
    model = _balloon(membrane, subdivisions=subdivisions,
                     gas=sb.Gas.fixed_pressure(pressure))  # fmt: skip
    state = model.state()
    rng = np.random.default_rng(1)
    s = _rising_branch(membrane, rest, pressure)
    state.particle_q[:] = s * model.particle_q + rng.uniform(-0.003, 0.003, model.particle_q.shape)
    return model, state


def test_velocity_verlet_conserves_energy_to_second_order():
    """Reference: velocity Verlet is symplectic and second order, so the total energy
    (kinetic + membrane + the fixed-pressure gas's -P V) of an undamped run oscillates
    about its start by O(dt^2): over 0.05 s the largest drift falls fourfold (3.5-4.5) as
    dt halves, and is below 1e-3 of the membrane's energy at dt = 5e-5 s (about a tenth
    of the stable step)."""
    drift = []
    for dt in (1e-4, 5e-5):
        model, state = _oscillating()
        start = sb.energies(model, state)
        sim = sb.Simulator(model, integrator="velocity_verlet", dt=dt)
        worst = 0.0
        for _ in range(50):
            sim.run(state, round(0.05 / dt) // 50)
            worst = max(worst, abs(sb.energies(model, state).total - start.total))
        drift.append(worst / start.spring)
    assert 3.5 <= drift[0] / drift[1] <= 4.5
    assert drift[1] < 1e-3


@pytest.mark.parametrize("name", list(MATERIALS))
def test_stable_step_bound_covers_the_stiffest_membrane_mode(name):
    """Reference: the largest eigenvalue of M^-1/2 (-K) M^-1/2 from the dense central-
    difference Hessian of the core's force (a 42-particle balloon, masses by area, at rest
    and stretched by 1.2 and 1.5). The Gershgorin bound (stiffest_mode without the
    spectral part) is at least it and at most 4 times it (measured 2.9-3.2 for StVK);
    with the spectral part the bound is SPECTRAL_MARGIN (1.15) times it, to 1e-6."""
    from softbody.stability import SPECTRAL_MARGIN, stiffest_mode

    b = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    b.add_soft_body(sb.icosphere(1, radius=0.2), mass=0.05, gas=sb.Gas.fixed_pressure(0.0),
                    membrane=MATERIALS[name], mass_distribution="area")  # fmt: skip
    model = b.finalize()
    n3 = 3 * model.particle_count
    scale = np.repeat(np.sqrt(model.particle_inv_mass), 3)
    for s in (1.0, 1.2, 1.5):
        q = s * model.particle_q
        zero = np.zeros_like(q)
        cols = []
        for k in range(n3):
            e = np.zeros(n3)
            e[k] = 1e-6
            e = e.reshape(-1, 3)
            cols.append(((_core_force(model, q + e, zero) - _core_force(model, q - e, zero))
                         / 2e-6).ravel())  # fmt: skip
        k = -np.stack(cols, axis=1)
        top = np.linalg.eigvalsh(scale[:, None] * 0.5 * (k + k.T) * scale[None, :])[-1]
        gershgorin = stiffest_mode(model, q, spectral=False).omega ** 2
        assert top <= gershgorin <= 4.0 * top
        spectral = stiffest_mode(model, q).omega ** 2
        assert spectral == pytest.approx(SPECTRAL_MARGIN * top, rel=1e-6)


def test_explicit_run_is_stable_at_the_auto_step_and_blows_up_at_three_times_the_estimate():
    """Reference: the stable step's contract. Symplectic Euler on the undamped wobbling
    balloon (no springs: the membrane is the only stiffness), at the step dt="auto" takes
    (AUTO_SAFETY = 0.8 of the estimate at its positions), keeps its total energy within 2%
    of the membrane's energy over 2,000 steps; at 3 times the estimate the stiffest
    membrane mode grows until the run stops (a SimulationError) or the energy has grown
    by ten times the membrane's. (At the estimate itself this run is at the margin: the
    spectral bound is 1.15 times the stiffest mode at the start, and the incompressible
    sheet stiffens where it swings into compression; it blew up after 104 steps.)"""
    from softbody.sim.simulator import AUTO_SAFETY

    model, state = _oscillating(subdivisions=1)
    start = sb.energies(model, state)
    stable = sb.stable_dt(model, "symplectic_euler", state.particle_q)
    with warnings.catch_warnings():  # its own estimate, at the rest shape, is 3% smaller
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator="symplectic_euler", dt=AUTO_SAFETY * stable)
    sim.run(state, 2000)
    assert abs(sb.energies(model, state).total - start.total) <= 0.02 * start.spring
    model, state = _oscillating(subdivisions=1)
    with pytest.warns(sb.StabilityWarning):
        fast = sb.Simulator(model, integrator="symplectic_euler", dt=3.0 * stable)
    try:
        fast.run(state, 2000)
    except sb.SimulationError:
        return
    assert sb.energies(model, state).total - start.total > 10.0 * start.spring


# -- input -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: sb.Membrane.neo_hookean(-1.0, 1e-3), "shear_modulus must be >= 0"),
        (lambda: sb.Membrane.neo_hookean(1e5, 0.0), "thickness must be > 0"),
        (lambda: sb.Membrane.neo_hookean(1e5, -1e-3), "thickness must be > 0"),
        (lambda: sb.Membrane.neo_hookean(float("nan"), 1e-3), "shear_modulus must be finite"),
        (lambda: sb.Membrane.neo_hookean(1e5, 1e-3, damping=-1.0), "damping must be >= 0"),
        (lambda: sb.Membrane.mooney_rivlin(1e5, -2.0, 1e-3), "c01 must be >= 0"),
        (lambda: sb.Membrane.mooney_rivlin(float("inf"), 0.0, 1e-3), "c10 must be finite"),
        (lambda: sb.Membrane.stvk(-1e6, 0.3, 1e-3), "youngs_modulus must be >= 0"),
        (lambda: sb.Membrane.stvk(1e6, 0.5, 1e-3), r"poisson_ratio must lie in \(-1, 0.5\)"),
        (lambda: sb.Membrane.stvk(1e6, -1.0, 1e-3), r"poisson_ratio must lie in \(-1, 0.5\)"),
        (lambda: sb.Membrane.stvk(1e6, float("nan"), 1e-3), "poisson_ratio must lie"),
        (lambda: sb.Membrane.stvk(1e6, 0.3, "thin"), "thickness must be a number"),
    ],
)
def test_bad_material_parameters_name_the_parameter(make, message):
    """Contract: a ValueError naming the parameter and the reason."""
    with pytest.raises(ValueError, match=message):
        make()


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"mass": 0.1}, ValueError, "stiffness is required for a body without a membrane"),
        ({"membrane": NEO}, ValueError, "give the body's mass"),
        ({"membrane": NEO, "mass": 0.1, "density": 900.0}, ValueError, "not both"),
        ({"density": 900.0, "stiffness": 10.0}, ValueError, "density needs a membrane"),
        ({"membrane": NEO, "density": -1.0}, ValueError, "density must be > 0"),
        ({"membrane": "rubber", "mass": 0.1}, TypeError, "membrane must be a softbody.Membrane"),
        ({"membrane": [(NEO, [0, 80])], "mass": 0.1}, ValueError,
         r"face indices must lie in \[0, 79\]"),
        ({"membrane": [(NEO, [0.5])], "mass": 0.1}, ValueError, "integer face indices"),
        ({"membrane": [NEO], "mass": 0.1}, TypeError, r"\(Membrane, faces or None\) pair"),
        ({"membrane": NEO, "mass": 0.1, "damping": 1.0}, ValueError,
         "damping is the edge springs'"),
    ],
)  # fmt: skip
def test_bad_body_arguments_are_refused(kwargs, error, message):
    """Contract: add_soft_body refuses a body it cannot build, with the reason."""
    b = sb.ModelBuilder()
    with pytest.raises(error, match=message):
        b.add_soft_body(sb.icosphere(1), gas=sb.Gas.fixed_pressure(0.0), **kwargs)


def test_density_gives_the_mass_and_layers_add():
    """Reference: mass = density x thickness x rest area, summed over layers; a face with
    two layers has two membrane rows whose energies add, and a body with a membrane and no
    stiffness has no springs."""
    stiff = sb.Membrane.stvk(1e7, 0.3, 2e-4)
    b = sb.ModelBuilder()
    faces = np.arange(10)
    b.add_soft_body(sb.icosphere(1, radius=0.3), gas=sb.Gas.fixed_pressure(0.0), density=1100.0,
                    membrane=[(NEO, None), (stiff, faces)])  # fmt: skip
    model = b.finalize()
    assert model.spring_count == 0
    assert model.membrane_count == 80 + 10
    area = model.membrane_rest_area
    expected = 1100.0 * (1e-3 * area[:80].sum() + 2e-4 * area[80:].sum())
    assert model.body_mass[0] == pytest.approx(expected, rel=1e-14)
    np.testing.assert_array_equal(model.membrane_indices[80:], model.tri_indices[faces])
    np.testing.assert_allclose(area.sum(), 4 * np.pi * 0.3**2, rtol=0.05)


def test_implicit_preconditioners_converge_on_a_membrane_only_body():
    """Contract of the implicit solvers' CG: on a membrane-only balloon (no springs: the
    multigrid hierarchy is the membranes' Laplacian, its finest smoother Gauss-Seidel on
    the membrane's true 3 x 3 blocks) every step at 1/60 s converges within the iteration
    cap, and the V-cycle needs fewer iterations than Jacobi (measured at 642 particles:
    18.6 against 23.4 per step without gravity, 17.0 against 44.5 with it; at 2,562: 30
    against 55, 25 against 92)."""
    model = _balloon(NEO, subdivisions=3, gas=sb.Gas.fixed_pressure(900.0))
    iterations = {}
    for preconditioner in ("multigrid", "jacobi"):
        sim = sb.Simulator(model, integrator="implicit_euler", dt=1 / 60,
                           implicit_preconditioner=preconditioner)  # fmt: skip
        state = model.state()
        sim.run(state, 12)
        mean, most = sim.solver_iterations
        assert most < sim.implicit_max_iterations
        iterations[preconditioner] = mean
    assert iterations["multigrid"] < iterations["jacobi"]


# -- scenes ------------------------------------------------------------------------------
SCENE = """
name = "membranes"
[simulation]
integrator = "implicit_euler"
dt = 0.001
duration = 0.01
gravity = [0.0, 0.0, 0.0]
[[bodies]]
mesh = { shape = "icosphere", subdivisions = 2, radius = 0.2 }
density = 1000.0
gas = { law = "fixed_pressure", pressure = 900.0 }
membrane = { model = "neo_hookean", shear_modulus = 2e5, thickness = 1e-3, damping = 0.002 }
[[bodies]]
mesh = { shape = "icosphere", subdivisions = 1, radius = 0.2 }
position = [1.0, 0.0, 0.0]
mass = 0.05
stiffness = 20.0
gas = 20.0
membrane = [{ model = "stvk", youngs_modulus = 1e6, poisson_ratio = 0.3, thickness = 1e-3 },
            { model = "mooney_rivlin", c10 = 1e5, c01 = 2e4, thickness = 1e-4, faces = [0, 1, 2] }]
"""


def test_scene_membrane_tables_build_the_builders_layers(tmp_path):
    """Contract of the scene schema: a ``membrane`` table (or an array of them, layers
    with optional ``faces``) builds the same model as ModelBuilder with those Membranes;
    ``density`` gives the mass; a body with a membrane needs no stiffness."""
    from softbody.scenes import load_scene

    path = tmp_path / "membranes.toml"
    path.write_text(SCENE)
    model = load_scene(str(path)).model
    b = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    b.add_soft_body(sb.icosphere(2, radius=0.2), density=1000.0,
                    gas=sb.Gas.fixed_pressure(900.0), membrane=NEO)  # fmt: skip
    b.add_soft_body(sb.icosphere(1, radius=0.2, center=(1.0, 0.0, 0.0)), mass=0.05,
                    stiffness=20.0, gas=20.0,
                    membrane=[(sb.Membrane.stvk(1e6, 0.3, 1e-3), None),
                              (sb.Membrane.mooney_rivlin(1e5, 2e4, 1e-4), [0, 1, 2])],
                    )  # fmt: skip
    want = b.finalize()
    for name in ("membrane_indices", "membrane_material", "membrane_params",
                 "membrane_thickness", "membrane_damping", "membrane_body", "body_mass",
                 "spring_indices"):  # fmt: skip
        np.testing.assert_array_equal(getattr(model, name), getattr(want, name), err_msg=name)
    np.testing.assert_allclose(model.membrane_rest_inverse, want.membrane_rest_inverse,
                               rtol=1e-12, atol=1e-12)  # fmt: skip


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ('bodies.0.membrane.model="rubber"',
         r"bodies.0.membrane.model: unknown value 'rubber' \(valid: neo_hookean, "
         r"mooney_rivlin, stvk\)"),
        ("bodies.0.membrane.colour=1", "unknown scene key bodies.0.membrane.colour"),
        ("bodies.1.membrane.0.poisson_ratio=0.5",
         "bodies.1.membrane.0.poisson_ratio: must be < 0.5, got 0.5"),
        ("bodies.0.membrane.thickness=0", "bodies.0.membrane.thickness: must be > 0, got 0"),
        ("bodies.0.membrane.shear_modulus=-1", "bodies.0.membrane.shear_modulus: must be >= 0"),
        ("bodies.0.mass=1", "bodies.0.mass: give exactly one of mass or density"),
        ("bodies.1.membrane.1.faces=[99]", r"bodies.1.membrane.1.faces must lie in \[0, 79\]"),
        ("bodies.0.membrane={thickness=1}", "bodies.0.membrane.model: required, not given"),
        ("bodies.1.membrane=3", "bodies.1.membrane: must be a table, got 3"),
        ("bodies.0.damping=1", "bodies.0.damping: damps the edge springs: give stiffness too"),
    ],
)  # fmt: skip
def test_scene_membrane_errors_name_the_key(tmp_path, override, message):
    """Contract of the scene schema: a bad membrane key is a one-line error naming the
    dotted key and the reason, as for every other key (unknown keys refused)."""
    from softbody.scenes import load_scene

    path = tmp_path / "membranes.toml"
    path.write_text(SCENE)
    with pytest.raises(ValueError, match=message) as info:
        load_scene(str(path), [override])
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("membrane_material", lambda m: np.full_like(m.membrane_material, 3),
         "membrane_material holds 3"),
        ("membrane_indices", lambda m: np.full_like(m.membrane_indices, m.particle_count),
         "membrane_indices holds"),
        ("membrane_thickness", lambda m: np.full_like(m.membrane_thickness, -1.0),
         "membrane_thickness holds -1.0+ at 0; it must be finite and >= 0"),
        ("membrane_params", lambda m: np.full_like(m.membrane_params, np.nan),
         "membrane_params holds nan at 0; it must be finite"),
    ],
)  # fmt: skip
def test_the_core_refuses_broken_membrane_fields(field, value, message):
    """Contract of core/fields.hpp's declared checks: a Model whose membrane arrays break
    them (a material the core does not know, a particle index out of range, a negative
    thickness, a non-finite parameter) is refused with a ValueError naming the field."""
    import dataclasses

    model = _balloon(NEO, subdivisions=1)
    bad = dataclasses.replace(model, **{field: value(model)})
    with pytest.raises(ValueError, match=message):
        _core.Model(bad)


def test_a_fixed_gas_amount_holds_the_balloon_past_the_peak():
    """Reference: the balloon curve past its peak. With the isothermal gas amount
    nRT = P(s) V0 s^3 that balances the closed form at s = 2 (past 7^(1/6), where the
    membrane's pressure falls with stretch, but the gas's falls faster, so the equilibrium
    is stable), the damped neo-Hookean balloon inflates from rest and settles at s = 2
    within 1e-3 (the mesh's uneven triangles: as on the rising branch)."""
    rest = _balloon(NEO)
    area, volume = rest.membrane_rest_area.sum(), rest.body_rest_volume[0]
    nrt = float(equibiaxial_pressure(NEO, 2.0, area, volume)) * volume * 8.0
    model = _balloon(NEO, gas=sb.Gas.isothermal(nrt))
    state = model.state()
    sb.Simulator(model, integrator="implicit_euler", dt=1e-3).run(state, 1500)
    s = (sb.body_volume(model, state)[0] / volume) ** (1 / 3)
    assert abs(s / 2.0 - 1) <= 1e-3


@pytest.mark.parametrize("name", list(MATERIALS))
@pytest.mark.parametrize("scale", [0.8, 1.3])
def test_jacobian_product_matches_the_reference_clamped_hessian(name, scale):
    """Reference: softbody.reference.membrane.jacobian_product, which builds each
    triangle's F-Hessian by central differences of the NumPy Piola stress and clamps it
    with numpy.linalg.eigh. The core's (analytic Hessian, Jacobi eigensolver) alpha_c C p
    + alpha_k K p equals it at a compressed (0.8, where the clamping acts) and a stretched
    (1.3) perturbed state, to 1e-7 of |K p| (the differences' error, about 1e-10 of the
    stress, amplified by the clamping's sensitivity near zero eigenvalues)."""
    model = _balloon(MATERIALS[name], subdivisions=1)
    q, _ = _perturbed(model, scale=scale, noise=0.02)
    p = np.random.default_rng(9).normal(size=q.shape)
    for alpha_c, alpha_k in ((0.0, 1.0), (1.0, 0.0), (-0.01, -1e-4)):
        got = _jacobian_product(model, q, p, alpha_c=alpha_c, alpha_k=alpha_k)
        want = ref.membrane.jacobian_product(model, q, p, alpha_c, alpha_k)
        assert np.abs(want).max() > 0
        assert np.abs(got - want).max() <= 1e-7 * np.abs(want).max()


def test_a_given_linearisation_replaces_the_terms_own():
    """Contract of softbody._core.apply_jacobians' ``linearization``: a term's
    linearisation given by name is what its product reads, in place of its own prepare at
    q. The membrane's blocks given as zeros give the product with the membrane left out
    (leave_out), bit for bit, and the product without them differs (there the membrane's
    own blocks at q act); a linearisation of the wrong size or type, or a name that is no
    registered term, is refused naming it."""
    model = _balloon(MATERIALS["stvk"], subdivisions=1)
    q, _ = _perturbed(model, scale=0.9, noise=0.02)
    data = control_data(model)
    core = core_model(model)
    p = np.random.default_rng(2).normal(size=q.shape)
    plain, zeroed, without = (np.zeros_like(q) for _ in range(3))
    _core.apply_jacobians(core, data, q, p, 0.0, 0.3, 1.0, plain)
    blocks = {"membrane": np.zeros(42 * model.membrane_count)}  # (Tm, 42) flat, all zero
    _core.apply_jacobians(core, data, q, p, 0.0, 0.3, 1.0, zeroed, linearization=blocks)
    _core.apply_jacobians(core, data, q, p, 0.0, 0.3, 1.0, without, leave_out=["membrane"])
    np.testing.assert_array_equal(zeroed, without)
    assert np.abs(plain - without).max() > 1e-3 * np.abs(plain).max()
    with pytest.raises(ValueError, match=r"linearization\[membrane\]"):
        _core.apply_jacobians(core, data, q, p, 0.0, 0.3, 1.0, zeroed,
                              linearization={"membrane": np.zeros((3, 42))})  # fmt: skip
    with pytest.raises(ValueError, match=r"linearization\[membrane\] must be a C-contig"):
        listed = {"membrane": blocks["membrane"].tolist()}
        _core.apply_jacobians(core, data, q, p, 0.0, 0.3, 1.0, zeroed, linearization=listed)
    with pytest.raises(ValueError, match="no registered term is called membranes"):
        _core.apply_jacobians(core, data, q, p, 0.0, 0.3, 1.0, zeroed, leave_out=["membranes"])


def test_breathing_mode_frequency_is_the_rayleigh_quotient_of_uniform_scaling():
    """Reference: the Rayleigh quotient of uniform scaling x = s x0 about the equilibrium
    s0 = 1.15 of a neo-Hookean balloon holding a fixed amount of isothermal gas,
    omega^2 = (A0 H W''(s0) + 3 nRT / s0^2) / sum m |x0|^2 with W(s) = mu / 2 (2 s^2 +
    s^-4 - 3), nRT = P(s0) V0 s0^3. Released from 1.002 s0 x0 and stepped undamped by
    velocity Verlet at 2e-5 s, the volume oscillates with that period to 1e-4 (Verlet's
    phase error (omega dt)^2 / 24 is 6e-6; uniform scaling is the breathing mode up to the
    mesh's uneven triangles: measured agreement 1e-5)."""
    mu, thickness = 2e5, 1e-3
    membrane = sb.Membrane.neo_hookean(mu, thickness)

    def build(gas):
        b = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
        b.add_soft_body(sb.icosphere(2, radius=0.2), mass=0.05, gas=gas, membrane=membrane,
                        mass_distribution="area")  # fmt: skip
        return b.finalize()

    rest = build(sb.Gas.fixed_pressure(0.0))
    area, volume = rest.membrane_rest_area.sum(), rest.body_rest_volume[0]
    s0 = 1.15
    nrt = float(equibiaxial_pressure(membrane, s0, area, volume)) * volume * s0**3
    model = build(sb.Gas.isothermal(nrt))
    stiffness = area * thickness * mu / 2 * (4 + 20 * s0**-6) + 3 * nrt / s0**2
    inertia = np.sum(model.particle_mass * np.sum(model.particle_q**2, axis=1))
    period = 2 * np.pi / np.sqrt(stiffness / inertia)
    state = model.state()
    state.particle_q[:] = 1.002 * s0 * model.particle_q
    sim = sb.Simulator(model, integrator="velocity_verlet", dt=2e-5)
    times, volumes = [], []
    for _ in range(2500):
        sim.run(state, 1)
        times.append(state.time)
        volumes.append(sb.body_volume(model, state)[0])
    t, v = np.array(times), np.array(volumes) - np.mean(volumes)
    up = np.flatnonzero((v[:-1] < 0) & (v[1:] >= 0))
    crossing = t[up] - v[up] * (t[up + 1] - t[up]) / (v[up + 1] - v[up])
    assert len(crossing) >= 4
    assert np.mean(np.diff(crossing)) == pytest.approx(period, rel=1e-4)


def _tube(radius, length, segments, rings, cap_rings):
    """A closed tube along z: rings + 1 circles of ``segments`` vertices over ``length``
    [m], each end closed by a hemisphere of ``cap_rings`` latitude bands and a pole."""
    profile = [(radius * np.sin(np.pi / 2 * k / cap_rings),
                -length / 2 - radius * np.cos(np.pi / 2 * k / cap_rings))
               for k in range(1, cap_rings)]  # fmt: skip
    profile += [(radius, z) for z in np.linspace(-length / 2, length / 2, rings + 1)]
    profile += [(r, -z) for r, z in reversed(profile[: cap_rings - 1])]
    angle = 2 * np.pi * np.arange(segments) / segments
    vertices = [(r * np.cos(a), r * np.sin(a), z) for r, z in profile for a in angle]
    vertices += [(0.0, 0.0, -length / 2 - radius), (0.0, 0.0, length / 2 + radius)]
    bottom, top, n = len(vertices) - 2, len(vertices) - 1, segments
    faces = []
    for i in range(len(profile) - 1):
        for j in range(n):
            a, b, c, d = i * n + j, i * n + (j + 1) % n, (i + 1) * n + j, (i + 1) * n + (j + 1) % n
            faces += [(a, b, d), (a, d, c)]
    last = (len(profile) - 1) * n
    for j in range(n):
        faces += [(bottom, (j + 1) % n, j), (top, last + j, last + (j + 1) % n)]
    return sb.TriMesh(np.array(vertices), np.array(faces))


def test_pressurised_tube_has_laplaces_hoop_and_axial_tension():
    """Reference: the membrane equations of a closed tube under pressure P (Laplace): hoop
    tension N_t = P r, axial N_z = P r / 2, r the current radius. The tube here is a
    16-sided prism, for which the exact force balance of the faceted wall gives the same
    with a factor cos(pi / 16) on both (the pressure on two facets meeting at a vertex
    pulls it outward by P r sin(2 pi / n) per length; the caps' P times the polygon's
    area spread over its perimeter). With the StVK tensions N_t = H lt S_t / lz,
    N_z = H lz S_z / lt (S = E / (1 - nu^2) (G_t + nu G_z), ..., G = (l^2 - 1) / 2) the
    two stretches lt, lz follow by Newton's method; the settled middle of the damped
    membrane-only tube (1 m long, r = 0.1 m, P r / (E H) = 1%) has them to 1e-4 of the
    strains (measured 2e-6 and 1.1e-5; hoop strain 4.1 times the axial one, as plane stress with
    nu = 0.3 says at small strain: (1 - nu / 2) / (1 / 2 - nu) = 4.25)."""
    radius, segments = 0.1, 16
    youngs, nu, thickness, pressure = 1e6, 0.3, 1e-3, 100.0
    b = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    b.add_soft_body(_tube(radius, 1.0, segments, 20, 6), mass=0.05,
                    gas=sb.Gas.fixed_pressure(pressure),
                    membrane=sb.Membrane.stvk(youngs, nu, thickness, damping=5e-3))  # fmt: skip
    model = b.finalize()
    state = model.state()
    sb.Simulator(model, integrator="implicit_euler", dt=1e-3).run(state, 1500)
    q, q0 = state.particle_q, model.particle_q
    wall = np.abs(np.hypot(q0[:, 0], q0[:, 1]) - radius) < 1e-9

    def ring(z):
        return np.flatnonzero(wall & (np.abs(q0[:, 2] - z) < 1e-9))

    hoop = np.mean(np.hypot(q[ring(0.0), 0], q[ring(0.0), 1])) / radius
    axial = (q[ring(0.1), 2].mean() - q[ring(-0.1), 2].mean()) / 0.2
    facet = np.cos(np.pi / segments)
    k = youngs / (1 - nu**2)

    def residual(x):
        lt, lz = x
        gt, gz = (lt**2 - 1) / 2, (lz**2 - 1) / 2
        return np.array([thickness * lt * k * (gt + nu * gz) / lz - pressure * radius * lt * facet,
                         thickness * lz * k * (gz + nu * gt) / lt
                         - pressure * radius * lt * facet / 2])  # fmt: skip

    x = np.array([1.0, 1.0])
    for _ in range(30):  # Newton, the Jacobian by central differences
        jac = np.column_stack([(residual(x + e) - residual(x - e)) / 2e-7
                               for e in np.eye(2) * 1e-7])  # fmt: skip
        x = x - np.linalg.solve(jac, residual(x))
    lt, lz = x
    assert abs((hoop - 1) / (lt - 1) - 1) <= 1e-4
    assert abs((axial - 1) / (lz - 1) - 1) <= 1e-4
    assert 3.9 < (hoop - 1) / (axial - 1) < 4.3


def test_the_term_is_registered_and_acts_only_with_membranes():
    """Contract of the term registry: "membrane" is registered, with an energy, a
    projection and a vertex-major (lane) form, and no unconditional fused form (the fused
    symplectic pass covers it only where the lane pass runs); it acts only in a model with
    membrane triangles, so a membrane-free model keeps the fused symplectic pass."""
    table = {t["name"]: t for t in sb.core.terms()}
    traits = table["membrane"]
    assert traits["energy"] and traits["projected"] and traits["lane"]
    assert not (traits["fused"] or traits["external"])
    b = sb.ModelBuilder()
    b.add_soft_body(sb.icosphere(1), mass=0.1, stiffness=10.0, gas=5.0)
    assert "membrane" not in sb.diagnostics.active_terms(b.finalize())
    assert "membrane" in sb.diagnostics.active_terms(_balloon(NEO, subdivisions=1))


@pytest.mark.parametrize("dt", [1e-3, 1 / 60])
@pytest.mark.parametrize(("name", "stretch"), [("stvk", 1.8), ("neo_hookean", 2.5)])
def test_projective_dynamics_settles_stretched_sheets(name, stretch, dt):
    """Reference: the closed-form balloon curve at large stretch, where sheets stiffen. A
    StVK balloon under the fixed pressure of stretch 1.8 and a neo-Hookean one holding the
    isothermal gas of stretch 2.5 (past its peak), stepped by projective dynamics with 2
    iterations from rest, settle there within 1e-3 in 1 s. (With the factor holding only
    the small-strain bound, PROJECTIVE_MARGIN = 1, both diverged.) A matrix in Python and
    a right-hand side in the core that disagreed would move this fixed point. The
    isothermal gas's step estimate for projective dynamics, 1 / omega_gas = 0.7 ms, counts
    only the masses against the gas's volume mode; the membrane in the factor resists it
    too, so the larger steps here stay stable (its StabilityWarning is left out)."""
    membrane = MATERIALS[name]
    rest = _balloon(membrane)
    area, volume = rest.membrane_rest_area.sum(), rest.body_rest_volume[0]
    pressure = float(equibiaxial_pressure(membrane, stretch, area, volume))
    gas = (sb.Gas.fixed_pressure(pressure) if name == "stvk"
           else sb.Gas.isothermal(pressure * volume * stretch**3))  # fmt: skip
    model = _balloon(membrane, gas=gas)
    state = model.state()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator="projective", dt=dt)
    sim.run(state, round(1.0 / dt))
    s = (sb.body_volume(model, state)[0] / volume) ** (1 / 3)
    assert abs(s / stretch - 1) <= 1e-3


# The lane form (terms/membrane.hpp: lane_triangle): each particle's ring of triangles in
# the vertex-major pass, against the edge-major force of the scalar path.

LANE_PATHS = [p for p in sb.core.simd_paths() if p != "scalar"]
lane_paths = pytest.mark.skipif(not LANE_PATHS, reason="no SIMD path: the lane pass never runs")


def _on_path(path, call):
    before = sb.core.simd_path()
    sb.core.use_simd(path)
    try:
        return call()
    finally:
        sb.core.use_simd(before)


def _lane_models(material):
    """Membrane bodies whose triangles reach every part of the lane form: a balloon (each
    triangle on its corners' closed rings), the same with a second material on some faces
    (rows that differ within a lane group, and layers off the rings), a cloth (open fans:
    border triangles and rings that do not close) and springs with a membrane on part of
    the faces (ring slots without a triangle)."""
    layered = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    other = sb.Membrane.stvk(3e6, 0.25, 2e-4, damping=material.damping)
    layered.add_soft_body(sb.icosphere(2, radius=0.2), mass=0.05,
                          gas=sb.Gas.fixed_pressure(0.0),
                          membrane=[(material, None), (other, np.arange(0, 320, 3))])  # fmt: skip
    cloth = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    cloth.add_cloth(sb.rectangle((0.4, 0.3), (7, 5)), mass=0.02, membrane=material)
    part = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    part.add_soft_body(sb.icosphere(2, radius=0.2), mass=0.05, stiffness=50.0, damping=0.1,
                       gas=sb.Gas.fixed_pressure(0.0),
                       membrane=[(material, np.arange(40, 200))])  # fmt: skip
    return {"balloon": _balloon(material), "layered": layered.finalize(),
            "cloth": cloth.finalize(), "part": part.finalize()}  # fmt: skip


@lane_paths
@pytest.mark.parametrize("path", LANE_PATHS)
@pytest.mark.parametrize("damped", [True, False])
@pytest.mark.parametrize("name", list(MATERIALS))
def test_lane_form_matches_the_edge_major_force(name, damped, path):
    """Reference: the edge-major force (the scalar path, which the NumPy reference checks).
    The vertex-major pass's force on randomly stretched, sheared and moving membrane bodies
    (a balloon, a layered balloon, a cloth, springs with a membrane on part of the faces;
    fixed seeds) equals the scalar path's to 1e-12 of the membrane force's size, for each
    material with and without strain-rate damping."""
    base = MATERIALS[name]
    material = base if damped else dataclasses.replace(base, damping=0.0)
    for label, model in _lane_models(material).items():
        q, qd = _perturbed(model, scale=1.1, noise=0.02, seed=3)
        scalar = _on_path("scalar", lambda m=model, q=q, qd=qd: _core_force(m, q, qd))
        lanes = _on_path(path, lambda m=model, q=q, qd=qd: _core_force(m, q, qd))
        size = np.abs(ref.membrane.force(model, q, qd)).max()
        assert size > 0, label
        assert np.abs(lanes - scalar).max() <= 1e-12 * size, label


def _replayed(model, dt, steps):
    """Symplectic Euler by hand from the core's forces (forms::eval_forces: every term in
    registry order): v += dt f / m, x += dt v."""
    state = model.state()
    q, qd = state.particle_q.copy(), state.particle_qd.copy()
    h = dt * model.particle_inv_mass
    for _ in range(steps):
        f = _core_force(model, q, qd)
        qd = qd + h[:, None] * f
        q = q + dt * qd
    return q, qd


@pytest.mark.parametrize("path", sb.core.simd_paths())
def test_symplectic_euler_sums_the_forces_in_registry_order(path):
    """Contract of the fused symplectic pass (solvers/explicit.hpp): the same arithmetic as
    the general step. A pressurised, damped neo-Hookean balloon falling under gravity, 20
    steps: bit for bit the steps replayed by hand from the core's forces, on every path:
    on SIMD paths the fused pass with the membrane's lane form, on the scalar path the
    general step, where the membrane's edge-major force is summed after the pressure's."""
    b = sb.ModelBuilder()
    b.add_soft_body(sb.icosphere(2, radius=0.2, center=(0.0, 1.0, 0.0)), mass=0.05,
                    gas=sb.Gas.isothermal(30.0), membrane=NEO)  # fmt: skip
    model = b.finalize()
    dt, steps = 2e-5, 20

    def run():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sb.StabilityWarning)
            sim = sb.Simulator(model, integrator="symplectic_euler", dt=dt)
        state = model.state()
        sim.run(state, steps)
        return state.particle_q, state.particle_qd, _replayed(model, dt, steps)

    q, qd, (q_hand, qd_hand) = _on_path(path, run)
    assert np.abs(qd).max() > 0.01  # it moved
    np.testing.assert_array_equal(q, q_hand)
    np.testing.assert_array_equal(qd, qd_hand)


@lane_paths
@pytest.mark.skipif(sb.core.available_threads() < 2, reason="needs two cores")
@pytest.mark.parametrize("integrator", ["symplectic_euler", "implicit_euler", "xpbd"])
def test_membrane_lane_pass_on_threads_repeats_bit_for_bit(integrator):
    """Contract of the vertex-major pass on threads (each particle writes only its own row,
    the volumes summed in chunk order): a layered membrane balloon dropped on the ground
    repeats bit for bit on two threads, and agrees with the serial run to round-off."""
    layers = [(NEO, None), (MATERIALS["stvk"], np.arange(0, 320, 5))]

    def drop(threads):
        b = sb.ModelBuilder()
        b.add_soft_body(sb.icosphere(2, radius=0.2, center=(0.0, 0.21, 0.0)), mass=0.05,
                        gas=sb.Gas.isothermal(30.0), membrane=layers)  # fmt: skip
        b.add_collider(sb.ColliderPlane(restitution=0.3, friction=0.2))
        model = b.finalize()
        dt = 1e-3 if integrator == "implicit_euler" else 2e-5
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sb.StabilityWarning)
            sim = sb.Simulator(model, integrator=integrator, dt=dt, threads=threads)
        state = model.state()
        sim.run(state, 40 if integrator == "implicit_euler" else 400)
        return state

    serial, first, second = drop(1), drop(2), drop(2)
    np.testing.assert_array_equal(first.particle_q, second.particle_q)
    np.testing.assert_array_equal(first.particle_qd, second.particle_qd)
    assert np.abs(serial.particle_qd).max() > 0.05  # it fell
    assert np.abs(first.particle_q - serial.particle_q).max() < 1e-9


@lane_paths
def test_float32_force_pass_keeps_the_membrane():
    """Contract of force_precision="float32" (its springs and faces in float32, the rest in
    float64): a pressurised membrane balloon whose gas pushes against its skin is held the
    same way as in float64. After 300 steps of symplectic Euler the two runs agree to 1e-6
    of the displacement (float32 perturbs the forces by 2^-24), where a pass that left the
    membrane out would let the gas blow the skin outwards at once."""
    b = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    b.add_soft_body(sb.icosphere(2, radius=0.2), mass=0.05, gas=sb.Gas.fixed_pressure(2e3),
                    membrane=NEO)  # fmt: skip
    model = b.finalize()

    def run(precision):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sb.StabilityWarning)
            sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-5,
                               force_precision=precision)  # fmt: skip
        state = model.state()
        sim.run(state, 300)
        return state.particle_q - model.particle_q

    moved64, moved32 = run("float64"), run("float32")
    size = np.abs(moved64).max()
    assert size > 1e-5
    assert np.abs(moved32 - moved64).max() <= 1e-6 * size
