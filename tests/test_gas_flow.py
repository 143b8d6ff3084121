"""Gas that flows: vents, orifices, inflators and leaks acting on the gas state (amount n
and temperature T per body, ``State.body_gas_moles`` / ``body_gas_temperature``), each
against its closed form (core/terms/flows.hpp, core/solvers/gas_state.hpp).

Most checks use a rigid vessel, a sphere whose vertices are all pinned, so that the
volume V is fixed and the gas alone changes; the orifice law's constants are

    K = (2 / (g + 1))^((g + 1) / (2 (g - 1))),  c0 = sqrt(g R_s T0),  a = C_d A K c0 / V,

and while the flow is choked the blowdown follows P / P0 = exp(-a t) (isothermal) and
P / P0 = (1 + (g - 1) / 2 a t)^(-2 g / (g - 1)) (adiabatic), with T / T0 = (P / P0)^((g -
1) / g) on the isentrope.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import softbody as sb
from softbody.gas import AIR_MOLAR_MASS
from softbody.gas import GAS_CONSTANT as R

GAMMA = 1.4
RS = R / AIR_MOLAR_MASS
K = (2 / (GAMMA + 1)) ** ((GAMMA + 1) / (2 * (GAMMA - 1)))
RADIUS = 0.1
P_AMBIENT = 1.0e5


def _vessel(builder, *, temperature=300.0, process="isothermal", center=(0, 0, 0),
            ambient=P_AMBIENT, pinned=True, damping=0.5):  # fmt: skip
    """A sphere holding an ideal gas (its amount set later by _fill); every vertex pinned
    (a rigid vessel) unless `pinned` is False. Returns its body index."""
    mesh = sb.icosphere(2, radius=RADIUS, center=center)
    return builder.add_soft_body(
        mesh, mass=0.05, stiffness=2000.0, damping=damping,
        gas=sb.Gas.ideal(1.0, temperature, process=process, ambient_pressure=ambient),
        pinned=np.arange(len(mesh.vertices)) if pinned else None,
    )  # fmt: skip


def _model(build):
    """A model from build(builder) -> extra, with each body's gas scaled to its pressure."""
    builder = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    extra = build(builder)
    return builder.finalize(), extra


def _fill(model, state, pressures):
    """Set each body's amount so its gas is at `pressures` [Pa] (B,) at the state's
    volume and temperature: n = P V / (R T)."""
    volume = sb.body_volume(model, state)
    state.body_gas_moles[:] = np.asarray(pressures) * volume / (R * state.body_gas_temperature)


