"""Aerodynamic drag on faces (core/terms/drag.hpp).

The law, per face t with area A_t, unit normal n_t and velocity v_t (its corners' mean):
    F_t = -1/2 rho C_d A_t (v_rel . n_t) |v_rel . n_t| n_t,   v_rel = v_t - wind,
shared equally by the three corners.

Effective area. A body translating at velocity -V y (down) in still air has
v_rel . n = -V n_y on every face, so F_t = 1/2 rho C_d V^2 A_t n_y |n_y| n_t, whose upward
part is 1/2 rho C_d V^2 A_t |n_y|^3: the drag is 1/2 rho C_d V^2 A_eff with
    A_eff = sum_t A_t |n_t . y|^3                  (a mesh, exactly)
    A_eff = R^2 int_0^2pi int_0^pi |cos th|^3 sin th dth dphi
          = 2 pi R^2 * 2 int_0^1 c^3 dc = 2 pi R^2 * 2 * 1/4 = pi R^2   (a sphere).
Each hemisphere gives pi R^2 / 2: the front is pushed (v.n > 0 there), the back pulled
(v.n < 0), and the law acts on both, so C_d here is the usual sphere coefficient on the
frontal area pi R^2. The lateral parts cancel by symmetry and every force on a sphere is
radial, so it has no torque.

Terminal speed. m dV/dt = m g - 1/2 rho C_d A_eff V^2 from rest gives
    V(t) = v_t tanh(g t / v_t),   v_t = sqrt(2 m g / (rho C_d A_eff)).
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

import softbody as sb
from conftest import forces
from softbody import _core
from softbody.core import available_threads
from softbody.sim.control import control_data

RHO = 1.2  # air [kg/m^3]
G = 9.81  # [m/s^2]


def face_areas_normals(q: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Areas (T,) [m^2] and unit normals (T, 3) of the faces at q."""
    x = q[tri]
    area_normal = 0.5 * np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    area = np.linalg.norm(area_normal, axis=1)
    return area, area_normal / area[:, None]


def effective_area(q: np.ndarray, tri: np.ndarray, axis=(0.0, 1.0, 0.0)) -> float:
    """sum_t A_t |n_t . axis|^3 [m^2]: the drag area of the mesh translating along axis."""
    area, n = face_areas_normals(q, tri)
    return float(np.sum(area * np.abs(n @ np.asarray(axis)) ** 3))


def reference_drag(model: sb.Model, q, qd, wind, rho=RHO) -> np.ndarray:
    """The face law written out in NumPy: drag force on each particle (N, 3) [N]."""
    f = np.zeros_like(q)
    for b in range(model.body_count):
        t0, t1 = model.body_tri_range[b]
        tri = model.tri_indices[t0:t1]
        area, n = face_areas_normals(q, tri)
        v_rel = qd[tri].mean(axis=1) - wind
        vn = np.einsum("ij,ij->i", v_rel, n)
        face = -0.5 * rho * model.body_drag_coefficient[b] * (area * vn * np.abs(vn))[:, None] * n
        for corner in range(3):
            np.add.at(f, tri[:, corner], face / 3.0)
    return f


def drag_model(cd=0.5, *, subdivisions=2, radius=0.2, wind=(0.0, 0.0, 0.0), rho=RHO,
               gravity=(0.0, 0.0, 0.0), **kwargs) -> sb.Model:  # fmt: skip
    b = sb.ModelBuilder(gravity=gravity)
    b.set_air(density=rho, wind=wind)
    b.add_soft_body(sb.icosphere(subdivisions, radius=radius), mass=0.005, stiffness=50.0,
                    damping=0.0, gas=1.0, drag_coefficient=cd, **kwargs)  # fmt: skip
    return b.finalize()


def drag_forces(model, state, control=None) -> np.ndarray:
    """Total forces minus the same model's forces in vacuum (air density 0): the drag."""
    import dataclasses

    vacuum = dataclasses.replace(model, air_density=0.0)
    return forces(model, state, control) - forces(vacuum, state, control)


