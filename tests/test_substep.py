"""XPBD with small steps (integrator "xpbd", softbody.solvers.substep): its convergence to
the springs' own dynamics, its physics checks at the default settings and 1/60 s, its
options and the colouring it sweeps in."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import softbody as sb
from conftest import ball_model, deformed, uniform_scaling_stationary
from softbody import _core, core
from softbody.core import core_model
from softbody.solvers.substep import DEFAULT_SUBSTEPS, SubstepSolver, colour_springs

G = 9.81
FRAME = 1.0 / 60.0
#: the over-relaxed setting docs/guide/integrators.md gives for large meshes at 1/60 s
RELAXED = {"xpbd_substeps": 12, "xpbd_iterations": 4, "xpbd_relaxation": 1.9}
#: the physics checks run at the defaults and at RELAXED
SETTINGS = pytest.mark.parametrize("setting", [{}, RELAXED], ids=["default", "relaxed"])


def xpbd(model: sb.Model, dt: float = FRAME, **options) -> sb.Simulator:
    """An xpbd Simulator, its stability note silenced (tests that hold at any step)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        return sb.Simulator(model, integrator="xpbd", dt=dt, **options)


@pytest.mark.parametrize(
    "passes", [{}, {"xpbd_iterations": 3, "xpbd_relaxation": 1.9}], ids=["plain", "relaxed"]
)
def test_converges_to_velocity_verlet_at_first_order(passes):
    """Reference: XPBD is first order in the substep h (Macklin et al. 2019): with the
    compliance 1 / k its constraint pass gives the springs' forces as h -> 0. A ball
    (162 vertices, k = 500 N/m, nRT = 300 J, undamped) started 3% larger than its rest
    shape, 0.5 s at 1/60 s steps: the largest position difference from velocity Verlet at
    a step 400x smaller falls at each doubling of the substeps (32 -> 256) by a factor
    near 2 (> 1.5), and is below 3 mm at 256; with one pass per substep and with three,
    the later two over-relaxed (omega 1.9), which changes the substep's converged solution
    in nothing."""
    model = ball_model(subdivisions=2)

    def start() -> sb.State:
        state = model.state()
        state.particle_q *= 1.03
        return state

    reference = start()
    sb.Simulator(model, integrator="velocity_verlet", dt=0.5 / 12_000).run(reference, 12_000)
    errors = []
    for substeps in (32, 64, 128, 256):
        state = start()
        xpbd(model, xpbd_substeps=substeps, **passes).run(state, 30)
        errors.append(np.abs(state.particle_q - reference.particle_q).max())
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all(ratios > 1.5), (errors, ratios)
    assert errors[-1] < 3e-3


def hanging_ball() -> sb.Model:
    """The hanging-ball scene's middle body (paper, Figure 1 right): 162 vertices, r 0.5 m,
    1 kg, k = 30 N/m, c = 0.3 N s/m, bending 1.0, nRT = 4 J, pinned above y = 1.425 m."""
    builder = sb.ModelBuilder()
    mesh = sb.icosphere(2, radius=0.5, center=(0.0, 1.0, 0.0))
    builder.add_soft_body(
        mesh, mass=1.0, stiffness=30.0, damping=0.3, bend_stiffness=1.0, bend_damping=0.03,
        gas=sb.Gas.isothermal(4.0), pinned=np.flatnonzero(mesh.vertices[:, 1] > 1.425),
    )  # fmt: skip
    return builder.finalize()


@SETTINGS
def test_hanging_ball_sags_as_velocity_verlet_does(setting):
    """Reference: the static equilibrium under gravity, converged (velocity Verlet at
    1 ms): the hanging ball's sag (its centre of mass's drop, mean over the 10th second)
    at 1/60 s, at the default settings and at RELAXED, is within 5% of it."""
    model = hanging_ball()
    start = sb.body_center_of_mass(model, model.state())[0, 1]

    def sag(sim: sb.Simulator) -> float:
        state = model.state()
        sim.advance(state, 9.0)
        heights = []
        for _ in range(60):
            sim.advance(state, FRAME)
            heights.append(sb.body_center_of_mass(model, state)[0, 1])
        return start - float(np.mean(heights))

    converged = sag(sb.Simulator(model, integrator="velocity_verlet", dt=1e-3))
    assert converged > 0.05  # it sags [m]
    assert sag(xpbd(model, **setting)) == pytest.approx(converged, rel=0.05)


