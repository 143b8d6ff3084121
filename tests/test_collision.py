"""Collisions: rigid colliders, soft-soft contacts, impulses, tunnelling."""

from __future__ import annotations

import numpy as np
import pytest

import softbody as sb

G = 9.81


def bouncing_particle(restitution: float, height: float, dt: float):
    builder = sb.ModelBuilder()
    builder.add_particle((0.0, height, 0.0), mass=1.0)
    builder.add_collider(sb.ColliderPlane(restitution=restitution, friction=0.0))
    model = builder.finalize()
    sim = sb.Simulator(model, integrator="velocity_verlet", dt=dt)
    state = model.state()
    heights = []
    fall = np.sqrt(2 * height / G)
    for _ in range(int(1.5 * fall / dt) + int(2 * restitution * fall / dt) + 10):
        sim.step(state)
        heights.append(state.particle_q[0, 1])
    return np.array(heights)


@pytest.mark.parametrize("restitution", [0.3, 0.5, 0.8, 1.0])
def test_particle_rebounds_to_e_squared_height(restitution):
    """A point mass dropped from h leaves the ground at e v (v = sqrt(2 g h)) and rises to
    e^2 h. Detection at the end of a step sees v up to g dt too fast and moves the particle
    by up to v dt: tolerance e^2 h 2 g dt / v + 2 v dt."""
    h, dt = 1.0, 1e-3
    y = bouncing_particle(restitution, h, dt)
    v = np.sqrt(2 * G * h)
    bounce = int(np.argmin(y))
    rebound = y[bounce:].max()
    tol = restitution**2 * h * 2 * G * dt / v + 2 * v * dt
    assert rebound == pytest.approx(restitution**2 * h, abs=tol)
    assert y.min() >= 0.0  # never below the ground at the end of a step