def moving_state(model, velocity, seed=None) -> sb.State:
    state = model.state()
    state.particle_qd[:] = velocity
    if seed is not None:
        rng = np.random.default_rng(seed)
        state.particle_q += rng.uniform(-0.01, 0.01, state.particle_q.shape)
        state.particle_qd += rng.normal(0.0, 1.0, state.particle_qd.shape)
    return state


# -- the law -------------------------------------------------------------------------------
def test_sphere_effective_area_converges_to_pi_r_squared():
    """sum_t A_t |n_y|^3 on icospheres tends to the integral pi R^2 (module docstring):
    the faces lie inside the sphere, so the deficit is second order in the edge length
    and shrinks about 4 times per subdivision; at 10242 vertices it is below 1e-3."""
    radius = 0.2
    deficits = []
    for s in range(2, 6):
        mesh = sb.icosphere(s, radius=radius)
        deficits.append(1.0 - effective_area(mesh.vertices, mesh.faces) / (np.pi * radius**2))
    assert all(d > 0 for d in deficits)
    ratios = np.array(deficits[:-1]) / np.array(deficits[1:])
    assert np.all((ratios > 3.5) & (ratios < 4.5)), ratios
    assert deficits[-1] < 1e-3


def test_core_drag_is_the_face_law():
    """The core's drag (total force minus the vacuum's) equals the face law in NumPy for
    a deformed ball with random velocities in a wind, to round-off (1e-12 of the largest
    force: the sums differ only in order)."""
    wind = np.array([0.7, -0.2, 1.3])
    model = drag_model(0.8, wind=wind)
    state = moving_state(model, (0.3, -1.0, 0.5), seed=1)
    got = drag_forces(model, state)
    want = reference_drag(model, state.particle_q, state.particle_qd, wind)
    assert np.abs(want).max() > 1e-4
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())


def test_control_wind_overrides_the_model_wind_and_nan_keeps_it():
    """Control.wind replaces the model's wind for the call; None keeps the model's."""
    model = drag_model(0.5, wind=(0.0, 0.0, 2.0))
    state = moving_state(model, (0.0, 0.0, 0.0), seed=2)
    gust = np.array([3.0, 0.0, -1.0])
    control = model.control()
    np.testing.assert_array_equal(drag_forces(model, state, control), drag_forces(model, state))
    control.wind = gust
    want = reference_drag(model, state.particle_q, state.particle_qd, gust)
    got = drag_forces(model, state, control)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())


@pytest.mark.parametrize("where", ["model", "control"])
def test_wind_equal_to_the_body_velocity_gives_no_drag(where):
    """A body moving rigidly with the air feels nothing: v_rel = mean(u, u, u) - u is zero
    up to one rounding of the mean (|v_rel| <= 2e-16 |u|, so |F| <= rho C_d A (2e-16 |u|)^2,
    below 1e-30 N), while at rest in the same wind each particle feels ~1e-3 N."""
    u = np.array([1.5, -2.0, 0.75])
    model = drag_model(1.0, wind=u if where == "model" else (0.0, 0.0, 0.0))
    control = model.control()
    if where == "control":
        control.wind = u
    moving = moving_state(model, u)
    assert np.abs(drag_forces(model, moving, control)).max() < 1e-30
    at_rest = moving_state(model, (0.0, 0.0, 0.0))
    assert np.abs(drag_forces(model, at_rest, control)).max() > 1e-4


def test_only_the_velocity_relative_to_the_wind_counts():
    """Galilean invariance: a body at velocity u + w in wind w feels the drag of u in
    still air (bit for bit up to the rounding of u + w - w)."""
    u, w = np.array([0.2, -1.1, 0.4]), np.array([-0.5, 0.3, 2.0])
    still, windy = drag_model(0.6), drag_model(0.6, wind=w)
    a = drag_forces(still, moving_state(still, u))
    b = drag_forces(windy, moving_state(windy, u + w))
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-12 * np.abs(a).max())