def breathing_frequency(model: sb.Model, sim: sb.Simulator, scale: float) -> float:
    """The volume's oscillation frequency [Hz] over 3 s from the rest shape scaled by
    ``scale``: the mean period between its upward crossings of the mean volume (linear
    interpolation between frames)."""
    state = model.state()
    state.particle_q *= scale
    volumes = []
    while state.time < 3.0 - 1e-9:
        sim.advance(state, FRAME)
        volumes.append(sb.body_volume(model, state)[0])
    v = np.array(volumes) - np.mean(volumes)
    up = np.flatnonzero((v[:-1] < 0) & (v[1:] >= 0))
    crossings = (up + v[up] / (v[up] - v[up + 1])) * FRAME
    assert len(crossings) >= 3
    return (len(crossings) - 1) / (crossings[-1] - crossings[0])


@SETTINGS
def test_breathing_mode_frequency_as_velocity_verlet(setting):
    """Reference: the breathing mode, converged (velocity Verlet at 1 ms), of a free ball
    of the hanging ball's material (162 vertices, k = 30 N/m, c = 0.3, nRT = 4 J, bending
    1.0) started 2% beyond its stationary uniform scale (conftest.uniform_scaling_stationary):
    its frequency at 1/60 s, at the default settings and at RELAXED, is within 5% of it."""
    model = ball_model(
        subdivisions=2, radius=0.5, stiffness=30.0, damping=0.3, gas=4.0, bend_stiffness=1.0,
        bend_damping=0.03,
    )  # fmt: skip
    scale = 1.02 * uniform_scaling_stationary(30.0, model.spring_rest_length, 4.0)
    converged = breathing_frequency(
        model, sb.Simulator(model, integrator="velocity_verlet", dt=1e-3), scale
    )
    assert 0.5 < converged < 10.0  # a breathing mode [Hz] resolved at 60 frames a second
    frequency = breathing_frequency(model, xpbd(model, **setting), scale)
    assert frequency == pytest.approx(converged, rel=0.05)


@SETTINGS
def test_free_body_momentum_is_conserved(setting):
    """Reference: Newton's third law. Without gravity or contacts the explicit forces
    (pressure, P dV/dx summed over a closed surface) add to zero and each constraint moves
    its two ends by equal and opposite impulses (w_i m_i = 1, over-relaxed or not), so the
    total momentum of a deformed, spinning, flying ball stays as it was to round-off over
    60 steps, at the default settings and at RELAXED."""
    model = ball_model(subdivisions=2, damping=0.5)
    state = deformed(model, seed=7, amplitude=0.05)
    rng = np.random.default_rng(8)
    drift = np.array([1.0, 2.0, -0.5])  # [m/s]
    state.particle_qd[:] = rng.normal(0.0, 0.5, state.particle_qd.shape) + drift
    mass = model.particle_mass[:, None]
    before = (mass * state.particle_qd).sum(axis=0)
    xpbd(model, **setting).run(state, 60)
    after = (mass * state.particle_qd).sum(axis=0)
    assert np.abs(after - before).max() < 1e-11 * np.abs(mass * state.particle_qd).sum()


@SETTINGS
def test_resting_ball_contact_force_is_its_weight(setting):
    """Reference: static equilibrium, as tests/test_collision.py checks it for midpoint: a
    ball resting on the ground gives it an impulse per second equal to its weight M g
    (collider impulse over 1 s after 3 s of settling), within 2%, at the default settings
    and at RELAXED."""
    builder = sb.ModelBuilder()
    builder.add_soft_body(
        sb.icosphere(2, radius=0.3, center=(0, 0.31, 0)),
        mass=2.0, stiffness=800.0, damping=2.0, gas=200.0,
    )  # fmt: skip
    builder.add_collider(sb.ColliderPlane(restitution=0.0, friction=0.5))
    model = builder.finalize()
    sim = xpbd(model, **setting)
    state = model.state()
    sim.run(state, 180)  # settle for 3 s
    sim.run(state, 60)  # then measure over 1 s
    assert -state.collider_impulse[0, 1] == pytest.approx(2.0 * G * 1.0, rel=0.02)