def drop_ball(restitution, *, steps=6000, dt=2e-4):
    builder = sb.ModelBuilder()
    builder.add_soft_body(
        sb.icosphere(2, radius=0.5, center=(0, 1.5, 0)),
        mass=1.0,
        stiffness=500.0,
        damping=0.0,
        gas=300.0,
    )
    builder.add_collider(sb.ColliderPlane(restitution=restitution, friction=0.0))
    model = builder.finalize()
    sim = sb.Simulator(model, integrator="velocity_verlet", dt=dt)
    state = model.state()
    e0 = sb.energies(model, state).total
    com = []
    for _ in range(steps // 20):
        sim.run(state, 20)
        com.append(sb.body_center_of_mass(model, state)[0, 1])
        assert state.particle_q[:, 1].min() >= 0.0
    return model, state, e0, np.array(com)


def test_soft_ball_elastic_bounce_keeps_energy():
    """Restitution 1, no friction, no damping: contacts reflect velocities without loss,
    so total energy (kinetic + gravity + springs + gas) is kept up to the contact
    projection, which moves a particle by at most v dt per contact: within 5% of the
    kinetic energy at impact over a bounce (measured: 3%). The centre of mass comes back
    up but not all the way: part of the energy stays in vibration of the ball."""
    model, state, e0, com = drop_ball(1.0)
    e1 = sb.energies(model, state).total
    kinetic_at_impact = 1.0 * G * 1.0  # M g (fall height of the centre, 1.5 - 0.5)
    assert abs(e1 - e0) <= 0.05 * kinetic_at_impact
    bottom = int(np.argmin(com))
    assert 1.0 < com[bottom:].max() < 1.5


def test_inelastic_contacts_dissipate_energy():
    """With restitution < 1 every contact removes (1 - e^2) of the normal kinetic energy of
    the particle it stops, so the bounce loses energy (at least 1% of the M g h = 9.81 J
    the ball brought down) and rebounds lower than the elastic ball; no contact adds energy.
    (The rebound is not monotonic in e for a soft ball: at e = 0.5 the bottom vertices
    chatter and lose energy on every re-contact.)"""
    _, _, _, com_elastic = drop_ball(1.0)
    elastic_peak = com_elastic[int(np.argmin(com_elastic)) :].max()
    for e in (0.0, 0.5):
        model, state, e0, com = drop_ball(e)
        e1 = sb.energies(model, state).total
        assert e0 - e1 > 0.01 * G
        assert com[int(np.argmin(com)) :].max() < elastic_peak


def signed_distance(collider, x):
    """Distance of points x (N, 3) from a collider's allowed region's boundary, positive on
    the allowed side (closed forms, independent of the solver's contact code)."""
    if isinstance(collider, sb.ColliderPlane):
        n = np.asarray(collider.normal, float)
        return (x - collider.point) @ (n / np.linalg.norm(n))
    if isinstance(collider, sb.ColliderSphere):
        return np.linalg.norm(x - collider.center, axis=1) - collider.radius
    rot = np.eye(3) if collider.rotation is None else np.asarray(collider.rotation)
    local = (x - collider.center) @ rot
    d = np.abs(local) - collider.half_extents
    outside = np.linalg.norm(np.maximum(d, 0.0), axis=1)
    inside = np.minimum(d.max(axis=1), 0.0)
    return outside + inside


def fast_ball_scene(collider, speed, direction=(1.0, 0.0, 0.0), dt=1e-3):
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.add_soft_body(
        sb.icosphere(2, radius=0.2),
        mass=1.0,
        stiffness=2000.0,
        damping=2.0,
        gas=50.0,
        velocity=speed * np.asarray(direction),
    )
    builder.add_collider(collider)
    model = builder.finalize()
    # RK4: midpoint at 1 ms would grow this small, hard-pumped ball's undamped pressure
    # modes faster than the stability estimate accepts
    return model, sb.Simulator(model, integrator="rk4", dt=dt)


THIN_WALL = sb.ColliderBox(center=(0.6, 0.0, 0.0), half_extents=(0.005, 0.5, 0.5), restitution=0.5)


@pytest.mark.parametrize(
    "collider",
    [
        sb.ColliderSphere(center=(0.6, 0.0, 0.0), radius=0.15, restitution=0.5),
        THIN_WALL,
        sb.ColliderBox(
            center=(0.6, 0.05, 0.0),
            half_extents=(0.1, 0.1, 0.1),
            rotation=sb.collision.rotation_about((0, 1, 1), 0.7),
            restitution=0.2,
        ),
        sb.ColliderPlane(point=(0.5, 0.0, 0.0), normal=(-1.0, 0.2, 0.0), restitution=0.8),
    ],
    ids=["sphere", "thin-wall", "turned-box", "plane"],
)
def test_no_vertex_ends_a_step_inside_a_static_collider(collider):
    """A ball thrown at 30 m/s (a wall 1 cm thick is crossed in a third of a step): after
    every step no vertex is inside the collider (continuous detection for thin solids),
    and no vertex has passed through to the far side."""
    model, sim = fast_ball_scene(collider, 30.0)
    state = model.state()
    for _ in range(120):
        sim.step(state)
        # on the surface up to round-off of the projection (|x| ~ 1: 1e-12)
        assert signed_distance(collider, state.particle_q).min() >= -1e-12
        if collider is THIN_WALL:  # none got to the far side of the 1 cm wall
            assert state.particle_q[:, 0].max() <= 0.595 + 1e-12
    assert np.mean(state.particle_qd[:, 0]) < 0  # it bounced back


def slid(collider, integrator: str, steps: int = 500, dt: float = 1e-3) -> np.ndarray:
    """A point mass set on y = 0 (on top of `collider`) moving at 1 m/s along x under
    gravity, after `steps` steps: its positions [m] and velocities [m/s] at every step,
    shape (steps, 2, 3)."""
    builder = sb.ModelBuilder(gravity=(0.0, -G, 0.0))
    builder.add_particle((0.0, 0.0, 0.0), mass=1.0, velocity=(1.0, 0.0, 0.0))
    builder.add_collider(collider)
    model = builder.finalize()
    sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    out = []
    for _ in range(steps):
        sim.step(state)
        out.append([state.particle_q[0].copy(), state.particle_qd[0].copy()])
    return np.array(out)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "implicit_euler"])
