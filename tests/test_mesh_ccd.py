"""Continuous soft-edge against mesh-edge contacts of mesh colliders (``core/collision/
mesh.hpp``, ``swept_edge_contacts``): a soft edge swept wholly over an edge of the mesh
within one step is stopped on the side it came from; and the colliders' impulses through
the particles they caught when thickness contacts hold a body on them
(``core/solvers/common.hpp``, ``loop::thick_with_colliders``)."""

from __future__ import annotations

import numpy as np
import pytest

import softbody as sb
from softbody.collision.mesh_collider import inside_mesh
from softbody.mesh.topology import unique_edges
from test_mesh_edges import crossings as segment_crossings

G = 9.81
HALF = 0.25  # the box mesh's half-size [m]: its top face at y = HALF
DT = 1e-2  # [s]
FALL = 120.0  # [m/s]: 1.2 m in one step, from 5 cm above the box's top to 0.65 m below it


def strip(*, velocity=(0.0, -FALL, 0.0), restitution=0.0, friction=0.0, motion=None,
          pinned=None, y=HALF + 0.05):  # fmt: skip
    """A 1 m x 2 cm cloth strip (two squares, four triangles, six particles, 0.1 kg) along
    z at height ``y`` over a 0.5 m box mesh at the origin (its 12 edges sharp), no gravity:
    the strip's ends (z = +-0.5) lie beyond the box's (z = +-0.25), so that no particle's
    path meets the box; only its long edges pass over the box's top edges along x."""
    sheet = sb.rectangle((0.02, 1.0), (2, 1))
    flat = sheet.vertices[:, [0, 2, 1]] * [1.0, 0.0, 1.0] + [0.013, y, 0.0]
    builder = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    builder.add_cloth(sb.TriMesh(flat, sheet.faces), mass=0.1, stiffness=50.0,
                      velocity=velocity, pinned=pinned)  # fmt: skip
    collider = sb.ColliderMesh(sb.box((2 * HALF, 2 * HALF, 2 * HALF)), restitution=restitution,
                               friction=friction, motion=motion)  # fmt: skip
    builder.add_collider(collider)
    return builder.finalize(), collider


def crossings(model, state, collider) -> int:
    """Brute force: the box's edges through the strip's triangles plus the strip's edges
    through the box's triangles (segments strictly through a triangle's inside)."""
    box = state.collider_q[0] + collider.data.vertices @ state.collider_rotation[0].T
    bt, st = collider.data.triangles, model.tri_indices
    be, se = unique_edges(bt), unique_edges(st)
    q = state.particle_q
    soft_through = segment_crossings(q, st, box[be[:, 0]], box[be[:, 1]])
    return soft_through + segment_crossings(box, bt, q[se[:, 0]], q[se[:, 1]])


def above_the_box(model, state, collider) -> bool:
    """Whether the strip lies on the box's near side: 65 points along each of its edges,
    none inside the box (the mesh's ray-parity test) and those over the top face's
    footprint (|x|, |z| < 0.25 m from the box's centre) above the top (y > top)."""
    c = state.collider_q[0]
    e = unique_edges(model.tri_indices)
    f = np.linspace(0.0, 1.0, 65)[:, None, None]
    q = state.particle_q
    x = (q[e[:, 0]] + f * (q[e[:, 1]] - q[e[:, 0]])).reshape(-1, 3) - c
    over = (np.abs(x[:, 0]) < HALF) & (np.abs(x[:, 2]) < HALF)
    inside = inside_mesh(collider.data, x)  # the box is not turned: local = world - c
    return bool(over.any() and not inside.any() and np.all(x[over, 1] > HALF))


def test_the_free_flight_passes_the_box_unseen_by_the_step_s_end():
    """The scene's premise (what the step's-end tests see without the continuous test):
    the strip's free flight over one step ends 0.65 m below the box's bottom, every particle
    outside the box at both ends of the step (the mesh's inside test) and no edge of
    either through the other (brute force), though the strip's long edges swept through
    the box. Run against the code before the continuous test (its compiled core), the
    strip did pass: every particle at y = -0.9 m after the step."""
    model, collider = strip()
    q0 = model.state().particle_q
    q1 = q0 + DT * np.array([0.0, -FALL, 0.0])
    state = model.state()
    for q in (q0, q1):
        assert not inside_mesh(collider.data, q - state.collider_q[0]).any()
    state.particle_q[:] = q1
    assert crossings(model, state, collider) == 0
    assert q0[:, 1].min() > HALF > -HALF > q1[:, 1].max()


