"""The two-balloon instability: two rubber balloons joined by a tube do not share their
air equally. Both past the peak of the balloon curve, the smaller one (higher pressure)
empties into the larger until it is back on the rising branch at the larger one's
pressure: a neo-Hookean membrane (core/terms/membrane.hpp) and an orifice between two
chambers (core/terms/flows.hpp) together.

Reference: the neo-Hookean balloon curve P = P_a + c (1 / s - 1 / s^7), c = 2 mu H A0 /
(3 V0) (A0, V0 the mesh's rest area and volume: exact for uniform scaling), and the
isothermal gas n_i = P V0 s_i^3 / (R T): the stable end state has equal pressures, s_1 on
the rising branch (below 7^(1/6)) and s_2 past the peak, and holds the gas the two began
with.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

import softbody as sb
from softbody.gas import GAS_CONSTANT as R

MU, H, RADIUS, T, P_A = 2e5, 1e-3, 0.2, 293.15, 1e5
PEAK = 7 ** (1 / 6)


def gauge(s, c):
    """The balloon curve's gauge pressure [Pa] at stretch s."""
    return c * (1 / s - 1 / s**7)


def stable_pair(total, c, v0):
    """(s_1, s_2): equal pressures, s_1 < 7^(1/6) < s_2, holding `total` moles."""

    def rising(s2):
        return brentq(lambda s: gauge(s, c) - gauge(s2, c), 1.0 + 1e-12, PEAK)

    def excess(s2):
        s1 = rising(s2)
        return (P_A + gauge(s2, c)) * v0 * (s1**3 + s2**3) / (R * T) - total

    s2 = brentq(excess, PEAK * (1 + 1e-9), 10.0)
    return rising(s2), s2


def joined_balloons(start):
    """Two 162-vertex neo-Hookean balloons joined by a wide orifice, scaled to the
    stretches `start` (2,), each holding the isothermal air that balances it alone: (model,
    state, c [Pa] the curve's constant, V0 [m^3] the rest volume)."""
    neo = sb.Membrane.neo_hookean(MU, H, damping=0.002)
    builder = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    for x in (-1.0, 1.0):
        builder.add_soft_body(
            sb.icosphere(2, radius=RADIUS, center=(x, 0.0, 0.0)), mass=0.05, membrane=neo,
            gas=sb.Gas.ideal(1.0, T, ambient_pressure=P_A),
        )  # fmt: skip
    builder.add_orifice(0, 1, area=0.05)
    model = builder.finalize()
    v0 = model.body_rest_volume[0]
    c = 2 * MU * H * model.membrane_rest_area[model.membrane_body == 0].sum() / (3 * v0)
    state = model.state()
    for body, s in enumerate(start):
        p0, p1 = model.body_particle_range[body]
        centre = state.particle_q[p0:p1].mean(axis=0)
        state.particle_q[p0:p1] = centre + s * (state.particle_q[p0:p1] - centre)
    volume = sb.body_volume(model, state)
    state.body_gas_moles[:] = (P_A + gauge(np.asarray(start), c)) * volume / (R * T)
    return model, state, c, v0


def test_two_joined_balloons_end_unequal_on_the_closed_form():
    """Two 162-vertex neo-Hookean balloons (mu = 0.2 MPa, H = 1 mm, R = 0.2 m) at
    stretches 1.65 and 1.55, both past the peak, each holding the air that balances it,
    joined by an orifice (isothermal air at 1 bar outside): the smaller shrinks onto the
    rising branch and the larger grows, to the closed-form pair within 1e-3 of the
    stretch (the mesh is not exactly uniform under pressure: 1e-5 measured); the air is
    conserved to round-off throughout, and the pressures end equal."""
    model, state, c, v0 = joined_balloons((1.65, 1.55))
    total = state.body_gas_moles.sum()
    s1, s2 = stable_pair(total, c, v0)
    assert s1 < PEAK < s2
    sim = sb.Simulator(model, integrator="implicit_euler", dt=2e-3)
    for _ in range(16):
        sim.advance(state, 0.5)
        np.testing.assert_allclose(state.body_gas_moles.sum(), total, rtol=1e-13)
    stretch = (sb.body_volume(model, state) / v0) ** (1 / 3)
    np.testing.assert_allclose(stretch, [s2, s1], rtol=1e-3)
    gauges = sb.body_pressure(model, state) - P_A
    np.testing.assert_allclose(gauges[0], gauges[1], rtol=1e-3)


def test_the_two_balloons_scene_ends_on_the_closed_form_pair():
    """The `two-balloons` scene (softbody run two-balloons): two balloons at rest, joined,
    are filled by inflators for 2 s, the left a little faster, past the peak; after its
    12 s the left is past the peak and the right on the rising branch, at the closed-form
    pair for the air they then hold (1e-3 of the stretch, as above; at 8 s the right is
    still 0.5 % above it, 1.175 against 1.169, and settles by 10 s); the inflators' air is
    all in them, to the first-order error of sampling the tables' 2 ms ramp at step starts
    (the implicit schemes take flows by forward Euler: at most the whole flow times one
    step, 0.0084 mol of 11), and the bodies, pushed by their own gas and skins only, keep
    their momentum (0 to CG's tolerance)."""
    from softbody.scenes import load_scene

    scene = load_scene("two-balloons")
    model = scene.model
    v0 = model.body_rest_volume[0]
    c = 2 * MU * H * model.membrane_rest_area[model.membrane_body == 0].sum() / (3 * v0)
    state = model.state()
    delivered = (0.06819 + 0.05327) * 2.0 / model.body_gas_molar_mass[0]
    start = state.body_gas_moles.sum()
    sb.Simulator(model, integrator=scene.integrator, dt=scene.dt).advance(
        state, scene.duration, progress=False
    )
    total = state.body_gas_moles.sum()
    ramp = (0.06819 + 0.05327) * scene.dt / model.body_gas_molar_mass[0]
    assert abs(total - (start + delivered)) <= 1.001 * ramp
    s1, s2 = stable_pair(total, c, v0)
    stretch = (sb.body_volume(model, state) / v0) ** (1 / 3)
    np.testing.assert_allclose(stretch, [s2, s1], rtol=1e-3)
    momentum = (model.particle_mass[:, None] * state.particle_qd).sum(axis=0)
    assert np.abs(momentum).max() < 1e-6
