"""Membrane and material bending together: a compressed film buckles when, and as much
as, Euler's column says, so a thin film wrinkles and a thick one does not."""

from __future__ import annotations

import numpy as np
import pytest

import softbody as sb

L, W, E, RHO = 0.1, 0.02, 1e7, 1000.0  # strip length, width [m]; E [Pa]; density [kg/m^3]


def critical_strain(thickness: float) -> float:
    """Euler's buckling strain of a simply supported strip of length L [1]:
    pi^2 D / (E H L^2) = pi^2 H^2 / (12 L^2) for Poisson ratio 0 (a plate and a beam
    agree)."""
    return np.pi**2 * thickness**2 / (12 * L**2)


def compressed_strip(thickness: float, strain: float) -> tuple[sb.Model, sb.State]:
    """A 10 x 2 cm StVK strip (E = 10 MPa, nu = 0, 40 x 8 squares) with material bending
    of its own thickness, its two ends held (free to turn about them: simply supported),
    compressed by ``strain`` along its length and lifted by a random 1 um out of plane
    (fixed seed): the start of the buckling instability."""
    mesh = sb.rectangle((L, W), (40, 8))
    x = mesh.vertices[:, 0]
    ends = np.flatnonzero(np.isclose(np.abs(x), L / 2))
    builder = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    builder.add_cloth(
        mesh, density=RHO, membrane=sb.Membrane.stvk(E, 0.0, thickness, damping=0.02),
        bending=sb.Bending.from_material(youngs_modulus=E, poisson_ratio=0.0,
                                         thickness=thickness),
        pinned=ends,
    )  # fmt: skip
    model = builder.finalize()
    state = model.state()
    q = model.particle_q.copy()
    q[:, 0] *= 1.0 - strain
    inside = np.ones(len(q), dtype=bool)
    inside[ends] = False
    q[inside, 2] += 1e-6 * np.random.default_rng(1).standard_normal(inside.sum())
    state.particle_q = q
    return model, state


def test_a_thin_film_buckles_as_eulers_column_and_a_thick_one_stays_flat():
    """The same compression, 1.48e-3, of two strips. Reference: Euler's critical strain
    eps_c = pi^2 H^2 / (12 L^2) (D = E H^3 / 12 for nu = 0) and, past it, the first-order
    post-buckling amplitude of a simply supported column, A = (2 L / pi) sqrt(eps -
    eps_c): the bent shape takes up the shortening beyond eps_c, the membrane keeping
    eps_c. The 3 mm strip (eps = 2 eps_c) buckles into the half sine of its first mode
    (correlation with sin(pi x / L) above 0.99) with its amplitude within 5% of A
    (measured 2.8%: the 40-segment mesh's critical strain lies a few per cent below
    Euler's, O(h^2), and A's next order); the 4.74 mm one (eps = 0.8 eps_c) stays flat,
    its 1 um start decaying (below 1e-7 m)."""
    strain = 2.0 * critical_strain(3e-3)
    amplitudes = {}
    for thickness in (3e-3, 3e-3 * np.sqrt(2.0 / 0.8)):
        model, state = compressed_strip(thickness, strain)
        sim = sb.Simulator(model, integrator="implicit_euler", dt=1e-3)
        sim.advance(state, 0.5, progress=False)
        q = state.particle_q
        amplitudes[thickness] = np.abs(q[:, 2]).max()
        if strain > critical_strain(thickness):
            z = q[:, 2] * np.sign(q[np.argmax(np.abs(q[:, 2])), 2])
            mode = np.cos(np.pi * q[:, 0] / (L * (1.0 - strain)))  # x from -L/2 to L/2
            assert np.corrcoef(z, mode)[0, 1] > 0.99
            expected = 2 * L / np.pi * np.sqrt(strain - critical_strain(thickness))
            assert amplitudes[thickness] == pytest.approx(expected, rel=0.05)
        else:
            assert amplitudes[thickness] < 1e-7
    assert strain == pytest.approx(0.8 * critical_strain(3e-3 * np.sqrt(2.0 / 0.8)))