@pytest.mark.parametrize("friction", [0.0, 0.1])
def test_a_particle_slides_on_a_box_top_as_on_the_plane(integrator, friction):
    """A solid box's top face is a plane: a particle sliding on it (re-entering it each step
    as gravity pulls it in) goes where it goes on a ColliderPlane of the same restitution
    and friction, step by step, to round-off. Frictionless that is x = v t (0.5 m in
    0.5 s); with friction its velocity loses the fraction each contact, as on the plane.
    Before, a path entering the box was put back where it entered, so the particle stayed
    at x = 0 whatever the friction while its velocity said 1 m/s."""
    kw = dict(restitution=0.5, friction=friction)
    box = slid(sb.ColliderBox(center=(0.0, -1.0, 0.0), half_extents=(5.0, 1.0, 5.0), **kw),
               integrator)  # fmt: skip
    plane = slid(sb.ColliderPlane(**kw), integrator)
    np.testing.assert_allclose(box, plane, rtol=0.0, atol=1e-12)
    if friction == 0.0:
        assert box[-1, 0, 0] == pytest.approx(0.5, abs=1e-12)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "implicit_euler"])
def test_a_frictionless_particle_slides_over_a_sphere_keeping_its_energy(integrator):
    """A point mass sliding frictionless over the top of a solid sphere of radius 100 m at
    1 m/s follows the surface (its distance from the centre stays R to within a step's
    sag, g dt^2 plus the tangent's rise |v|^2 dt^2 / 2 R) and keeps its energy: gravity
    along the surface speeds it up as it goes down, |v|^2 = 1 + 2 g (0 - y). The
    restitution's losses in the normal direction are of order g dt per contact, so the
    tolerance on |v|^2 is 2 g dt. Its path along the surface is the sum of its speeds times
    dt, to within 2 steps' motion. Before, it stayed at its start."""
    radius, dt = 100.0, 1e-3
    run = slid(sb.ColliderSphere(center=(0.0, -radius, 0.0), radius=radius, restitution=0.5,
                                 friction=0.0), integrator, dt=dt)  # fmt: skip
    q, v = run[:, 0], run[:, 1]
    r = np.linalg.norm(q - [0.0, -radius, 0.0], axis=1)
    sag = G * dt**2 + 2.0**2 * dt**2 / (2 * radius)  # |v| < 2 m/s
    assert np.all(np.abs(r - radius) <= sag + 1e-12)
    speed2 = (v**2).sum(axis=1)
    np.testing.assert_allclose(speed2, 1.0 - 2.0 * G * q[:, 1], rtol=0.0, atol=2 * G * dt)
    arc = radius * np.arctan2(q[-1, 0], q[-1, 1] + radius)
    assert arc == pytest.approx(dt * np.sqrt(speed2).sum(), abs=2 * 1.02 * dt)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "implicit_euler"])
@pytest.mark.parametrize("kind", ["box", "sphere"])
def test_a_moving_solid_carries_a_particle_resting_on_it_by_its_friction(kind, integrator):
    """A conveyor: a solid box (or a 100 m sphere) moving at 1 m/s along x under a point
    mass resting on its top, restitution 0. With friction 1 a contact gives the particle
    the surface's velocity along it, so from the first step's contact on it rides along:
    x = 1 m/s (T - dt) = 0.499 m after 0.5 s (to 1e-3 on the sphere, whose top curves away
    below it by 1.2 mm). Frictionless the surface slides away under it: it stays at x = 0
    on the box. Before, the particle went back to where its path entered the moving solid
    each step: with friction 1 it kept the velocity 1 m/s and stayed at x = 0 on the box
    (0.087 m on the sphere)."""
    def ride(friction: float) -> float:
        builder = sb.ModelBuilder(gravity=(0.0, -G, 0.0))
        builder.add_particle((0.0, 0.0, 0.0), mass=1.0)
        kw = dict(friction=friction, restitution=0.0,
                  motion=sb.MotionTranslation(velocity=(1.0, 0.0, 0.0)))
        if kind == "box":
            builder.add_collider(sb.ColliderBox(center=(0.0, -1.0, 0.0),
                                                half_extents=(5.0, 1.0, 5.0), **kw))
        else:
            builder.add_collider(sb.ColliderSphere(center=(0.0, -100.0, 0.0), radius=100.0,
                                                   **kw))
        model = builder.finalize()
        state = model.state()
        sb.Simulator(model, integrator=integrator, dt=1e-3).run(state, 500)
        return float(state.particle_q[0, 0])

    assert ride(1.0) == pytest.approx(0.499, abs=1e-9 if kind == "box" else 1e-3)
    if kind == "box":
        assert ride(0.0) == pytest.approx(0.0, abs=1e-12)