@SETTINGS
def test_energy_does_not_grow_over_a_long_undamped_run(setting):
    """Reference: the total energy (kinetic + springs + gas) of an undamped free ball is
    conserved by the true dynamics; XPBD, whose constraints act at the predicted positions
    (backward Euler in them), may only lose it: over 20 s at 1/60 s, at the default
    settings and at RELAXED, it never exceeds its start by more than 1e-6 of itself."""
    model = ball_model(subdivisions=2)
    state = deformed(model, seed=3, amplitude=0.03)
    start = sb.energies(model, state).total
    sim = xpbd(model, **setting)
    for _ in range(20):
        sim.run(state, 60)
        assert sb.energies(model, state).total <= start + 1e-6 * abs(start)


def test_simulator_takes_xpbd_and_its_options():
    """Contract: Simulator(model, integrator="xpbd") steps with the SubstepSolver at
    DEFAULT_SUBSTEPS substeps and 1 iteration, reports them in ``options`` (so a copy
    solves the same way), and its stable step is the substeps times the gas's 1 / omega."""
    model = ball_model(subdivisions=1)
    sim = sb.Simulator(model, integrator="xpbd", dt=FRAME)
    assert isinstance(sim.solver, SubstepSolver)
    assert sim.options["xpbd_substeps"] == DEFAULT_SUBSTEPS
    assert sim.options["xpbd_iterations"] == 1
    assert sim.options["xpbd_relaxation"] == 1.0
    mode = sim.stiffest_mode
    assert sim.stable_dt == pytest.approx(DEFAULT_SUBSTEPS / max(mode.omega_gas, 1e-300))
    other = sb.Simulator(model, integrator="xpbd", dt=FRAME, xpbd_substeps=4)
    assert other.stable_dt == pytest.approx(sim.stable_dt * 4 / DEFAULT_SUBSTEPS)
    assert sb.Integrator.parse("substep") == sb.Integrator.XPBD


@pytest.mark.parametrize("name", ["xpbd_substeps", "xpbd_iterations"])
@pytest.mark.parametrize("bad", [0, -3, 2.5, True, "8"])
def test_bad_counts_are_refused(name, bad):
    """Contract: the substeps and iterations are integers >= 1; anything else is a
    ValueError naming the option."""
    model = ball_model(subdivisions=1)
    with pytest.raises(ValueError, match=f"{name} must be an integer >= 1"):
        sb.Simulator(model, integrator="xpbd", dt=FRAME, **{name: bad})


@pytest.mark.parametrize("bad", [0.0, 2.0, -0.5, float("nan"), True, "1.5"])
def test_bad_relaxation_is_refused(bad):
    """Contract: xpbd_relaxation is a number in (0, 2), where successive over-relaxation
    converges; anything else is a ValueError naming the option."""
    model = ball_model(subdivisions=1)
    with pytest.raises(ValueError, match="xpbd_relaxation must be a number in"):
        sb.Simulator(model, integrator="xpbd", dt=FRAME, xpbd_relaxation=bad)


def test_colouring_puts_no_particle_twice_in_a_colour():
    """Contract of colour_springs: a permutation of the springs in which no two springs of
    a colour share a particle; an icosphere (valence 5 and 6) takes at most 2 * 6 - 1
    colours, greedy's bound."""
    model = ball_model(subdivisions=3)
    order, ptr = colour_springs(model.spring_indices, model.particle_count)
    assert sorted(order.tolist()) == list(range(model.spring_count))
    assert len(ptr) - 1 <= 11
    for c in range(len(ptr) - 1):
        ends = model.spring_indices[order[ptr[c] : ptr[c + 1]]].ravel()
        assert len(np.unique(ends)) == len(ends)