def _blowdown(process, integrator="rk4", dt=1e-4, steps=500, area=1e-5, cd=0.62):
    def build(b):
        body = _vessel(b, process=process)
        b.add_vent(body, area=area, discharge_coefficient=cd)

    model, _ = _model(build)
    state = model.state()
    _fill(model, state, [5e5])
    sim = sb.Simulator(model, integrator=integrator, dt=dt)
    p0 = sb.body_pressure(model, state)[0]
    times, ratios, temps = [], [], []
    for _ in range(5):
        sim.run(state, steps // 5)
        times.append(state.time)
        ratios.append(sb.body_pressure(model, state)[0] / p0)
        temps.append(state.body_gas_temperature[0])
    a = cd * area * K * np.sqrt(GAMMA * RS * 300.0) / model.body_rest_volume[0]
    return np.array(times), np.array(ratios), np.array(temps), a


def test_isothermal_blowdown_while_choked_is_exponential():
    """Rigid vessel, isothermal gas venting choked (P_a / P > 0.53 never reached):
    P / P0 = exp(-a t), a = C_d A K c0 / V; RK4 at dt = 1e-4 s with a ~ 0.5 / s leaves an
    error of order (a dt)^4, far below the 1e-9 asked. T stays T0."""
    t, ratio, temps, a = _blowdown("isothermal")
    assert np.all(ratio > P_AMBIENT / 5e5 / 0.5283)  # still choked
    np.testing.assert_allclose(ratio, np.exp(-a * t), rtol=1e-9)
    np.testing.assert_array_equal(temps, 300.0)


def test_adiabatic_blowdown_follows_the_isentrope():
    """Rigid vessel, adiabatic gas venting choked: P / P0 = (1 + (g - 1) / 2 a t)^(-2g /
    (g - 1)) and T / T0 = (P / P0)^((g - 1) / g) (the gas left inside expands
    isentropically); RK4, error far below 1e-9."""
    t, ratio, temps, a = _blowdown("adiabatic")
    expected = (1 + 0.5 * (GAMMA - 1) * a * t) ** (-2 * GAMMA / (GAMMA - 1))
    np.testing.assert_allclose(ratio, expected, rtol=1e-9)
    np.testing.assert_allclose(temps / 300.0, ratio ** ((GAMMA - 1) / GAMMA), rtol=1e-9)


@pytest.mark.parametrize(
    ("integrator", "order"),
    [("euler", 1), ("symplectic_euler", 1), ("midpoint", 2), ("velocity_verlet", 2),
     ("rk4", 4)],
)  # fmt: skip
def test_each_scheme_integrates_the_gas_with_its_order(integrator, order):
    """The adiabatic blowdown's error at t = 1 s against its closed form falls as dt^p for
    each explicit scheme's order p (gas_state.hpp: Euler and symplectic Euler first order,
    midpoint and velocity Verlet (Heun) second, RK4 fourth): the error ratio between dt
    and dt / 2 is 2^p within 25% (the asymptotic regime at a dt ~ 0.05)."""
    errors = []
    for dt in (0.1, 0.05):
        steps = round(1.0 / dt)
        t, ratio, _, a = _blowdown("adiabatic", integrator, dt, steps, area=1.6e-5)
        expected = (1 + 0.5 * (GAMMA - 1) * a * t[-1]) ** (-2 * GAMMA / (GAMMA - 1))
        assert ratio[-1] > P_AMBIENT / 5e5 / 0.5283  # still choked
        errors.append(abs(ratio[-1] - expected))
    observed = errors[0] / errors[1]
    assert 2**order * 0.75 < observed < 2**order * 1.25, observed


def _two_chambers(process="isothermal", pinned=True, area=2e-5, pressures=(3e5, 1.2e5)):
    def build(b):
        a = _vessel(b, process=process, pinned=pinned)
        c = _vessel(b, process=process, pinned=pinned, center=(0.3, 0, 0))
        b.add_orifice(a, c, area=area)

    model, _ = _model(build)
    state = model.state()
    _fill(model, state, pressures)
    return model, state


@pytest.mark.parametrize("process", ["isothermal", "adiabatic"])
def test_two_chambers_conserve_gas_and_equalise(process):
    """Two rigid chambers joined by an orifice: the total amount n_a + n_b is conserved to
    round-off (every mole one side loses the other gains, in every stage) and the
    pressures meet: after many time constants they agree to 1e-6 of their value and never
    cross (the flow tapers linearly near r = 1 and the limiter never overshoots
    equality)."""
    model, state = _two_chambers(process)
    total = state.body_gas_moles.sum()
    sim = sb.Simulator(model, integrator="rk4", dt=1e-3)
    gaps = []
    for _ in range(40):
        sim.run(state, 50)
        p = sb.body_pressure(model, state)
        gaps.append(p[0] - p[1])
        np.testing.assert_allclose(state.body_gas_moles.sum(), total, rtol=1e-14)
    assert np.all(np.array(gaps) >= 0.0)  # the high side stays high: no chattering
    p = sb.body_pressure(model, state)
    assert abs(p[0] - p[1]) < 1e-6 * p.mean()
    if process == "isothermal":  # equal volumes and temperatures: the mean amount each
        np.testing.assert_allclose(state.body_gas_moles, total / 2, rtol=1e-6)


@pytest.mark.parametrize(
    "integrator",
    ["rk4", "symplectic_euler", "velocity_verlet", "implicit_euler", "bdf2", "projective",
     "xpbd"],
)
def test_every_solver_conserves_gas_between_moving_chambers(integrator):
    """Two free, elastic balloons joined by an orifice, the gas adiabatic: whatever the
    solver (explicit Euler and midpoint amplify the balloons' vibration at any step and
    have their gas checked on the rigid vessel above), the total amount is conserved to
    round-off while the balloons move and the gas flows (gas_state.hpp: flows applied to
    both sides alike, explicitly in the implicit solvers, projective dynamics and xpbd's
    substeps); the amounts stay positive."""
    model, state = _two_chambers("adiabatic", pinned=False, pressures=(1.6e5, 1.1e5))
    total = state.body_gas_moles.sum()
    sim = sb.Simulator(model, integrator=integrator, dt=2e-5)
    sim.run(state, 200)
    np.testing.assert_allclose(state.body_gas_moles.sum(), total, rtol=1e-13)
    assert np.all(state.body_gas_moles > 0)
    assert state.body_gas_moles[0] < total / 2 * 1.6 / 1.35  # gas moved from 0 to 1


def test_inflator_mass_and_heat_in_a_rigid_adiabatic_vessel():
    """An inflator delivering mdot [kg/s] at T_in into a rigid adiabatic vessel: the mass
    is m = m0 + mdot t and the first law gives m T = m0 T0 + g T_in (m - m0) (internal
    energy c_v m T gains the enthalpy c_p T_in dm). Exact for the scheme (the rates are
    constant in n and linear in the product n T): RK4 to 1e-10."""
    mdot, t_in = 2e-4, 500.0

    def build(b):
        body = _vessel(b, process="adiabatic")
        b.add_inflator(body, mass_flow=mdot, temperature=t_in)

    model, _ = _model(build)
    state = model.state()
    _fill(model, state, [1e5])
    m0 = state.body_gas_moles[0] * AIR_MOLAR_MASS
    sim = sb.Simulator(model, integrator="rk4", dt=1e-3)
    sim.run(state, 500)
    m = state.body_gas_moles[0] * AIR_MOLAR_MASS
    np.testing.assert_allclose(m, m0 + mdot * state.time, rtol=1e-12)
    expected_t = (m0 * 300.0 + GAMMA * t_in * (m - m0)) / m
    np.testing.assert_allclose(state.body_gas_temperature[0], expected_t, rtol=1e-10)


def test_unchoked_vent_matches_the_orifice_ode():
    """A rigid isothermal vessel just above the ambient pressure vents subsonically:
    the pressure follows dP/dt = -(R T / (M V)) mdot(P), mdot the subsonic orifice law
    (core/terms/flows.hpp), solved independently here by SciPy (solve_ivp, rtol 1e-12).
    The pressure stays below the taper (r = 0.9999) until the end checked."""
    area, cd, t_gas = 1e-5, 0.62, 300.0

    def build(b):
        body = _vessel(b)
        b.add_vent(body, area=area, discharge_coefficient=cd)

    model, _ = _model(build)
    state = model.state()
    _fill(model, state, [1.3e5])
    volume = model.body_rest_volume[0]

    def rate(_, y):
        p = y[0]
        r = P_AMBIENT / p
        flux = cd * area * p * np.sqrt(
            2 * GAMMA / ((GAMMA - 1) * RS * t_gas) * (r ** (2 / GAMMA) - r ** ((GAMMA + 1) / GAMMA))
        )
        return [-R * t_gas / (AIR_MOLAR_MASS * volume) * flux]

    p0 = sb.body_pressure(model, state)[0]
    sim = sb.Simulator(model, integrator="rk4", dt=1e-3)
    sim.run(state, 100)
    solution = solve_ivp(rate, (0, state.time), [p0], rtol=1e-12, atol=1e-6)
    p_end = sb.body_pressure(model, state)[0]
    assert P_AMBIENT / p_end < 0.9999
    np.testing.assert_allclose(p_end, solution.y[0, -1], rtol=1e-8)


def test_vent_opens_at_its_pressure_and_stays_open():
    """A vent with an opening pressure stays shut while the gauge pressure is below it (no
    gas leaves), opens when an inflator raises the pressure past it, latches
    (``State.vent_open``) and keeps venting after the inflator stops, down to the
    ambient pressure."""
    def build(b):
        body = _vessel(b)
        b.add_inflator(body, mass_flow=[(0.0, 1e-2), (0.2, 1e-2), (0.2001, 0.0)],
                       temperature=300.0)  # fmt: skip
        b.add_vent(body, area=2e-5, opening_pressure=2.0e4)
        return body

    model, _ = _model(build)
    state = model.state()
    _fill(model, state, [1.05e5])
    sim = sb.Simulator(model, integrator="rk4", dt=1e-3)
    sim.run(state, 20)  # 0.02 s: shut, gauge 5 kPa plus 4% more gas
    n_in = 1e-2 * 0.02 / AIR_MOLAR_MASS
    assert state.vent_open[0] == 0.0
    n0 = 1.05e5 * model.body_rest_volume[0] / (R * 300.0)
    np.testing.assert_allclose(state.body_gas_moles[0], n0 + n_in, rtol=1e-10)
    sim.run(state, 980)
    assert state.vent_open[0] == 1.0
    assert sb.body_pressure(model, state)[0] < 1.05 * P_AMBIENT  # vented after the inflator


def test_a_huge_vent_never_drives_the_amount_negative():
    """A vent of 1 m^2 on a 4-litre vessel empties it in far less than a step: the limiter
    moves at most the gas that brings it to the ambient pressure per step, so the amount
    falls to the ambient amount and never below (no negative amount, no chattering): with
    RK4's stages each limited, a step closes about half of the remaining difference."""
    def build(b):
        body = _vessel(b)
        b.add_vent(body, area=1.0)

    model, _ = _model(build)
    state = model.state()
    _fill(model, state, [5e5])
    sim = sb.Simulator(model, integrator="rk4", dt=1e-3)
    pressures = []
    for _ in range(40):
        sim.run(state, 1)
        pressures.append(sb.body_pressure(model, state)[0])
    assert np.all(np.array(pressures) >= P_AMBIENT * (1 - 1e-12))
    np.testing.assert_allclose(pressures[-1], P_AMBIENT, rtol=1e-6)


def test_control_closes_a_valve():
    """Control.vent_area = 0 closes a vent for that call (the amount stays exactly), and
    NaN gives it back its own area."""
    def build(b):
        body = _vessel(b)
        b.add_vent(body, area=1e-5)

    model, _ = _model(build)
    state = model.state()
    _fill(model, state, [3e5])
    n0 = state.body_gas_moles[0]
    sim = sb.Simulator(model, integrator="rk4", dt=1e-3)
    control = model.control()
    control.vent_area = np.array([0.0])
    sim.run(state, 10, control)
    assert state.body_gas_moles[0] == n0
    control.vent_area = np.array([np.nan])
    sim.run(state, 10, control)
    assert state.body_gas_moles[0] < n0


def test_pressure_and_energy_read_the_state_gas():
    """P = n R T / V from the state: doubling ``state.body_gas_moles`` of an isothermal
    body doubles its pressure; an adiabatic gas's energy is its internal energy
    n c_v T = n R T / (g - 1) (plus P_a V)."""
    def build(b):
        _vessel(b, ambient=0.0)
        _vessel(b, process="adiabatic", center=(0.3, 0, 0), ambient=0.0)

    model, _ = _model(build)
    state = model.state()
    p = sb.body_pressure(model, state)
    state.body_gas_moles *= 2
    np.testing.assert_allclose(sb.body_pressure(model, state), 2 * p, rtol=1e-14)
    state.body_gas_temperature[1] = 450.0
    energy = sb.energies(model, state).body_gas[1]
    expected = state.body_gas_moles[1] * R * 450.0 / (GAMMA - 1)
    np.testing.assert_allclose(energy, expected, rtol=1e-12)


def test_bad_flow_input_is_refused():
    """Flows refuse what has no meaning, naming the argument: negative areas, an orifice
    from a body to itself, to a cloth or to a prescribed gas, negative or non-finite mass
    flow, unknown bodies, gases of two species."""
    builder = sb.ModelBuilder()
    a = _vessel(builder)
    c = _vessel(builder, center=(0.3, 0, 0))
    fixed = builder.add_soft_body(sb.icosphere(1, 0.1, (0.6, 0, 0)), mass=0.1, stiffness=100.0,
                                  damping=0.0, gas=sb.Gas.fixed_pressure(1e5))  # fmt: skip
    helium = builder.add_soft_body(
        sb.icosphere(1, 0.1, (0.9, 0, 0)), mass=0.1, stiffness=100.0, damping=0.0,
        gas=sb.Gas.ideal(1.0, 300.0, molar_mass=0.004, gamma=5 / 3),
    )  # fmt: skip
    cases = [
        (lambda: builder.add_vent(a, area=-1.0), "vent area"),
        (lambda: builder.add_vent(a, area=1e-4, discharge_coefficient=1.5), "discharge"),
        (lambda: builder.add_vent(7, area=1e-4), "vent body 7"),
        (lambda: builder.add_orifice(a, a, area=1e-4), "twice"),
        (lambda: builder.add_orifice(a, fixed, area=1e-4), "prescribed"),
        (lambda: builder.add_orifice(a, helium, area=1e-4), "different gases"),
        (lambda: builder.add_orifice(a, c, area=float("nan")), "orifice area"),
        (lambda: builder.add_inflator(a, mass_flow=-1.0, temperature=300.0), "mass_flow"),
        (lambda: builder.add_inflator(a, mass_flow=[(0, 1), (0, 2)], temperature=300.0),
         "increase"),
        (lambda: builder.add_inflator(a, mass_flow=[(0, float("inf"))], temperature=300.0),
         "infinite"),
        (lambda: builder.add_inflator(a, mass_flow=1e-3, temperature=0.0), "temperature"),
        (lambda: builder.add_leak(a, coefficient=-1e-9), "leak coefficient"),
        (lambda: sb.Gas.ideal(1.0, 300.0, process="polytropic"), "process"),
    ]  # fmt: skip
    for call, words in cases:
        with pytest.raises(ValueError, match=words):
            call()
    cloth = builder.add_cloth(sb.rectangle(), mass=0.01, stiffness=10.0, damping=0.0)
    with pytest.raises(ValueError, match="cloth"):
        builder.add_vent(cloth, area=1e-4)
    with pytest.raises(ValueError, match="cloth"):
        builder.add_orifice(a, cloth, area=1e-4)


def test_fabric_leak_decays_exponentially():
    """A rigid isothermal vessel leaking through its fabric, mdot = c A (P - P_a): the
    gauge pressure decays as exp(-k t) with k = R T c A / (M V), A the vessel's area
    (core/terms/flows.hpp, LeakTerm); RK4 at k dt = 0.01, error far below 1e-9."""
    coefficient = 1e-7

    def build(b):
        body = _vessel(b)
        b.add_leak(body, coefficient=coefficient)

    model, _ = _model(build)
    state = model.state()
    _fill(model, state, [1.5e5])
    area = sb.body_area(model, state)[0]
    k = R * 300.0 * coefficient * area / (AIR_MOLAR_MASS * model.body_rest_volume[0])
    dt = 0.01 / k
    sim = sb.Simulator(model, integrator="rk4", dt=dt)
    sim.run(state, 100)
    gauge = sb.body_pressure(model, state)[0] - P_AMBIENT
    np.testing.assert_allclose(gauge, 0.5e5 * np.exp(-k * state.time), rtol=1e-9)


@pytest.mark.parametrize("integrator", ["implicit_euler", "bdf2", "projective"])
def test_implicit_solvers_take_the_flows_to_first_order(integrator):
    """The implicit schemes and projective dynamics step the gas by forward Euler with the
    rates at each step's start (gas_state.hpp): the isothermal blowdown's error at t = 1 s
    against exp(-a t) halves with dt (first order, ratio 2 within 15%)."""
    errors = []
    for dt in (0.02, 0.01):
        t, ratio, _, a = _blowdown("isothermal", integrator, dt, round(1.0 / dt), area=1.6e-5)
        errors.append(abs(ratio[-1] - np.exp(-a * t[-1])))
    assert 2 * 0.85 < errors[0] / errors[1] < 2 * 1.15, errors


def test_adiabatic_energy_bookkeeping_of_a_venting_balloon():
    """A free, undamped elastic balloon of adiabatic gas vents to vacuum while it
    vibrates: the first law of the open system makes kinetic + elastic + internal energy
    n c_v T fall by exactly the enthalpy that left, E(t) + int c_p T dn_out = E(0)
    (c_p = g R / (g - 1) per mole). RK4 at dt = 1e-5 s, the enthalpy summed by the
    trapezoid rule over steps: the residual is under 1e-3 of the enthalpy that left (it
    falls tenfold at dt / 2)."""
    def build(b):
        body = _vessel(b, process="adiabatic", pinned=False, damping=0.0, ambient=0.0)
        b.add_vent(body, area=1e-6)

    model, _ = _model(build)
    state = model.state()
    _fill(model, state, [1.6e5])
    sim = sb.Simulator(model, integrator="rk4", dt=1e-5)
    cp = GAMMA * R / (GAMMA - 1)
    e0 = sb.energies(model, state).total
    n, t = state.body_gas_moles[0], state.body_gas_temperature[0]
    enthalpy = 0.0
    for _ in range(1000):
        sim.run(state, 1)
        n1, t1 = state.body_gas_moles[0], state.body_gas_temperature[0]
        enthalpy += cp * 0.5 * (t + t1) * (n - n1)
        n, t = n1, t1
    assert enthalpy > 0.1  # J: a real flow
    residual = sb.energies(model, state).total + enthalpy - e0
    assert abs(residual) < 1e-3 * enthalpy, residual


def test_a_control_value_holds_for_its_call_and_a_schedule_sets_the_amount():
    """A Control's nRT prescribes a body's gas for its call only: the state's amount stays
    the body's own (a later call without it reads the model's value again), and no gas
    flows through the body's vent meanwhile. A scheduled body's amount follows its
    schedule: n = nRT(t) / (R T)."""
    builder = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    vented = _vessel(builder)
    builder.add_vent(vented, area=1e-5)
    builder.add_soft_body(
        sb.icosphere(1, 0.1, (0.4, 0, 0)), mass=0.05, stiffness=2000.0, damping=0.5,
        gas=sb.Gas.isothermal(400.0, schedule=[(0.0, 400.0), (0.01, 600.0)]),
        pinned=np.arange(42),
    )  # fmt: skip
    model = builder.finalize()
    state = model.state()
    _fill(model, state, [3e5, sb.body_pressure(model, state)[1]])
    n0 = state.body_gas_moles[0]
    control = model.control()
    control.body_gas_nrt[0] = 500.0
    sim = sb.Simulator(model, integrator="rk4", dt=1e-3)
    sim.run(state, 20, control)
    assert state.body_gas_moles[0] == n0
    np.testing.assert_allclose(
        state.body_gas_moles[1], 600.0 / (R * state.body_gas_temperature[1]), rtol=1e-14
    )
    sim.run(state, 1)
    assert state.body_gas_moles[0] < n0


def test_symplectic_euler_fused_pass_steps_the_gas_as_the_general_step():
    """Symplectic Euler's fused pass (taken when every force is one it covers; the flows
    add none) steps the gas as the general step does: a vented, elastic balloon run both
    ways (the general step forced by a grab spring of zero stiffness and damping, which
    adds exactly 0 N) ends with the same positions and gas to the last bit."""
    builder = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    body = _vessel(builder, process="adiabatic", pinned=False)
    builder.add_vent(body, area=1e-6)
    model = builder.finalize()
    start = model.state()
    _fill(model, start, [1.5e5])
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=2e-5)
    fused, general = start.copy(), start.copy()
    sim.run(fused, 300)
    control = model.control()
    control.grab_particle, control.grab_target = 0, np.zeros(3)
    assert "grab" in sb.diagnostics.active_terms(model, control)
    sim.run(general, 300, control)
    assert fused.body_gas_moles[0] < start.body_gas_moles[0]  # it vented
    np.testing.assert_array_equal(fused.particle_q, general.particle_q)
    np.testing.assert_array_equal(fused.body_gas_moles, general.body_gas_moles)
    np.testing.assert_array_equal(fused.body_gas_temperature, general.body_gas_temperature)