def test_fast_ball_stays_in_container():
    """A container clamps particles in its own frame, so a ball at 20 m/s (2 cm per step,
    a twentieth of its width; faster, its 1 kg would flatten it against the gas) cannot
    tunnel through a wall however it bounces."""
    box = sb.ColliderBox(half_extents=(0.5, 0.5, 0.5), container=True, restitution=0.9)
    model, sim = fast_ball_scene(box, 20.0, direction=(1.0, 0.3, -0.2))
    state = model.state()
    for _ in range(200):
        sim.step(state)
        assert np.abs(state.particle_q).max() <= 0.5 + 1e-12


def test_ball_in_spinning_box_stays_inside_for_10_seconds():
    """The paper's rotating box (Figures 1, 7): a box spinning at 1 rad/s about a
    horizontal axis keeps the ball inside for 10 s; the box has turned by 10 rad."""
    builder = sb.ModelBuilder()
    builder.add_soft_body(
        sb.icosphere(2, radius=0.3), mass=1.0, stiffness=500.0, damping=1.0, gas=100.0
    )
    builder.add_collider(
        sb.ColliderBox(
            half_extents=(1.0, 1.0, 1.0),
            container=True,
            restitution=0.5,
            friction=0.2,
            motion=sb.MotionRotation((0.0, 0.0, 1.0)),
        )
    )
    model = builder.finalize()
    sim = sb.Simulator(model, integrator="midpoint", dt=5e-4)
    state = model.state()
    for _ in range(100):
        sim.run(state, 200)
        local = (state.particle_q - state.collider_q[0]) @ state.collider_rotation[0]
        assert np.abs(local).max() <= 1.0 + 1e-12
    assert state.time == pytest.approx(10.0)
    angle = np.arctan2(state.collider_rotation[0][1, 0], state.collider_rotation[0][0, 0])
    assert angle == pytest.approx(np.angle(np.exp(10j)), abs=1e-9)


def head_on(mode, shape_mesh=None, restitution=0.5):
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact(mode, restitution=restitution, friction=0.0)
    for x, v in ((-0.8, 2.0), (0.8, -2.0)):
        mesh = sb.icosphere(2, radius=0.5) if shape_mesh is None else shape_mesh
        builder.add_soft_body(
            mesh.translated((x, 0.0, 0.0)),
            mass=1.0,
            stiffness=500.0,
            damping=1.0,
            gas=300.0,
            velocity=(v, 0, 0),
        )
    model = builder.finalize()
    return model, sb.Simulator(model, integrator="midpoint", dt=2e-4)


def body_momentum(model, state):
    m = model.particle_mass[:, None]
    return np.array(
        [(m[a:b] * state.particle_qd[a:b]).sum(axis=0) for a, b in model.body_particle_range]
    )


