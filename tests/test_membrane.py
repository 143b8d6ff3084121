"""Triangle membranes (``core/terms/membrane.hpp``, :mod:`softbody.membrane`).

References: the NumPy reference (``softbody.reference.membrane``) for the force and the
energy; central differences of the core's energy for the force and of the core's force
for the Jacobian product; the closed-form balloon curve P(s) = A0 H W'(s) / (3 V0 s^2)
for a uniformly scaled closed mesh; energy conservation under velocity Verlet; the
stability estimate against the largest eigenvalue of M^-1 K.
"""

from __future__ import annotations

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
                          alpha_k, *inputs, out)  # fmt: skip
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