@pytest.mark.parametrize("pressure", [5e5, 1.5e5, 1.0003e5, 1.00005e5, 0.6e5])
def test_core_flows_match_the_reference_orifice_law(pressure):
    """body_gas_flows (the core's vent law) against softbody.reference.flows: choked
    (5 bar into 1), subsonic (1.5 bar and 30 Pa above the ambient), in the linear taper
    (5 Pa above) and backflow from the ambient at its temperature (0.6 bar inside), to
    round-off."""
    from softbody.reference.flows import orifice_mass_flow

    def build(b):
        body = _vessel(b, temperature=350.0)
        b.add_vent(body, area=3e-5, discharge_coefficient=0.7)

    model, _ = _model(build)
    state = model.state()
    _fill(model, state, [pressure])
    flows = sb.body_gas_flows(model, state)
    # near r = 1 the law reads 1 - r: round-off in the pressures grows by 1 / (1 - r)
    rtol = max(1e-12, 1e-14 / abs(1 - P_AMBIENT / pressure))
    if pressure > P_AMBIENT:
        expected = orifice_mass_flow(0.7, 3e-5, pressure, 350.0, P_AMBIENT, GAMMA, AIR_MOLAR_MASS)
        np.testing.assert_allclose(flows.mass_outflow, [expected], rtol=rtol)
        np.testing.assert_array_equal(flows.inflow, [0.0])
    else:
        expected = orifice_mass_flow(0.7, 3e-5, P_AMBIENT, 293.15, pressure, GAMMA, AIR_MOLAR_MASS)
        np.testing.assert_allclose(flows.mass_inflow, [expected], rtol=rtol)
        np.testing.assert_allclose(flows.inflow_temperature, [293.15], rtol=1e-14)
        np.testing.assert_array_equal(flows.outflow, [0.0])