def test_drag_on_a_sphere_moving_straight_has_no_torque_and_dissipates():
    """A rigidly translating icosphere: the net drag torque about its centre vanishes (the
    mesh is centrally symmetric, x -> -x maps each face to one with the same force at the
    opposite point, so the torques cancel in pairs; a sphere's pressure forces are
    radial) to round-off, 1e-12 of sum |x_i x F_i|; the drag opposes the motion and its
    power sum F . v is -1/2 rho C_d A_eff(u) |u|^3 (A_eff along u) in still air."""
    rng = np.random.default_rng(3)
    u = rng.normal(size=3)
    model = drag_model(0.5, subdivisions=3)
    state = moving_state(model, u)
    f = drag_forces(model, state)
    x = state.particle_q - state.particle_q.mean(axis=0)
    torque = np.cross(x, f)
    assert np.linalg.norm(torque.sum(axis=0)) < 1e-12 * np.linalg.norm(torque, axis=1).sum()
    speed = np.linalg.norm(u)
    a_eff = effective_area(state.particle_q, model.tri_indices, u / speed)
    power = float(np.sum(f * state.particle_qd))
    np.testing.assert_allclose(power, -0.5 * RHO * 0.5 * a_eff * speed**3, rtol=1e-12)
    assert power < 0


# -- terminal speed --------------------------------------------------------------------------
R, MASS, CD = 0.2, 0.005, 0.5
AMBIENT = 1000.0  # [Pa]


def balloon() -> sb.Model:
    """A 5 g balloon of radius 0.2 m, 642 vertices: gas at the ambient pressure at its rest
    volume (nRT = P_a V0), so it starts in equilibrium at its mesh's shape, and edge
    springs much stiffer than the drag's uneven load (module test docstring)."""
    mesh = sb.icosphere(3, radius=R)
    v0 = float(
        _core.body_volumes(
            mesh.vertices.copy(), mesh.faces.astype(np.int64),
            np.array([[0, mesh.vertex_count]]), np.array([[0, mesh.face_count]]),
            np.zeros(1, dtype=np.int64), np.zeros((1, 2), dtype=np.int64), np.zeros((0, 2)),
        )[0]
    )  # fmt: skip
    b = sb.ModelBuilder(gravity=(0.0, -G, 0.0))
    b.set_air(density=RHO)
    b.add_soft_body(mesh, mass=MASS, stiffness=50.0, damping=5e-4, drag_coefficient=CD,
                    gas=sb.Gas.isothermal(AMBIENT * v0, ambient_pressure=AMBIENT))  # fmt: skip
    return b.finalize()


