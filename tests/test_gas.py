"""Gas laws: P(V) closed forms, energies, schedules and control overrides."""

from __future__ import annotations

import numpy as np
import pytest

import softbody as sb
from conftest import ball_model
from softbody.reference.gas import law_energy


def scaled_state(model, s):
    """The rest shape scaled by s about its centre: V = s^3 V0."""
    state = model.state()
    c = state.particle_q.mean(axis=0)
    state.particle_q[:] = c + s * (state.particle_q - c)
    return state


@pytest.mark.parametrize("s", [0.8, 1.0, 1.3])
def test_isothermal_pressure_is_nrt_over_v(s):
    """Paper eq. 5: P = nRT / V."""
    model = ball_model(gas=sb.Gas.isothermal(420.0))
    state = scaled_state(model, s)
    v = sb.body_volume(model, state)[0]
    assert v == pytest.approx(s**3 * model.body_rest_volume[0], rel=1e-12)
    assert sb.body_pressure(model, state)[0] == pytest.approx(420.0 / v, rel=1e-13)


@pytest.mark.parametrize("s", [0.8, 1.3])
def test_adiabatic_pressure_keeps_pv_gamma(s):
    """Adiabatic: P V^gamma is the same at every volume, and P(V_rest) = nRT / V_rest."""
    model = ball_model(gas=sb.Gas.adiabatic(420.0, gamma=1.4))
    v0 = model.body_rest_volume[0]
    p0 = sb.body_pressure(model, model.state())[0]
    assert p0 == pytest.approx(420.0 / v0, rel=1e-13)
    state = scaled_state(model, s)
    v = sb.body_volume(model, state)[0]
    p = sb.body_pressure(model, state)[0]
    assert p * v**1.4 == pytest.approx(p0 * v0**1.4, rel=1e-12)


def test_fixed_pressure_ignores_volume():
    """A regulated supply: P = P0 whatever the volume."""
    model = ball_model(gas=sb.Gas.fixed_pressure(150.0))
    for s in (0.7, 1.0, 1.5):
        assert sb.body_pressure(model, scaled_state(model, s))[0] == 150.0


def test_ideal_gas_from_moles_and_temperature():
    """nRT with R = 8.314462618 J/(mol K): 0.1 mol at 300 K -> 249.43 J."""
    gas = sb.Gas.ideal(0.1, 300.0)
    assert gas.value == pytest.approx(0.1 * 8.314462618 * 300.0, rel=1e-15)


@pytest.mark.parametrize(
    "law,gamma",
    [
        (sb.GasLaw.ISOTHERMAL, 1.4),
        (sb.GasLaw.ADIABATIC, 1.4),
        (sb.GasLaw.ADIABATIC, 5 / 3),
        (sb.GasLaw.FIXED_PRESSURE, 1.4),
    ],
)
def test_gas_energy_derivative_is_minus_net_pressure(law, gamma):
    """-dE/dV = P - P_ambient for every law (central difference, h = 1e-6 V)."""
    value, vref, amb = 300.0, 2.0, 25.0
    v = np.array([1.1, 2.7, 4.0])
    h = 1e-6 * v
    law_a = np.full(3, int(law))

    def energy(x):
        return law_energy(law_a, value, gamma, vref, amb, x)

    de = (energy(v + h) - energy(v - h)) / (2 * h)
    p = {
        sb.GasLaw.ISOTHERMAL: value / v,
        sb.GasLaw.FIXED_PRESSURE: np.full(3, value),
        sb.GasLaw.ADIABATIC: value * vref ** (gamma - 1) / v**gamma,
    }[law]
    assert np.allclose(-de, p - amb, rtol=1e-8)


def test_schedule_interpolates_and_holds_ends():
    """Piecewise-linear nRT(t), held before the first and after the last point."""
    gas = sb.Gas.isothermal(100.0, schedule=[(0.5, 100.0), (1.5, 300.0), (2.0, 50.0)])
    model = ball_model(gas=gas)
    state = model.state()
    expected = {0.0: 100.0, 0.5: 100.0, 1.0: 200.0, 1.5: 300.0, 1.75: 175.0, 9.0: 50.0}
    for t, nrt in expected.items():
        state.time = t
        assert sb.body_gas_value(model, state)[0] == pytest.approx(nrt, rel=1e-15)
        v = sb.body_volume(model, state)[0]
        assert sb.body_pressure(model, state)[0] == pytest.approx(nrt / v, rel=1e-13)


def test_control_overrides_gas_of_one_body():
    """Control.body_gas_nrt replaces nRT for the bodies it sets (NaN keeps the model's);
    body_gas_pressure does the same for fixed-pressure bodies, and mixing them up is an error."""
    builder = sb.ModelBuilder()
    for k, gas in enumerate([sb.Gas.isothermal(100.0), sb.Gas.fixed_pressure(40.0)]):
        builder.add_soft_body(
            sb.icosphere(1, center=(3 * k, 0, 0)), mass=1.0, stiffness=10.0, damping=0.0, gas=gas
        )
    model = builder.finalize()
    state = model.state()
    control = model.control()
    control.body_gas_nrt[0] = 250.0
    control.body_gas_pressure[1] = 55.0
    v = sb.body_volume(model, state)
    assert np.allclose(sb.body_pressure(model, state, control), [250.0 / v[0], 55.0])
    bad = model.control()
    bad.body_gas_nrt[1] = 1.0
    with pytest.raises(ValueError, match=r"body_gas_nrt set for fixed-pressure bodies \[1\]"):
        sb.body_pressure(model, state, bad)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"nrt": float("nan")}, "gas nRT must be finite"),
        ({"nrt": -1.0}, "gas nRT must be >= 0"),
        ({"nrt": 1.0, "schedule": [(1.0, 1.0), (0.5, 2.0)]}, "times must increase"),
        ({"nrt": 1.0, "schedule": [(0.0, -1.0)]}, "values must be >= 0"),
        ({"nrt": 1.0, "ambient_pressure": -5.0}, "ambient_pressure must be >= 0"),
    ],
)
def test_bad_gas_parameters(kwargs, match):
    """NaN, negative or unordered gas parameters are refused with the reason."""
    with pytest.raises(ValueError, match=match):
        sb.Gas.isothermal(**kwargs)


def test_adiabatic_gamma_must_exceed_one():
    """gamma = 1 would be the isothermal law with a singular energy formula."""
    with pytest.raises(ValueError, match="gas gamma must be > 1"):
        sb.Gas.adiabatic(10.0, gamma=1.0)