@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4", "implicit_euler"])
def test_a_strip_swept_over_box_edges_in_one_step_stops_on_the_near_side(integrator):
    """Issue 32, item 2 (no tunnelling in a fast step): the strip falling 1.2 m in one step
    past the box's top (no particle's path meets the box; its long edges pass over the
    top's two edges along x) is stopped on the side it came from: after the step the strip
    lies over the box (above_the_box: no point of it inside, those over the top face above
    it), no edge of either passes through the other (brute force), and, restitution 0,
    the strip no longer falls (every particle's vertical velocity above -1 % of the fall
    speed: the ends of an edge caught tilted keep a little along the tilted normal)."""
    model, collider = strip()
    state = model.state()
    sb.Simulator(model, integrator=integrator, dt=DT).run(state, 1)
    assert above_the_box(model, state, collider)
    assert crossings(model, state, collider) == 0
    assert state.particle_qd[:, 1].min() > -0.01 * FALL


def test_a_box_rising_through_a_strip_in_one_step_pushes_it():
    """The collider's motion is part of the relative motion: the strip at rest 5 cm above
    the box and the box rising at 120 m/s (1.2 m in the step, its top passing wholly
    through the strip's height): after the step the strip lies over the box at its pose at
    the step's end (above_the_box), no edge of either through the other, and it moves up
    with the box (restitution 0: the mean vertical velocity 120 m/s within 1 %)."""
    model, collider = strip(velocity=(0.0, 0.0, 0.0),
                            motion=sb.MotionTranslation(velocity=(0.0, FALL, 0.0)))  # fmt: skip
    state = model.state()
    sb.Simulator(model, integrator="symplectic_euler", dt=DT).run(state, 1)
    top = state.collider_q[0, 1] + HALF
    assert top == pytest.approx(HALF + FALL * DT)
    assert above_the_box(model, state, collider)
    assert crossings(model, state, collider) == 0
    assert state.particle_qd[:, 1].mean() == pytest.approx(FALL, rel=0.01)


def test_the_collider_receives_the_strip_s_momentum_change():
    """Newton's third law: no gravity, the strip thrown at the box (restitution 0.5,
    friction 0.3, a sideways component along the box's edges): the impulse the collider
    receives over the step is minus the strip's momentum change (internal forces sum to
    zero), to 1e-9 of it; it bounced (its vertical momentum changed by more than its
    approach's)."""
    model, collider = strip(velocity=(3.0, -FALL, 1.0), restitution=0.5, friction=0.3)
    state = model.state()
    m = model.particle_mass
    p0 = m @ state.particle_qd
    sb.Simulator(model, integrator="symplectic_euler", dt=DT).run(state, 1)
    dp = m @ state.particle_qd - p0
    np.testing.assert_allclose(state.collider_impulse[0], -dp, atol=1e-9 * np.linalg.norm(dp))
    assert dp[1] > m.sum() * FALL
    assert crossings(model, state, collider) == 0


@pytest.mark.parametrize("friction", [0.0, 0.5])
def test_a_frictionless_edge_contact_keeps_the_velocity_along_the_mesh_edge(friction):
    """The contact normal is the two edges' common normal, across the box's edges (along
    x): frictionless, the strip caught on them keeps its velocity along them (vx = 3 m/s,
    every particle, to 1e-9) while its fall stops; with friction 0.5 the tangential
    velocity is cut (the sideways speed drops below 2.9 m/s somewhere), so the check can
    tell."""
    model, collider = strip(velocity=(3.0, -FALL, 0.0), friction=friction)
    state = model.state()
    sb.Simulator(model, integrator="symplectic_euler", dt=DT).run(state, 1)
    assert above_the_box(model, state, collider)
    assert crossings(model, state, collider) == 0
    if friction == 0.0:
        np.testing.assert_allclose(state.particle_qd[:, 0], 3.0, rtol=1e-9)
    else:
        assert state.particle_qd[:, 0].min() < 2.9


def test_a_pinned_strip_swept_over_the_box_stops_the_run():
    """A crossing no free particle can answer stops the run and says where (issue 32): the
    strip's particles all pinned, driven by their Control targets 1.2 m down in one step
    past the box: the step stops with a SimulationError naming mesh collider 0 and a strip
    edge, the state left at the step's start."""
    model, _ = strip(velocity=(0.0, 0.0, 0.0), pinned=np.arange(6))
    state = model.state()
    start = state.particle_q.copy()
    control = model.control()
    control.pin_target = start + np.array([0.0, -FALL * DT, 0.0])
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=DT)
    with pytest.raises(sb.SimulationError, match="crossed mesh collider 0 at step 0"):
        sim.run(state, 1, control=control)
    np.testing.assert_array_equal(state.particle_q, start)


# -- collider impulses through caught particles --------------------------------------------
FACE_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # xy plane to xz
CLOTH_MASS, BALL_MASS, H = 0.2, 1.0, 0.01  # [kg], [kg], [m]