@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4", "projective"])
def test_balloon_falls_at_its_terminal_speed(integrator):
    """A balloon dropped in still air follows V(t) = v_t tanh(g t / v_t) and settles at
    v_t = sqrt(2 m g / (rho C_d A_eff)) with the mesh's discrete A_eff at rest (its 0.5%
    discretisation deficit against pi R^2 cancels; the sphere's value is checked too).

    Tolerances, relative to v_t (1.14 m/s; g / v_t = 8.6 1/s):
    - on the way (t = 0.1, 0.2, 0.3 s): the scheme's error in V. For the first-order
      symplectic Euler, e' = f'(V) e + dt/2 V'' with f' < 0, so |e| <= dt/2 int |V''| dt
      = dt/2 (V'(0) - V'(t)) <= dt g / 2 = 1e-3 m/s (9e-4 of v_t) at dt = 2e-4 s; RK4's
      is far smaller. Projective dynamics is backward Euler, first order with the same
      bound (its local error is -dt^2/2 V''), the drag taken at the previous iterate
      within each step: its two iterations leave (dt f')^2 = 1e-5 of each step's velocity
      change unconverged (f' = -2 g / v_t, the drag's slope per unit mass). Plus the
      elastic lag: while the drag builds up, its uneven load deforms the balloon and its
      particles' speeds spread by up to 8e-4 of v_t (checked below 1e-3); the quadratic
      drag then departs from the rigid body's by a fraction of that, 1.3e-4 of v_t at
      t = 0.2 s for RK4, the same at dt = 1e-4 s (so not the scheme's): allowed 2e-4 of
      v_t.
    - at t = 0.8 s: the approach leaves 1 - tanh(x) ~ 2 exp(-2x) = 2e-6 (x = g t / v_t =
      6.9), and dt none (a one-step scheme's fixed point of dV/dt = f(V) is f = 0 itself;
      the transient's dt error decays with the approach). The balloon stays round: the
      drag's uneven load (m g / N = 8e-5 N per particle against edge springs of 50 N/m)
      moves particles by ~1e-6 m, 5e-6 of R, and the gas at 1000 Pa holds the volume; its
      A_eff, measured at the end, moves by < 1e-4, so v_t by < 5e-5. The vibration left
      by the spring damping is below 1e-5 m/s. Tolerance 2e-4 of v_t.
    """
    model = balloon()
    tri = model.tri_indices
    a_rest = effective_area(model.particle_q, tri)
    assert abs(a_rest / (np.pi * R**2) - 1.0) < 0.01  # 642 vertices: 0.48% short
    v_t = np.sqrt(2.0 * MASS * G / (RHO * CD * a_rest))
    dt = 2e-4
    with warnings.catch_warnings():
        warnings.simplefilter("error", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    for t in (0.1, 0.2, 0.3):
        sim.advance(state, t - state.time)
        speed = -state.particle_qd[:, 1].mean()
        assert abs(speed - v_t * np.tanh(G * t / v_t)) < dt * G / 2 + 2e-4 * v_t, t
        assert np.ptp(state.particle_qd[:, 1]) < 1e-3 * v_t, t
    sim.advance(state, 0.8 - state.time)
    assert abs(effective_area(state.particle_q, tri) / a_rest - 1.0) < 1e-4
    velocity = state.particle_qd.mean(axis=0)
    assert abs(-velocity[1] / v_t - 1.0) < 2e-4
    assert np.abs(velocity[[0, 2]]).max() < 1e-6 * v_t  # straight down: no lateral force
    assert np.ptp(state.particle_qd, axis=0).max() < 1e-4 * v_t  # moving as one
    # the sphere's closed form, with the mesh's discretisation as the only difference
    v_sphere = np.sqrt(2.0 * MASS * G / (RHO * CD * np.pi * R**2))
    assert abs(-velocity[1] / v_sphere - 1.0) < 0.005


@pytest.mark.parametrize("integrator", ["implicit_euler", "bdf2"])
def test_implicit_balloon_falls_at_its_terminal_speed(integrator):
    """Backward Euler and BDF2 in the compiled core take the drag explicitly (its force at
    the step's start enters the right-hand side, its Jacobian is left out), so the balloon
    of the explicit test falls at v_t tanh(g t / v_t) to the scheme's error and settles at
    v_t exactly: uniform fall at v_t has f0 = 0, a fixed point of the step.

    Tolerances, relative to v_t (1.14 m/s), at dt = 1/240 s: on the way, backward Euler's
    first-order error with f' < 0 is bounded as symplectic Euler's, |e| <= dt g / 2 =
    0.020 m/s (BDF2's is smaller); plus the elastic lag, 2e-4 of v_t (explicit test). At
    t = 0.8 s: 1 - tanh(6.9) = 2e-6 and the transient's error decayed by exp(-g t / v_t)
    ~ 1e-3 from its largest, 1.8 % of v_t: 2e-4 of v_t allowed. The explicit drag is stable
    at this step: dF/dV = 2 m g / v_t at v_t gives an explicit limit of v_t / g = 0.12 s."""
    model = balloon()
    v_t = np.sqrt(2.0 * MASS * G / (RHO * CD * effective_area(model.particle_q, model.tri_indices)))
    dt = 1.0 / 240.0
    sim = sb.Simulator(model, integrator=integrator, dt=dt, implicit_tolerance=1e-10)
    state = model.state()
    for t in (0.1, 0.2, 0.3):
        sim.advance(state, t - state.time)
        speed = -state.particle_qd[:, 1].mean()
        assert abs(speed - v_t * np.tanh(G * t / v_t)) < dt * G / 2 + 2e-4 * v_t, t
    sim.advance(state, 0.8 - state.time)
    velocity = state.particle_qd.mean(axis=0)
    assert abs(-velocity[1] / v_t - 1.0) < 2e-4
    # without the drag the balloon would be falling at g t
    assert -velocity[1] < 0.2 * G * 0.8


# -- drag off --------------------------------------------------------------------------------
def test_zero_drag_coefficient_is_bit_identical_to_no_drag():
    """C_d = 0 in a wind and air density 0 give the very same trajectory (the term is
    skipped, not added as zeros)."""

    def run(rho, wind):
        b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
        b.set_air(density=rho, wind=wind)
        b.add_soft_body(sb.icosphere(2, radius=0.3), mass=1.0, stiffness=400.0, damping=0.5,
                        gas=40.0, drag_coefficient=0.0 if rho else 2.0)  # fmt: skip
        model = b.finalize()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sb.StabilityWarning)
            sim = sb.Simulator(model, integrator="midpoint", dt=1e-3)
        state = model.state()
        state.particle_qd[:] = (0.5, 1.0, -0.3)
        sim.run(state, 200)
        return state.particle_q, state.particle_qd

    still = run(RHO, (1.0, 0.0, 2.0))
    other = run(0.0, (0.0, 0.0, 0.0))
    np.testing.assert_array_equal(still[0], other[0])
    np.testing.assert_array_equal(still[1], other[1])