def test_every_simd_path_steps_as_the_scalar_one():
    """Contract of the constraint pass's lanes (springs::constrain_lanes: each spring's two
    rows loaded and stored whole, transposed in registers): on every instruction set this
    CPU runs, a damped ball with attachments (162 vertices, colours of springs that are not
    whole multiples of the lanes, so the one-by-one tail runs too; 2 passes per substep,
    the second over-relaxed) follows the scalar path's trajectory to round-off (1e-9 m
    after 30 frames: the force passes sum in another order, the constraint arithmetic is
    the same)."""
    builder = sb.ModelBuilder()
    mesh = sb.icosphere(2, radius=0.5, center=(0.0, 1.0, 0.0))
    builder.add_soft_body(mesh, mass=1.0, stiffness=500.0, damping=0.5, gas=sb.Gas.isothermal(50.0))
    for v in (0, 17, 40):
        builder.add_attachment(v, tuple(1.1 * mesh.vertices[v]), stiffness=80.0, damping=0.4)
    model = builder.finalize()
    kick = 0.02 * np.random.default_rng(3).standard_normal((model.particle_count, 3))

    def run() -> np.ndarray:
        state = model.state()
        state.particle_q = state.particle_q + kick
        xpbd(model, xpbd_substeps=8, xpbd_iterations=2, xpbd_relaxation=1.5).run(state, 30)
        return state.particle_q

    before = core.simd_path()
    try:
        core.use_simd("scalar")
        reference = run()
        for name in core.simd_paths():
            core.use_simd(name)
            assert np.abs(run() - reference).max() < 1e-9, name
    finally:
        core.use_simd(before)
    assert np.abs(reference - model.state().particle_q).max() > 0.05  # it moved


def test_core_refuses_a_colouring_that_shares_a_particle():
    """Contract of _core.SubstepSolver: a colour whose springs share a particle (which a
    colour-parallel sweep would race on), an order that is not a permutation, or offsets
    that do not cover the springs are refused with a ValueError saying which."""
    model = ball_model(subdivisions=1)
    core = core_model(model)
    s = model.spring_count
    order = np.arange(s, dtype=np.int64)
    with pytest.raises(ValueError, match="colour 0 holds two springs at particle"):
        _core.SubstepSolver(core, order, np.array([0, s], dtype=np.int64))
    with pytest.raises(ValueError, match="not a permutation"):
        _core.SubstepSolver(core, np.zeros(s, np.int64), np.array([0, s], dtype=np.int64))
    with pytest.raises(ValueError, match="colour_ptr must run from 0"):
        _core.SubstepSolver(core, order, np.array([0, s - 1], dtype=np.int64))


def test_a_blow_up_is_reported_and_the_step_undone():
    """Contract shared by every solver: a step that blows up (here one substep per 1/60 s
    on a gas 1,000x too stiff for it) raises SimulationError and leaves the state at the
    last good step, its time a whole number of steps."""
    model = ball_model(subdivisions=2, gas=300_000.0)
    sim = xpbd(model, xpbd_substeps=1)
    state = model.state()
    with pytest.raises(sb.SimulationError):
        sim.run(state, 600)
    assert np.isfinite(state.particle_q).all()
    assert state.time == pytest.approx(state.step_count * FRAME)


def hung_particles() -> tuple[sb.Model, int, int, int]:
    """A 0.5 kg particle on an attachment (k = 100 N/m, c = 2) and a chain of two 0.2 kg
    particles hung from a pinned one by springs of 50 N/m (c = 1): the model and the
    particles (attached, middle, lower)."""
    builder = sb.ModelBuilder()
    a = builder.add_particle((0.0, -0.3, 0.0), mass=0.5)
    builder.add_attachment(a, (0.0, 0.0, 0.0), stiffness=100.0, damping=2.0, rest_length=0.3)
    top = builder.add_particle((1.0, 0.0, 0.0), mass=1.0, pinned=True)
    mid = builder.add_particle((1.0, -0.2, 0.0), mass=0.2)
    low = builder.add_particle((1.0, -0.4, 0.0), mass=0.2)
    builder.add_spring(top, mid, stiffness=50.0, damping=1.0, rest_length=0.2)
    builder.add_spring(mid, low, stiffness=50.0, damping=1.0, rest_length=0.2)
    return builder.finalize(), a, mid, low


def test_relaxation_keeps_a_lone_constraint_exact():
    """Reference: Hooke's static equilibrium, as in the test below. The over-relaxation
    acts on the passes after a substep's first only, so the attachment (a lone constraint,
    solved exactly by the first pass: the later passes' steps are zero) still settles at
    its stretch m g / k (4.905 cm) to 1e-6 m with 3 passes at omega 1.9, at 4 and 16
    substeps (relaxing the first pass too would scale that stretch by about 1 / omega).
    The chain's two coupled links, which a truncated sweep leaves off their stretch, settle
    within 1 mm of it at 4 substeps and 0.2 mm at 16 (measured 0.80 and 0.17 mm)."""
    model, a, mid, low = hung_particles()
    for substeps, tolerance in ((4, 1e-3), (16, 2e-4)):
        state = model.state()
        sim = xpbd(model, xpbd_substeps=substeps, xpbd_iterations=3, xpbd_relaxation=1.9)
        sim.run(state, 1200)
        q = state.particle_q
        assert -0.3 - q[a, 1] == pytest.approx(0.5 * G / 100.0, abs=1e-6)
        assert q[mid, 1] - q[low, 1] - 0.2 == pytest.approx(0.2 * G / 50.0, abs=tolerance)
        assert -0.2 - q[mid, 1] == pytest.approx(0.4 * G / 50.0, abs=tolerance)