@pytest.mark.parametrize("mode", ["bounding", "surface"])
def test_head_on_collision_is_symmetric(mode):
    """Two equal balls meeting head on at +-2 m/s: total momentum stays zero (every
    contact impulse has an equal and opposite one), each ball's momentum change is the
    mirror of the other's, and both come back out with reversed velocity."""
    model, sim = head_on(mode)
    state = model.state()
    sim.run(state, 4000)
    p = body_momentum(model, state)
    assert np.allclose(p.sum(axis=0), 0.0, atol=1e-12)
    assert p[0, 0] == pytest.approx(-p[1, 0], rel=1e-12)
    assert p[0, 0] < -0.5 and p[1, 0] > 0.5  # bounced
    assert p[0, 0] > -2.0  # and did not gain momentum


def test_surface_contact_touches_where_surfaces_touch():
    """Two cubes meeting face to face at 4 m/s relative speed. With surface contacts the
    step that first touches moves no vertex further than the contact margin: the faces
    meet. With the paper's method the bounding boxes overlap only when the faces touch,
    and then the face centre is already deep in the other cube's bounding ellipsoid
    (semi-axes sqrt(3) x 0.3 m = 0.52 m for a flat-faced cube, 0.22 m beyond the face), so
    it jumps out by a good part of that."""
    cube = sb.box((0.6, 0.6, 0.6), subdivisions=2)
    jumps = {}
    for mode in ("surface", "bounding"):
        model, sim = head_on(mode, shape_mesh=cube)
        state = model.state()
        a0, a1 = model.body_particle_range[0]
        p0 = body_momentum(model, state)[0, 0]
        while abs(body_momentum(model, state)[0, 0] - p0) < 1e-9:
            before = state.particle_q[a0:a1].copy()
            sim.step(state)
            assert state.time < 1.0
        jumps[mode] = np.linalg.norm(state.particle_q[a0:a1] - before, axis=1).max()
        margin = model.contact_margin
    assert jumps["surface"] < margin
    # inflated cubes bulge, so their ellipsoids hug them more than the 0.22 m of a
    # flat-faced cube; the jump is still many contact margins
    assert jumps["bounding"] > 0.1 > margin


def test_pushing_collider_receives_the_momentum_it_gives():
    """A sphere driven through Control into a free ball (no gravity): the impulse the
    collider reports is minus the momentum the ball gained (Newton's third law)."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.add_soft_body(
        sb.icosphere(2, radius=0.3), mass=1.0, stiffness=800.0, damping=1.0, gas=100.0
    )
    builder.add_collider(
        sb.ColliderSphere(center=(-1.0, 0.0, 0.0), radius=0.2, restitution=0.5, friction=0.0)
    )
    model = builder.finalize()
    sim = sb.Simulator(model, integrator="midpoint", dt=2e-4)
    state = model.state()
    control = model.control()
    p0 = body_momentum(model, state)[0]
    total = np.zeros(3)
    for k in range(40):  # 0.4 s: the sphere moves from x = -1 to x = -0.2 at 2 m/s
        control.collider_target = np.array([[-1.0 + 0.8 * (k + 1) / 40, 0.0, 0.0]])
        sim.run(state, 50, control)
        total += state.collider_impulse[0]
    gained = body_momentum(model, state)[0] - p0
    assert gained[0] > 0.1  # the ball was pushed
    assert np.allclose(total, -gained, atol=1e-10)
    assert state.collider_q[0] == pytest.approx([-0.2, 0.0, 0.0])


def test_ball_resting_on_ground_is_held_by_its_weight():
    """At rest on the ground, the impulse the ground receives per second is the ball's
    weight M g (static equilibrium), within 2% once settled (residual vibration)."""
    builder = sb.ModelBuilder()
    builder.add_soft_body(
        sb.icosphere(2, radius=0.3, center=(0, 0.31, 0)),
        mass=2.0,
        stiffness=800.0,
        damping=2.0,
        gas=200.0,
    )
    builder.add_collider(sb.ColliderPlane(restitution=0.0, friction=0.5))
    model = builder.finalize()
    sim = sb.Simulator(model, integrator="midpoint", dt=5e-4)
    state = model.state()
    sim.run(state, 6000)  # settle for 3 s
    sim.run(state, 2000)  # then measure over 1 s
    assert -state.collider_impulse[0, 1] == pytest.approx(2.0 * G * 1.0, rel=0.02)


def test_bad_colliders_are_refused():
    """Colliders check their parameters and say which one is wrong."""
    builder = sb.ModelBuilder()
    with pytest.raises(ValueError, match="collider 0 restitution must lie in"):
        builder.add_collider(sb.ColliderPlane(restitution=1.5))
    with pytest.raises(ValueError, match="radius must be finite and > 0"):
        builder.add_collider(sb.ColliderSphere(radius=-1.0))
    with pytest.raises(ValueError, match="half_extents must be > 0"):
        builder.add_collider(sb.ColliderBox(half_extents=(1.0, 0.0, 1.0)))
    with pytest.raises(ValueError, match="soft contact mode must be"):
        builder.set_soft_contact("sticky")


def _fit_reference(x, shape):
    """Centre and semi-axes of the paper's bounding object of points x (N, 3): the box
    of their bounds; the sphere about the box centre through the farthest point; the
    ellipsoid with the box's proportions through the farthest point (section 3.5)."""
    lo, hi = x.min(axis=0), x.max(axis=0)
    c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
    if shape == "bounding_box":
        return c, h
    if shape == "bounding_sphere":
        return c, np.full(3, np.linalg.norm(x - c, axis=1).max())
    return c, h * np.sqrt((((x - c) / h) ** 2).sum(axis=1).max())