# -- drag on threads, and bad input ---------------------------------------------------------
@pytest.mark.parametrize("integrator", ["implicit_euler", "bdf2", "projective"])
def test_drag_on_threads_matches_one_thread(integrator):
    """Every solver steps drag on threads too: a ball falling in a side wind, 100 steps,
    ends where the one-thread run ends, to the round-off of the chunked volume sums
    (1e-12 of the motion's scale per step), and 1 mm or more away from the same run
    without air (the term acts)."""
    if available_threads() < 2:
        pytest.skip("needs 2 cores")
    ends = []
    for threads, rho in ((1, 1.2), (2, 1.2), (1, 0.0)):
        b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
        b.set_air(density=rho, wind=(3.0, 0.0, 0.0))
        b.add_soft_body(sb.icosphere(2, radius=0.3), mass=0.05, stiffness=50.0, damping=0.1,
                        gas=sb.Gas.isothermal(1.0), drag_coefficient=0.5)  # fmt: skip
        model = b.finalize()
        sim = sb.Simulator(model, integrator=integrator, dt=2e-3, threads=threads)
        state = model.state()
        sim.run(state, 100)
        ends.append(state.particle_q.copy())
    np.testing.assert_allclose(ends[1], ends[0], rtol=0, atol=100 * 1e-12)
    assert np.abs(ends[2] - ends[0]).max() > 1e-3


def test_drag_runs_with_surface_contacts():
    """Surface soft contacts step in the compiled core too, so drag runs with them. They
    act only between different bodies: a lone ball falling in air with them ends
    bit-identical to the same ball without them."""
    runs = []
    for mode in ("surface", "none"):
        b = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
        b.set_air(density=RHO)
        b.set_soft_contact(mode)
        b.add_soft_body(sb.icosphere(1, radius=0.3), mass=1.0, stiffness=50.0, damping=0.1,
                        gas=1.0, drag_coefficient=0.5)  # fmt: skip
        model = b.finalize()
        assert "drag" in sb.diagnostics.active_terms(model)
        state = model.state()
        sb.Simulator(model, integrator="midpoint", dt=1e-3).run(state, 200)
        runs.append(state)
    np.testing.assert_array_equal(runs[0].particle_q, runs[1].particle_q)
    np.testing.assert_array_equal(runs[0].particle_qd, runs[1].particle_qd)