def ball_on_cloth(walls: bool = False) -> sb.Model:
    """A 1 kg gas-filled ball (162 vertices, radius 0.15 m) resting on a 0.8 m square
    cloth (0.2 kg, 8 x 8 squares) lying on the ground plane; thickness contacts (h = 1 cm,
    friction 0.5) between them. ``walls``: four frictionless planes 0.6 m from the axis
    too, touching nothing (more than one collider)."""
    builder = sb.ModelBuilder()
    builder.set_soft_contact("surface", thickness=H, restitution=0.0, friction=0.5)
    cloth = sb.rectangle((0.8, 0.8), (8, 8)).rotated(FACE_UP).translated((0.0, 5e-4, 0.0))
    builder.add_cloth(cloth, mass=CLOTH_MASS, stiffness=300.0, damping=0.5)
    builder.add_soft_body(sb.icosphere(2, radius=0.15, center=(0.013, 0.15 + H + 0.002, 0.011)),
                          mass=BALL_MASS, stiffness=800.0, damping=3.0,
                          gas=sb.Gas.isothermal(20.0))  # fmt: skip
    builder.add_collider(sb.ColliderPlane(restitution=0.0, friction=0.5))
    if walls:
        for normal in np.array([(1, 0, 0), (-1, 0, 0), (0, 0, 1), (0, 0, -1)], dtype=float):
            builder.add_collider(sb.ColliderPlane(point=-0.6 * normal, normal=normal,
                                                  restitution=0.0, friction=0.0))  # fmt: skip
    return builder.finalize()


@pytest.mark.parametrize(
    ("integrator", "dt", "walls"),
    [("symplectic_euler", 5e-4, False), ("symplectic_euler", 5e-4, True),
     ("implicit_euler", 2e-3, False)],
)  # fmt: skip
def test_the_ground_under_a_ball_on_a_cloth_carries_both_weights(integrator, dt, walls):
    """Newton's third law through a caught particle: the ball rests on the cloth, which
    the ground holds (thickness contacts run again holding the particles the ground caught;
    their push on the ball is the ground's). Over 1 s after 2 s of settling, the momentum
    balance of the whole system, whose only outside forces are gravity and the ground:
    minus the ground's impulse is (M_ball + M_cloth) g T plus the momentum change, to 1e-5
    of the weight's impulse (round-off; the implicit solve's tolerance); at rest the
    ground's impulse per second is the total weight within 2 % (the ball's residual
    rocking: measured 0.7 %). The walls, touching nothing, receive nothing. Before the
    ground was given the second pass's reaction it carried 3.5 N (symplectic Euler) or
    7.8 N (implicit Euler) of the 11.8 N."""
    model = ball_on_cloth(walls)
    sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    sim.run(state, round(2.0 / dt))
    p0 = model.particle_mass @ state.particle_qd
    steps = round(1.0 / dt)
    sim.run(state, steps)
    window = steps * dt
    dp = model.particle_mass @ state.particle_qd - p0
    weight = (CLOTH_MASS + BALL_MASS) * G
    ground = state.collider_impulse[0]
    assert -ground[1] == pytest.approx(weight * window + dp[1], abs=1e-5 * weight * window)
    assert -ground[1] / window == pytest.approx(weight, rel=0.02)
    if walls:
        assert np.abs(state.collider_impulse[1:]).max() == 0.0


def test_an_edge_falling_parallel_to_a_box_edge_through_it_is_caught():
    """Parallel edges: a 1 m x 2 cm strip along x (two squares across its width: rows at
    z = 0.25, 0.26, 0.27 m) falling 1.2 m in one step, its row at z = 0.25 in the plane of
    the box's front face, so that its edge there falls through the box's top front edge,
    parallel to it (the two lines coplanar all along: first_touch's quadratic is zero; the
    edge meets the top's edges along z at the box's corners at the same time). Only that
    edge touches the box (the other rows pass in front of it, every particle outside the
    box at both ends): its two particles stop at the margin above the edge (y = 0.25 m +
    margin, to 1e-9 m; the contact normal +y, toward the side it came from), the others
    fall on past the box, and no edge of either passes through the other. Before the
    continuous test the whole strip ended 0.65 m below the box's bottom."""
    sheet = sb.rectangle((1.0, 0.02), (1, 2))
    flat = sheet.vertices[:, [0, 2, 1]] * [1.0, 0.0, 1.0] + [0.0, HALF + 0.05, HALF + 0.01]
    builder = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    builder.add_cloth(sb.TriMesh(flat, sheet.faces), mass=0.1, stiffness=50.0,
                      velocity=(0.0, -FALL, 0.0))  # fmt: skip
    collider = sb.ColliderMesh(sb.box((2 * HALF, 2 * HALF, 2 * HALF)), restitution=0.0,
                               friction=0.0)  # fmt: skip
    builder.add_collider(collider)
    model = builder.finalize()
    state = model.state()
    on_face = np.isclose(state.particle_q[:, 2], HALF)
    assert on_face.sum() == 2
    sb.Simulator(model, integrator="symplectic_euler", dt=DT).run(state, 1)
    margin = model.collider_mesh_margin[0]
    np.testing.assert_allclose(state.particle_q[on_face, 1], HALF + margin, atol=1e-9)
    np.testing.assert_allclose(state.particle_q[~on_face, 1], HALF + 0.05 - FALL * DT)
    assert crossings(model, state, collider) == 0