def test_attachment_and_chain_hang_at_their_static_stretch():
    """Reference: Hooke's static equilibrium, each spring carrying the weight below it. A
    0.5 kg particle on an attachment (k = 100 N/m) and the lower link of a chain of two
    0.2 kg particles hung from a pinned one by springs of 50 N/m settle (damped) at their
    stretch m g / k (4.905 cm, 3.924 cm) to 1e-6 m at any substep count: the fixed point
    of one XPBD pass on a lone constraint is exact (the prediction's h^2 g and the
    correction balance there). The upper link, whose pass runs before the lower one's in
    the sweep, settles beyond its 7.848 cm by the one pass's softness, an excess that
    halves with each doubling of the substeps (first order in h; 1 mm at 4 substeps)."""
    model, a, mid, low = hung_particles()
    excess = []
    for substeps in (4, 8, 16, 32):
        state = model.state()
        xpbd(model, xpbd_substeps=substeps).run(state, 1200)
        q = state.particle_q
        assert -0.3 - q[a, 1] == pytest.approx(0.5 * G / 100.0, abs=1e-6)
        assert q[mid, 1] - q[low, 1] - 0.2 == pytest.approx(0.2 * G / 50.0, abs=1e-6)
        excess.append(-0.2 - q[mid, 1] - 0.4 * G / 50.0)
    assert 5e-4 < excess[0] < 2e-3
    ratios = np.array(excess[:-1]) / np.array(excess[1:])
    assert np.all((ratios > 1.8) & (ratios < 2.4)), (excess, ratios)


def test_a_scene_can_name_xpbd():
    """Contract: a scene file's ``[simulation] integrator`` takes "xpbd" (the schema's list
    is the Integrator enum's): the hanging-ball scene with it runs 1 s at 1/60 s."""
    from softbody.scenes import load_scene

    scene = load_scene("hanging-ball", ['simulation.integrator="xpbd"'])
    assert scene.integrator == "xpbd"
    sim = sb.Simulator(scene.model, integrator=scene.integrator, dt=FRAME)
    state = scene.model.state()
    sim.run(state, 60)
    assert np.isfinite(state.particle_q).all()


def test_xpbd_steps_a_damped_membrane_at_its_own_stable_step():
    """xpbd takes membranes explicitly within its substeps, their strain-rate damping too:
    its stable step counts the membrane's stiffness and its damping rate (symplectic Euler
    on a damped mode needs h c < 2), so at dt = "auto" a damped neo-Hookean balloon under
    a fixed pressure settles on the closed-form rising branch, P(s) = A0 H W'(s) / (3 V0
    s^2), within 1e-3 of the stretch (the mesh's uneven triangles; 4e-5 measured). Without
    the damping in the rule the first step blew up."""
    from softbody.membrane import equibiaxial_pressure

    rubber = sb.Membrane.neo_hookean(2e5, 1e-3, damping=0.002)
    builder = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    builder.add_soft_body(sb.icosphere(2, radius=0.2), mass=0.05, membrane=rubber,
                          gas=sb.Gas.fixed_pressure(1000.0))  # fmt: skip
    model = builder.finalize()
    area, volume = model.membrane_rest_area.sum(), model.body_rest_volume[0]
    s = np.linspace(1.0, 1.38, 20001)
    expected = s[np.argmin(np.abs(equibiaxial_pressure(rubber, s, area, volume) - 1000.0))]
    sim = sb.Simulator(model, integrator="xpbd", dt="auto")
    assert sim.stiffest_mode.damping_rate_terms["membrane"] > 0
    state = model.state()
    sim.advance(state, 1.0, progress=False)
    stretch = (sb.body_volume(model, state)[0] / volume) ** (1 / 3)
    assert abs(stretch / expected - 1) < 1e-3