def test_the_orifice_law_is_continuous_and_falls_to_zero_at_equal_pressure():
    """The orifice law (reference): the subsonic branch meets the choked flow at the
    critical ratio r_c = (2 / (g + 1))^(g / (g - 1)) and the linear taper at r = 0.9999
    (continuous), the flow falls monotonically in r and is exactly 0 at r = 1
    with a finite slope there (no chattering between two chambers at equal pressure)."""
    from softbody.reference.flows import LINEAR, orifice_mass_flow

    def flow(r):
        return orifice_mass_flow(0.62, 1e-4, 2e5, 300.0, r * 2e5, GAMMA, AIR_MOLAR_MASS)

    critical = (2 / (GAMMA + 1)) ** (GAMMA / (GAMMA - 1))
    for r in (critical, LINEAR):
        # either side of the joint, 2e-13 apart in r: the flow's relative slope there is at
        # most 1 / (1 - r) = 1e4, so a continuous law differs by under 1e-8 (a jump: more)
        np.testing.assert_allclose(flow(r * (1 - 1e-13)), flow(r * (1 + 1e-13)), rtol=1e-8)
    r = np.linspace(0.0, 1.0, 2001)
    values = flow(r)
    assert np.all(np.diff(values) <= 1e-15 * values[0])
    assert values[-1] == 0.0
    slope = flow(1.0 - 1e-6) / 1e-6  # inside the taper: the chord to r = 1
    np.testing.assert_allclose(slope, flow(LINEAR) / (1 - LINEAR), rtol=1e-8)