def test_drag_without_air_runs_anywhere():
    """C_d > 0 in air of density 0 is no drag: the implicit integrators take it."""
    model = drag_model(0.5, rho=0.0)
    assert "drag" not in sb.diagnostics.active_terms(model)
    sb.Simulator(model, integrator="implicit_euler", dt=1e-3)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda b: b.set_air(density=-1.0), "air density must be >= 0"),
        (lambda b: b.set_air(density=float("nan")), "air density must be finite"),
        (lambda b: b.set_air(wind=(1.0, float("inf"), 0.0)), "wind must be 3 finite"),
        (lambda b: b.set_air(wind=(1.0, 2.0)), "wind must be 3 finite"),
        (lambda b: b.add_soft_body(sb.icosphere(1), mass=1.0, stiffness=1.0, damping=0.0,
                                   gas=1.0, drag_coefficient=-0.1),
         "drag_coefficient must be >= 0"),
        (lambda b: b.add_cloth(sb.rectangle(), mass=1.0, stiffness=1.0, damping=0.0,
                               drag_coefficient="much"),
         "drag_coefficient must be a number"),
    ],
)  # fmt: skip
def test_builder_refuses_bad_air_and_coefficients(call, message):
    """A negative or non-finite air density, a wind that is not 3 finite numbers, and a
    negative or non-numeric drag coefficient are ValueErrors naming them, at the builder
    call."""
    with pytest.raises(ValueError, match=message):
        call(sb.ModelBuilder())


def test_control_refuses_a_bad_wind():
    """Control.wind must be 3 finite numbers or all NaN (the model's wind): another shape,
    or a NaN beside numbers, is a ValueError at the step, never a silent default."""
    model = drag_model(0.5)
    control = model.control()
    sim = sb.Simulator(model, integrator="rk4", dt=1e-4)
    for wind, message in (((1.0, 2.0), "shape"), ((np.nan, 0.0, 0.0), "3 finite numbers")):
        control.wind = wind
        with pytest.raises(ValueError, match=message):
            sim.step(model.state(), control)


def test_core_checks_the_drag_arrays():
    """The C++ core checks what it reads (a Model edited past the builder): shapes,
    signs and finiteness, with a ValueError naming the array."""
    model = drag_model(0.5)

    def edit(**fields):
        return dataclasses.replace(model, **fields)

    bad = [
        (edit(body_drag_coefficient=np.zeros(2)), "body_drag_coefficient must have"),
        (edit(body_drag_coefficient=np.array([-1.0])), "body_drag_coefficient holds"),
        (edit(air_density=float("inf")), "air_density holds inf at 0; it must be finite"),
        (edit(wind=np.array([0.0, np.nan, 0.0])), "wind holds nan at 1; it must be finite"),
        (edit(wind=np.zeros(2)), "wind must have shape"),
    ]
    for edited, message in bad:
        with pytest.raises(ValueError, match=message):
            _core.Model(edited)
    core = _core.Model(model)
    control = control_data(model)._replace(wind=np.array([np.nan, 1.0, 0.0]))
    q = np.ascontiguousarray(model.particle_q)
    with pytest.raises(ValueError, match="Control wind must be 3 finite numbers"):
        _core.eval_forces(core, control, 0.0, q, np.zeros_like(q))


# -- scenes ----------------------------------------------------------------------------------
def test_scene_air_table_and_drag_coefficient():
    """[air] density and wind and a body's drag_coefficient reach the model; defaults are
    sea-level still air and no drag; bounds are checked with the key named."""
    from softbody.scenes import SceneError, load_scene

    plain = load_scene("hanging-ball").model
    assert plain.air_density == 1.2 and "drag" not in sb.diagnostics.active_terms(plain)
    np.testing.assert_array_equal(plain.wind, 0.0)
    scene = load_scene("hanging-ball", ["air.density=1.0", "air.wind=[2.0, 0.0, 0.5]",
                                        "bodies.1.drag_coefficient=0.4"])  # fmt: skip
    model = scene.model
    assert model.air_density == 1.0 and "drag" in sb.diagnostics.active_terms(model)
    np.testing.assert_array_equal(model.wind, [2.0, 0.0, 0.5])
    np.testing.assert_array_equal(model.body_drag_coefficient, [0.0, 0.4, 0.0])
    for override, key in (("air.density=-1", "air.density"),
                          ("bodies.0.drag_coefficient=-0.5", "bodies.0.drag_coefficient"),
                          ("air.wind=[1, 2]", "air.wind")):  # fmt: skip
        with pytest.raises(SceneError, match=key):
            load_scene("hanging-ball", [override])