def bounding_contact_pass(model, q, qd):
    """One pass of the paper's soft-soft contact kernel on q, qd (N, 3) in place."""
    from softbody import _core
    from softbody.core import core_model

    assert _core.soft_contacts(core_model(model), q, qd) == 0


@pytest.mark.parametrize("shape", ["bounding_box", "bounding_sphere", "bounding_ellipsoid"])
def test_bounding_contact_moves_vertices_to_the_other_object(shape):
    """One pass of the paper's soft-soft contact on two overlapping balls (seed 4 for
    their velocities): every vertex inside the other ball's bounding object (fitted
    before the pass) ends on its surface, on the nearest face of a box or along the ray
    from the centre of a sphere or ellipsoid; the others stay; and the impulses cancel,
    so the total momentum is unchanged (to round-off)."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact("bounding", restitution=0.5, friction=0.2)
    for center, scale in (((-0.3, 0.0, 0.0), (1.0, 0.8, 1.0)), ((0.3, 0.1, 0.0), (0.7, 1.0, 1.0))):
        mesh = sb.icosphere(2, radius=0.5)
        mesh = sb.TriMesh(mesh.vertices * scale + center, mesh.faces)
        builder.add_soft_body(
            mesh, mass=1.0, stiffness=500.0, damping=1.0, gas=300.0, contact_shape=shape
        )
    model = builder.finalize()
    q = model.particle_q.copy()
    qd = np.random.default_rng(4).normal(size=q.shape)
    q0, p0 = q.copy(), (model.particle_mass[:, None] * qd).sum(axis=0)
    bounding_contact_pass(model, q, qd)
    (a0, a1), (b0, b1) = model.body_particle_range
    moved = 0
    for mine, other in ((slice(a0, a1), slice(b0, b1)), (slice(b0, b1), slice(a0, a1))):
        c, axes = _fit_reference(q0[other], shape)
        d = q0[mine] - c
        expected = q0[mine].copy()
        if shape == "bounding_box":
            depth = axes - np.abs(d)
            inside = np.all(depth > 0, axis=1)
            k = np.argmin(depth, axis=1)
            rows = np.nonzero(inside)[0]
            expected[rows, k[rows]] = c[k[rows]] + np.sign(d[rows, k[rows]]) * axes[k[rows]]
        else:
            f = ((d / axes) ** 2).sum(axis=1)
            inside = f < 1
            expected[inside] = c + d[inside] / np.sqrt(f[inside])[:, None]
        moved += inside.sum()
        assert np.allclose(q[mine], expected, rtol=0, atol=1e-12)
    assert moved > 10  # the balls do overlap
    p1 = (model.particle_mass[:, None] * qd).sum(axis=0)
    assert np.allclose(p1, p0, rtol=0, atol=1e-12)


@pytest.mark.parametrize("pinned", [42, 41])
def test_bounding_contact_against_a_pinned_body(pinned):
    """The paper's soft-soft contact against a ball with all or all but one of its 42
    particles pinned: its mean velocity and mass count the pinned particles, whose share
    of the impulse goes to what holds them. Before, an all-pinned ball was skipped (a ball
    fell straight through it: centres 0.02 m apart), and with one free particle that
    particle took the whole impulse, flew and pumped the other ball 3 m up. One pass
    (seed 5 for the velocities): the free ball's vertices inside the pinned ball's
    bounding sphere end on it, along the ray from its centre (section 3.5); their normal
    velocity relative to the pinned ball's mass-weighted mean velocity u is reversed and
    scaled by the restitution; the pinned particles are untouched and the free one takes
    -(momentum change) / (ball mass). Then a ball dropped onto it from rest, 0.2 m above
    it, stays on top (its vertices are kept outside the 0.5 m sphere; a ball squashed
    around it could bring its centroid a little inside, so the bound is 0.4 m) and,
    losing energy in every contact, never rises above its start."""
    restitution = 0.5

    def two_balls(height):
        builder = sb.ModelBuilder()
        builder.set_soft_contact("bounding", restitution=restitution, friction=0.0)
        for y, pins in ((0.0, np.arange(pinned)), (height, None)):
            builder.add_soft_body(
                sb.icosphere(1, radius=0.5, center=(0.0, y, 0.0)),
                mass=1.0,
                stiffness=100.0,
                damping=0.1,
                gas=10.0,
                pinned=pins,
                contact_shape="bounding_sphere",
            )
        return builder.finalize()

    model = two_balls(0.8)  # overlapping
    q = model.particle_q.copy()
    qd = np.random.default_rng(5).normal(size=q.shape)
    q0, qd0 = q.copy(), qd.copy()
    bounding_contact_pass(model, q, qd)
    held = slice(0, pinned)
    assert np.array_equal(q[held], q0[held]) and np.array_equal(qd[held], qd0[held])
    c, axes = _fit_reference(q0[:42], "bounding_sphere")
    d = q0[42:] - c
    inside = np.linalg.norm(d, axis=1) < axes[0]
    assert inside.sum() > 3  # the balls do overlap
    normal = d[inside] / np.linalg.norm(d[inside], axis=1)[:, None]
    assert np.allclose(q[42:][inside], c + axes[0] * normal, rtol=0, atol=1e-12)
    mass = model.particle_mass
    u = (mass[:42, None] * qd0[:42]).sum(axis=0) / mass[:42].sum()
    before = ((qd0[42:][inside] - u) * normal).sum(axis=1)
    after = ((qd[42:][inside] - u) * normal).sum(axis=1)
    approaching = before < 0
    assert np.all(approaching == (after != before))  # the receding ones keep their velocity
    assert np.allclose(after[approaching], -restitution * before[approaching], atol=1e-12)
    assert np.array_equal(q[42:][~inside], q0[42:][~inside])
    change = (mass[42:, None] * (qd[42:] - qd0[42:])).sum(axis=0)
    assert np.allclose(qd[pinned:42], qd0[pinned:42] - change / mass[:42].sum(), atol=1e-12)

    model = two_balls(1.2)  # 0.2 m apart
    sim = sb.Simulator(model, integrator="symplectic_euler", dt=1e-3)
    state = model.state()
    closest, highest = np.inf, -np.inf
    for _ in range(100):  # 2 s
        sim.run(state, 20)
        centres = [state.particle_q[s].mean(axis=0) for s in (slice(0, 42), slice(42, 84))]
        closest = min(closest, np.linalg.norm(centres[1] - centres[0]))
        highest = max(highest, centres[1][1])
    assert closest > 0.4  # measured 0.51 and 0.54
    assert highest < 1.2
