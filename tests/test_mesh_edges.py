"""Edge contacts of mesh colliders (``core/collision/mesh.hpp``, ``edge_contacts``): the
sharp edges and corners of a mesh collider against the soft bodies' edges and triangles,
so that a ridge or a corner cannot pass between soft vertices that all stay outside."""

from __future__ import annotations

import re

import numpy as np
import pytest

import softbody as sb
from softbody.collision.mesh_collider import sharp_edges
from softbody.mesh.topology import unique_edges

RIDGE_TOP = 0.5 * np.sqrt(2.0)  # a unit cube turned 45 degrees about z: its top edge's height


def crossings(q: np.ndarray, tri: np.ndarray, a: np.ndarray, b: np.ndarray) -> int:
    """How many (segment, triangle) pairs cross: each segment a[k]-b[k] (E, 3) against each
    triangle q[tri] (T, 3, 3), brute force: the segment's ends strictly on opposite sides of
    the triangle's plane and the crossing point strictly inside it (its three signed
    sub-areas along the normal > 0)."""
    p0, p1, p2 = q[tri[:, 0]], q[tri[:, 1]], q[tri[:, 2]]
    n = np.cross(p1 - p0, p2 - p0)
    total = 0
    for x0, x1 in zip(a, b, strict=True):
        da = np.einsum("ij,ij->i", x0 - p0, n)
        db = np.einsum("ij,ij->i", x1 - p0, n)
        straddle = da * db < 0
        s = da / np.where(straddle, da - db, 1.0)
        x = x0 + s[:, None] * (x1 - x0)
        w0 = np.einsum("ij,ij->i", np.cross(p1 - x, p2 - x), n)
        w1 = np.einsum("ij,ij->i", np.cross(p2 - x, p0 - x), n)
        w2 = np.einsum("ij,ij->i", np.cross(p0 - x, p1 - x), n)
        total += int(np.count_nonzero(straddle & (w0 > 0) & (w1 > 0) & (w2 > 0)))
    return total


def collider_crossings(model, state, collider: sb.ColliderMesh) -> int:
    """Crossings of every edge of the collider's mesh (in its pose in ``state``) through
    the soft triangles."""
    world = state.collider_q[0] + collider.data.vertices @ state.collider_rotation[0].T
    e = unique_edges(collider.data.triangles)
    return crossings(state.particle_q, model.tri_indices, world[e[:, 0]], world[e[:, 1]])


def ridge(sharp_angle=30.0, **kw) -> sb.ColliderMesh:
    """The 12-triangle mesh of a unit cube turned 45 degrees about z: an edge along z on
    top, at y = RIDGE_TOP."""
    rot = sb.collision.rotation_about((0, 0, 1), np.pi / 4)
    kw = {"restitution": 0.0, "friction": 0.8} | kw
    return sb.ColliderMesh(sb.box((1.0, 1.0, 1.0)), rotation=rot, sharp_angle=sharp_angle,
                           **kw)  # fmt: skip


def ball_over(collider, *, integrator="midpoint", dt=5e-4, gravity=(0.0, -9.81, 0.0),
              velocity=(0.0, 0.0, 0.0), center=(0.0, 1.1, 0.0), **kw):  # fmt: skip
    """A 162-vertex ball of radius 0.3 (edges about 0.1 m) above ``collider``."""
    builder = sb.ModelBuilder(gravity=gravity)
    builder.add_soft_body(sb.icosphere(2, radius=0.3, center=center), mass=1.0,
                          stiffness=800.0, damping=2.0, gas=100.0, velocity=velocity)  # fmt: skip
    builder.add_collider(collider)
    model = builder.finalize()
    return model, sb.Simulator(model, integrator=integrator, dt=dt, **kw)



def most_crossings(sim, model, state, collider, chunks: int, count) -> int:
    """Runs `chunks` chunks of 5 steps, returning the most crossings `count(model, state,
    collider)` found after any of them."""
    worst = 0
    for _ in range(chunks):
        sim.run(state, 5)
        worst = max(worst, count(model, state, collider))
    return worst

def test_a_box_has_twelve_sharp_edges_listed_once():
    """The 12-triangle box has 18 edges: its 12 box edges (faces at 90 degrees, convex)
    are sharp and listed once each, by the triangle whose first vertex index is the
    lower, with the triangle across them; the 6 face diagonals (flat) are not. Above 90
    degrees, or with sharp_angle None, no edge is; a 1,280-triangle sphere (faces about 10
    degrees apart) has none at the default 30."""
    box = sb.box((1.0, 0.4, 1.0))
    flags = sharp_edges(box.vertices, box.faces, 30.0)
    t, k = np.nonzero(flags >= 0)
    assert len(t) == 12
    a, b = box.faces[t, k], box.faces[t, (k + 1) % 3]
    assert np.all(a < b)
    assert len({(int(x), int(y)) for x, y in zip(a, b, strict=True)}) == 12
    # each is an edge of a box (its ends differ in one coordinate) shared with the twin
    d = np.abs(box.vertices[a] - box.vertices[b]) > 1e-12
    assert np.all(d.sum(axis=1) == 1)
    twin = box.faces[flags[t, k]]
    assert np.all(np.any(twin == a[:, None], axis=1) & np.any(twin == b[:, None], axis=1))
    assert not np.any(sharp_edges(box.vertices, box.faces, 91.0) >= 0)
    assert not np.any(sharp_edges(box.vertices, box.faces, None) >= 0)
    ball = sb.icosphere(3, radius=0.5)
    assert not np.any(sharp_edges(ball.vertices, ball.faces, 30.0) >= 0)
    assert np.count_nonzero(sharp_edges(ball.vertices, ball.faces, 1.0) >= 0) == 1920


def test_tree_nodes_know_whether_they_hold_a_sharp_edge():
    """The tree's node flags (the edge contacts skip a subtree without a sharp edge): a
    node is flagged exactly when one of the triangles below it (found by walking its
    children) has a sharp edge. On a box of 8 x 8 squares a side, the 96 sharp edge pieces
    lie along its 12 edges, so some nodes (inside the faces) are not flagged."""
    data = sb.ColliderMesh(sb.box((1.0, 1.0, 1.0), subdivisions=3)).data
    assert np.count_nonzero(data.sharp_edges >= 0) == 96

    def below(node):
        b, e = data.node_tris[node]
        if e > b:
            return list(range(b, e))
        return below(data.node_children[node, 0]) + below(data.node_children[node, 1])

    expected = [int(np.any(data.sharp_edges[below(k)] >= 0)) for k in range(len(data.node_tris))]
    np.testing.assert_array_equal(data.node_sharp, expected)
    assert data.node_sharp[0] == 1 and 0 in data.node_sharp
    assert not np.any(sb.ColliderMesh(sb.box((1, 1, 1)), sharp_angle=None).data.node_sharp)


def test_concave_edges_are_not_sharp():
    """A unit cube whose top face is a funnel (4 triangles down to a centre 0.3 m below the
    top): the 4 funnel edges between its faces are valleys (concave: soft vertices meet
    their faces first) and are not listed; the cube's other 12 edges (the rim's now at 121
    degrees, all convex) are."""
    box = sb.box((1.0, 1.0, 1.0))
    top = np.all(box.vertices[box.faces][:, :, 1] > 0.4, axis=1)
    rim = [int(i) for i in np.nonzero(box.vertices[:, 1] > 0.4)[0]]
    # the rim's corners in turn about +y, each funnel triangle wound outward (up)
    rim.sort(key=lambda i: -np.arctan2(box.vertices[i, 2], box.vertices[i, 0]))
    centre = len(box.vertices)
    funnel = [(rim[(k + 1) % 4], centre, rim[k]) for k in range(4)]
    vertices = np.vstack([box.vertices, [0.0, 0.2, 0.0]])
    mesh = sb.ColliderMesh(sb.TriMesh(vertices, np.vstack([box.faces[~top], funnel]))).mesh
    flags = sharp_edges(mesh.vertices, mesh.faces, 30.0)
    t, k = np.nonzero(flags >= 0)
    a, b = mesh.faces[t, k], mesh.faces[t, (k + 1) % 3]
    centre = int(np.argmin(np.linalg.norm(mesh.vertices - [0.0, 0.2, 0.0], axis=1)))
    assert not np.any((a == centre) | (b == centre))
    assert len(t) == 12


def test_sharp_angle_is_checked():
    """A sharp_angle that is not a number of degrees in [0, 180] is a ValueError naming
    it."""
    with pytest.raises(ValueError, match="sharp_angle"):
        sb.ColliderMesh(sb.box((1.0, 1.0, 1.0)), sharp_angle=200.0)
    with pytest.raises(ValueError, match="sharp_angle"):
        sb.ColliderMesh(sb.box((1.0, 1.0, 1.0)), sharp_angle=float("nan"))


@pytest.mark.parametrize("angle", [30.0, None])
def test_a_ball_dropped_on_a_ridge_is_not_cut_by_it(angle):
    """A ball dropped onto the top edge of a 12-triangle box mesh (turned 45 degrees, the
    edge up): with edge contacts, at every 5th step of 0.8 s no edge of the box passes
    through a triangle of the ball (a brute-force segment-triangle test) and the ball
    rides on the edge (its lowest vertex not below the edge's height less 0.01 m); with
    edge contacts off (sharp_angle None: vertices only), the same check finds the edge
    through the ball, the edge between its vertices (the check can fail)."""
    collider = ridge(angle)
    model, sim = ball_over(collider)
    state = model.state()
    worst = most_crossings(sim, model, state, collider, 320, collider_crossings)
    if angle is None:
        assert worst > 0
    else:
        assert worst == 0
        assert state.particle_q[:, 1].min() > RIDGE_TOP - 0.01


@pytest.mark.parametrize(("integrator", "dt"), [("midpoint", 5e-4), ("implicit_euler", 2e-3)])
def test_a_fast_ball_thrown_at_a_ridge_is_never_cut(integrator, dt):
    """No gravity, a ball thrown at 30 m/s down onto the ridge (it crosses its 0.1 m edges
    in 7 and 2 steps): after every step of 0.1 s no box edge passes through a ball
    triangle (brute-force segment-triangle test), and the ball bounced back up. The edge
    test is at the step's end; the vertices' continuous test keeps them outside, so a
    soft edge across the ridge ends its step across it and is caught."""
    collider = ridge(restitution=0.5, friction=0.3)
    model, sim = ball_over(collider, integrator=integrator, dt=dt, gravity=(0.0, 0.0, 0.0),
                           velocity=(0.0, -30.0, 0.0), center=(0.0, 1.02, 0.0))  # fmt: skip
    state = model.state()
    for _ in range(round(0.1 / dt)):
        sim.run(state, 1)
        assert collider_crossings(model, state, collider) == 0
    assert sb.body_center_of_mass(model, state)[0, 1] > 1.02


def corner_up() -> np.ndarray:
    """The rotation (3, 3) turning a cube's diagonal (1, 1, 1) to +y: a corner up."""
    a = np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0)
    axis = np.cross(a, [0.0, 1.0, 0.0])
    return sb.collision.rotation_about(axis / np.linalg.norm(axis), np.arccos(a[1]))


def cloth_over_corner(**kw) -> tuple[sb.Model, sb.ColliderMesh]:
    """A 0.8 x 0.8 m cloth (16 x 16 squares) held flat 0.52 m up over the corner of a 0.5
    m cube standing on that corner's opposite (``kw``: the collider's keywords, such as
    sharp_angle): the model and the collider."""
    collider = sb.ColliderMesh(sb.box((0.5, 0.5, 0.5)), restitution=0.0, friction=0.5,
                               rotation=corner_up(), **kw)  # fmt: skip
    sheet = sb.rectangle((0.8, 0.8), (16, 16))
    flat = sheet.vertices[:, [0, 2, 1]] * [1.0, 0.0, 1.0] + [0.013, 0.52, 0.021]
    builder = sb.ModelBuilder()
    builder.add_cloth(sb.TriMesh(flat, sheet.faces), mass=0.1, stiffness=300.0, damping=0.05)
    builder.add_collider(collider)
    return builder.finalize(), collider


@pytest.mark.parametrize("angle", [30.0, None])
def test_cloth_draped_over_a_box_corner_is_not_pierced(angle):
    """A 0.8 x 0.8 m cloth (16 x 16 squares, 5 cm edges) dropped onto the corner of a
    0.5 m cube standing on that corner's opposite: with edge contacts, at every 5th step
    of 0.6 s no edge of the cube passes through a cloth triangle (brute-force segment-
    triangle test) and the cloth lies over the tip (its highest point above the tip's
    height, 0.433 m); without (sharp_angle None), the tip pokes through the cloth between
    its vertices and the check finds it."""
    model, collider = cloth_over_corner(sharp_angle=angle)
    sim = sb.Simulator(model, integrator="midpoint", dt=5e-4)
    state = model.state()
    worst = most_crossings(sim, model, state, collider, 240, collider_crossings)
    tip = 0.25 * np.sqrt(3.0)
    if angle is None:
        assert worst > 0
    else:
        assert worst == 0
        assert state.particle_q[:, 1].max() > tip


def test_cloth_resting_on_a_corner_presses_with_its_weight():
    """The cloth over the cube's corner (implicit Euler at 2 ms, no ground), settled for 3
    s: over the next second the impulse the cube receives is the cloth's weight m g
    (static equilibrium) within 0.1 % (measured 6e-6), with the cloth lying on the tip
    (its highest point above the tip, held by the corner contacts) and no cube edge
    through it."""
    model, collider = cloth_over_corner()
    sim = sb.Simulator(model, integrator="implicit_euler", dt=2e-3)
    state = model.state()
    sim.run(state, 1500)
    sim.run(state, 500)  # this call's impulses: 1 s
    np.testing.assert_allclose(state.collider_impulse[0], [0.0, -0.1 * 9.81, 0.0],
                               atol=1e-3 * 0.1 * 9.81)  # fmt: skip
    assert state.particle_q[:, 1].max() > 0.25 * np.sqrt(3.0)
    assert collider_crossings(model, state, collider) == 0


def test_edge_contact_impulse_is_the_ball_s_momentum_change():
    """No gravity, a ball thrown down at 3 m/s onto the ridge (restitution 0.5, friction
    0.5): the impulse the collider receives over the run is minus the change of the ball's
    momentum (internal forces sum to zero; every contact impulse, the edge contacts'
    included, has its opposite on the collider), to 1e-9 of it. The edge contacts took
    part: the impulse differs from the run without them by more than 0.1 % (measured 0.9
    %; a run in which no edge contact acts is the vertex-only run to the bit, as on the
    flat box below)."""
    out = {}
    for angle in (30.0, None):
        model, sim = ball_over(ridge(angle, restitution=0.5, friction=0.5), gravity=(0, 0, 0),
                               velocity=(0.4, -3.0, 0.2), center=(0.0, 1.05, 0.0))  # fmt: skip
        state = model.state()
        m = model.particle_mass[:, None]
        p0 = (m * state.particle_qd).sum(axis=0)
        sim.run(state, 400)
        dp = (m * state.particle_qd).sum(axis=0) - p0
        j = state.collider_impulse[0]
        np.testing.assert_allclose(j, -dp, atol=1e-9 * np.linalg.norm(dp))
        assert dp[1] > 3.0  # it bounced off
        out[angle] = j
    assert np.linalg.norm(out[30.0] - out[None]) > 1e-3 * np.linalg.norm(out[None])


@pytest.mark.parametrize(
    ("motion", "center"),
    [
        (sb.MotionTranslation(velocity=(0.0, 1.5, 0.0)), (0.0, 1.1, 0.0)),
        (sb.MotionRotation(angular_velocity=(0.0, 0.0, 2.0)), (0.0, 1.0, 0.0)),
    ],
)
def test_a_moving_ridge_pushes_the_ball_without_cutting_it(motion, center):
    """No gravity, the ridge moving: rising at 1.5 m/s into a ball at rest above it, or
    the box spinning at 2 rad/s about its axis under a ball touching it (its edges sweep
    through where the ball is). The edges' speed enters the contacts' relative velocity:
    at every 5th step of 0.25 s no box edge passes through a ball triangle (brute-force
    segment-triangle test), and the impulses the collider received are minus the ball's
    momentum change (to 1e-9 of it), which is not small: the ridge pushed it."""
    collider = ridge(motion=motion, friction=0.5, restitution=0.3)
    model, sim = ball_over(collider, gravity=(0.0, 0.0, 0.0), center=center)
    state = model.state()
    m = model.particle_mass[:, None]
    p0 = (m * state.particle_qd).sum(axis=0)
    impulse = np.zeros(3)
    for _ in range(100):
        sim.run(state, 5)
        impulse += state.collider_impulse[0]
        assert collider_crossings(model, state, collider) == 0
    dp = (m * state.particle_qd).sum(axis=0) - p0
    np.testing.assert_allclose(impulse, -dp, atol=1e-9 * np.linalg.norm(dp))
    assert np.linalg.norm(dp) > 0.5  # [kg m/s], the ball's mass 1 kg


def test_vertex_contacts_are_unchanged_away_from_sharp_edges():
    """A ball bouncing in the middle of a box mesh's top face, far from its edges: the run
    with edge contacts is bit for bit the run without them (the edge stage changes
    nothing where no soft edge reaches a sharp edge)."""
    states = []
    for angle in (30.0, None):
        model, sim = ball_over(sb.ColliderMesh(sb.box((3.0, 0.4, 3.0)), sharp_angle=angle))
        state = model.state()
        lowest = np.inf
        for _ in range(30):
            sim.run(state, 50)
            lowest = min(lowest, state.particle_q[:, 1].min())
        assert lowest < 0.21  # it reached the top (y = 0.2)
        states.append(state)
    np.testing.assert_array_equal(states[0].particle_q, states[1].particle_q)
    np.testing.assert_array_equal(states[0].particle_qd, states[1].particle_qd)
    np.testing.assert_array_equal(states[0].collider_impulse, states[1].collider_impulse)


@pytest.mark.parametrize(
    ("integrator", "dt", "kw"),
    [
        ("midpoint", 5e-4, {}),
        ("rk4", 5e-4, {}),
        ("symplectic_euler", 5e-4, {}),
        ("velocity_verlet", 5e-4, {}),
        ("implicit_euler", 2e-3, {}),
        ("bdf2", 2e-3, {}),
        ("projective", 2e-3, {"projective_iterations": 10}),
        ("xpbd", 2e-3, {}),
    ],
)
def test_every_solver_keeps_the_ridge_out_of_the_ball(integrator, dt, kw):
    """Every solver ends its steps with the contact stage, edge contacts included: the
    ball dropped on the ridge is never cut by a box edge at the sampled steps (every 0.01
    s of 0.8 s, brute-force segment-triangle test) and rides on the edge: its lowest vertex
    ends within 0.02 m of the edge's height (measured -0.002 to +0.023 m; without edge
    contacts every solver ends with the edge 0.025-0.04 m deep in the ball)."""
    collider = ridge()
    model, sim = ball_over(collider, integrator=integrator, dt=dt, **kw)
    state = model.state()
    steps = round(0.01 / dt)
    lowest = np.inf
    for _ in range(80):
        sim.run(state, steps)
        assert collider_crossings(model, state, collider) == 0
        lowest = min(lowest, state.particle_q[:, 1].min())
    assert lowest < RIDGE_TOP + 0.05  # it fell onto the edge (from 0.09 above it)
    assert state.particle_q[:, 1].min() > RIDGE_TOP - 0.02


SCENE = """
[simulation]
integrator = "midpoint"
dt = 0.0005
duration = 0.01

[[colliders]]
type = "mesh"
mesh = {{ shape = "box", extents = [1.0, 0.4, 1.0] }}
{extra}

[[bodies]]
mesh = {{ shape = "icosphere", subdivisions = 1, radius = 0.2 }}
position = [0.0, 0.8, 0.0]
mass = 1.0
stiffness = 800.0
gas = {{ law = "isothermal", nrt = 200.0 }}
"""


def test_scene_mesh_colliders_take_sharp_angle(tmp_path, capsys):
    """A scene's mesh collider has the box's 12 sharp edges by default, none with
    ``sharp_angle = 180`` (the edge contacts off); an angle outside [0, 180] is one line on
    stderr from ``softbody run`` naming the key, exit 2."""
    from softbody.cli import main
    from softbody.scenes.loader import load_scene

    counts = []
    for name, extra in [("a", ""), ("b", "sharp_angle = 180")]:
        (tmp_path / f"{name}.toml").write_text(SCENE.format(extra=extra))
        model = load_scene(tmp_path / f"{name}.toml").model
        counts.append(int(np.count_nonzero(model.collider_mesh_sharp_edges >= 0)))
    assert counts == [12, 0]
    (tmp_path / "bad.toml").write_text(SCENE.format(extra="sharp_angle = 200"))
    code = main(["run", str(tmp_path / "bad.toml"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err
    assert "colliders.0.sharp_angle" in err, err


# -- smooth colliders: chords and caps ------------------------------------------------------
def soft_mesh_crossings(model, state, collider: sb.ColliderMesh) -> int:
    """(edge, triangle) crossings between the soft surfaces and the collider's mesh in its
    pose in ``state``, both ways: soft edges through collider triangles and collider edges
    through soft triangles (edge_crossings, the independent NumPy check of the contact
    scenes, over the two surfaces together)."""
    from softbody.collision.crossings import edge_crossings

    q, n = state.particle_q, len(state.particle_q)
    world = state.collider_q[0] + collider.data.vertices @ state.collider_rotation[0].T
    tri, soft_tri = collider.data.triangles, model.tri_indices
    soft_edges = unique_edges(soft_tri)
    found = edge_crossings(np.vstack([q, world]), np.vstack([soft_tri, tri + n]),
                           np.vstack([soft_edges, unique_edges(tri) + n]))  # fmt: skip
    soft_edge = found[:, 0] < len(soft_edges)
    soft_triangle = found[:, 1] < len(soft_tri)
    return int(np.count_nonzero(soft_edge != soft_triangle))


def smooth_ball_collider(**kw) -> sb.ColliderMesh:
    """A 0.2 m sphere mesh (1,280 triangles, neighbouring faces about 10 degrees apart: no
    edge sharper than the default sharp_angle) with its top at y = 0.2."""
    return sb.ColliderMesh(sb.icosphere(3, radius=0.2), restitution=0.0, friction=0.5, **kw)


def smooth_capsule_collider(**kw) -> sb.ColliderMesh:
    """A capsule of radius 0.1 m lying along x (0.6 m between its caps' centres; 8 rings a
    cap, 32 segments around: faces about 11 degrees apart), its top at y = 0.1."""
    rot = sb.collision.rotation_about((0, 0, 1), np.pi / 2)
    return sb.ColliderMesh(sb.capsule(0.1, 0.6, rings=8, segments=32), rotation=rot,
                           restitution=0.0, friction=0.5, **kw)  # fmt: skip


@pytest.mark.parametrize("angle", [30.0, None])
def test_coarse_cloth_on_a_smooth_sphere_is_not_cut(angle):
    """A 0.8 m cloth of 8 x 8 squares (0.1 m edges: chords across a 0.2 m sphere sag up
    to 6 mm) dropped over a finely tessellated sphere mesh with no sharp edge. Reference:
    at every 5th step of 0.6 s no cloth edge passes through a sphere triangle and no sphere
    edge through a cloth triangle (edge_crossings both ways), and the cloth lies on the top
    (its highest point above the sphere's). The sphere's edges are all flatter than
    sharp_angle: before the edge contacts took every bent edge and face, the default run
    was the vertex-only run (sharp_angle None), whose chords the same check finds."""
    collider = smooth_ball_collider(sharp_angle=angle)
    assert not np.any(collider.data.sharp_edges >= 0)
    sheet = sb.rectangle((0.8, 0.8), (8, 8))
    flat = sheet.vertices[:, [0, 2, 1]] * [1.0, 0.0, 1.0] + [0.011, 0.25, 0.017]
    builder = sb.ModelBuilder()
    builder.add_cloth(sb.TriMesh(flat, sheet.faces), mass=0.1, stiffness=300.0, damping=0.05)
    builder.add_collider(collider)
    model = builder.finalize()
    sim = sb.Simulator(model, integrator="midpoint", dt=5e-4)
    state = model.state()
    worst = most_crossings(sim, model, state, collider, 240, soft_mesh_crossings)
    if angle is None:
        assert worst > 0
    else:
        assert worst == 0
        assert state.particle_q[:, 1].max() > 0.2


@pytest.mark.parametrize(
    ("integrator", "dt", "angle"),
    [("midpoint", 5e-4, 30.0), ("implicit_euler", 2e-3, 30.0), ("midpoint", 5e-4, None)],
)
def test_coarse_ball_on_a_smooth_capsule_is_not_cut(integrator, dt, angle):
    """A 42-vertex ball (radius 0.25 m, edges about 0.16 m: longer than the capsule's 0.1 m
    radius) dropped across a smooth capsule mesh lying along x. Reference: at every 5th step
    of 0.8 s no ball edge passes through a capsule triangle and no capsule edge through a
    ball triangle (edge_crossings both ways: a chord under the tube and the tube through a
    ball face), and the ball rests on it (its lowest point not below the capsule's axis).
    Vertex contacts alone (sharp_angle None) leave the ball cut."""
    collider = smooth_capsule_collider(sharp_angle=angle)
    assert not np.any(collider.data.sharp_edges >= 0)
    builder = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    builder.add_soft_body(sb.icosphere(1, radius=0.25, center=(0.013, 0.4, 0.021)), mass=1.0,
                          stiffness=800.0, damping=2.0, gas=100.0)  # fmt: skip
    builder.add_collider(collider)
    model = builder.finalize()
    sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    worst = most_crossings(sim, model, state, collider, round(0.8 / (5 * dt)), soft_mesh_crossings)
    if angle is None:
        assert worst > 0
    else:
        assert worst == 0
        assert state.particle_q[:, 1].min() > 0.0


def pinned_strip_through_a_box(thickness: float = 0.0) -> sb.Model:
    """A pinned 2 m x 4 mm strip (3 x 1 squares, every particle pinned) lying along x at
    y = 0 through a 0.5 m box mesh at the origin: its particles (x = +-1, +-1/3 m) all
    outside the box, its long edges through it, no box edge through the strip."""
    sheet = sb.rectangle((2.0, 0.004), (3, 1))
    flat = sheet.vertices[:, [0, 2, 1]] * [1.0, 0.0, 1.0]
    builder = sb.ModelBuilder()
    builder.add_cloth(sb.TriMesh(flat, sheet.faces), mass=0.1, stiffness=300.0,
                      pinned=np.arange(len(flat)))  # fmt: skip
    builder.add_collider(sb.ColliderMesh(sb.box((0.5, 0.5, 0.5)), restitution=0.0,
                                         friction=0.5))  # fmt: skip
    if thickness > 0.0:
        builder.set_soft_contact("surface", thickness=thickness)
    return builder.finalize()


@pytest.mark.parametrize(
    ("integrator", "thickness"),
    [("midpoint", 0.0), ("implicit_euler", 0.0), ("midpoint", 1e-3), ("implicit_euler", 1e-3)],
)
def test_a_pinned_edge_through_a_mesh_collider_stops_the_run(integrator, thickness):
    """Issue 32: when a crossing is detected anyway, the run stops and says where. A soft
    edge through a mesh collider whose particles are all pinned cannot be pushed out by the
    edge contacts (mesh.hpp, chords): the first step stops with a SimulationError naming
    the mesh collider and the edge (two particles of one strip triangle, the first the
    error's particle), the state left at the step's start (with and without the thickness
    stage, whose collider pass reports it the same way)."""
    model = pinned_strip_through_a_box(thickness)
    sim = sb.Simulator(model, integrator=integrator, dt=5e-4)
    state = model.state()
    start = state.particle_q.copy()
    with pytest.raises(sb.SimulationError, match="crossed mesh collider 0 at step 0") as err:
        sim.run(state, 3)
    found = re.search(r"the edge from particle (\d+) to particle (\d+)", str(err.value))
    assert found is not None
    a, b = int(found[1]), int(found[2])
    assert err.value.particle == a and err.value.step == 0
    tri = model.tri_indices
    assert np.any(np.isin(tri, [a]).any(axis=1) & np.isin(tri, [b]).any(axis=1))
    # the edge does pass through the box (x from one side of it to the other)
    assert state.particle_q[a, 0] * state.particle_q[b, 0] < 0.0
    assert state.step_count == 0
    np.testing.assert_array_equal(state.particle_q, start)


# -- friction where a sheet rests on the ridges and corners of a smooth mesh ----------------
DRAPE_CENTRE = np.array([0.65, 0.3, 0.0])  # the bending guide's drape sphere (radius 0.25 m)


def drape_offset(collider, shift: float = 0.0) -> float:
    """The bending guide's stiff drape sheet (1 x 1 m, 30 x 30 squares, 0.15 kg, stiffness
    300, damping 0.2, D = 1e-2 N m) dropped from 0.7 m, ``shift`` [m] along x off the axis
    of the sphere at DRAPE_CENTRE (``collider``), with the ground: 1.6 s of implicit Euler
    at 2 ms. Returns how far [m] its centre ends off the sphere's vertical axis."""
    sheet = sb.rectangle((1.0, 1.0), (30, 30))
    flat = sheet.vertices[:, [0, 2, 1]] * [1.0, 0.0, 1.0] + [0.65 + shift, 0.7, 0.0]
    builder = sb.ModelBuilder()
    builder.add_collider(sb.ColliderPlane())
    builder.add_collider(collider)
    builder.add_cloth(sb.TriMesh(flat, sheet.faces), mass=0.15, stiffness=300.0, damping=0.2,
                      bending=sb.Bending(1e-2))  # fmt: skip
    model = builder.finalize()
    state = model.state()
    sb.Simulator(model, integrator="implicit_euler", dt=2e-3).run(state, 800)
    centre = state.particle_q.mean(axis=0) - DRAPE_CENTRE
    return float(np.hypot(centre[0], centre[2]))


def drape_sphere_mesh(friction: float) -> sb.ColliderMesh:
    """The drape sphere as a 1,280-triangle mesh collider (default sharp_angle: every edge
    bent, none sharp; the edge contacts on)."""
    return sb.ColliderMesh(sb.icosphere(3, radius=0.25, center=DRAPE_CENTRE),
                           friction=friction)  # fmt: skip


def test_a_stiff_sheet_rests_on_a_smooth_sphere_mesh():
    """Issue 32 (cloth slid off smooth mesh colliders). Reference: the stiff drape sheet
    (friction 0.1) stays where it lands on top of a sphere, as a mesh vertex resting on a
    mesh collider goes back to where its path entered it each step (dropped centred on the
    analytic ColliderSphere it stays centred by symmetry). On the 1,280-triangle mesh of
    the sphere the sheet rests on the mesh's corners and chords (they hold it 0.2-0.8 mm
    out, its vertices off the faces), and a corner's and a chord's first push of a step
    takes the contact point back to where its path crossed its level, as a vertex contact
    does. Dropped 3 cm off the axis, the sheet ends within 5 mm of where it landed
    (measured 3.03 cm; the sheet still sways: within 8 mm of the held sheet at every 0.2 s
    up to 3.2 s; with the chords pushed straight out, 5.5 cm, having slid downhill, and
    5.35 cm at 3.2 s; before the corners were held too, 0.45 m: on the ground). Dropped
    centred it ends within 1 cm of the axis (the tessellation breaks the symmetry as it
    lands; measured 0.004 m; chords pushed straight out 0.007 m; before, 0.23 m: it slid
    off). Frictionless the mesh lets it slide off (measured 0.30 m): the contacts hold
    positions back, the friction their velocities. (The analytic sphere, whose contacts
    keep a particle's motion along its surface and which has no static friction, lets the
    sheet dropped 3 cm off slide off: 0.45 m.)"""
    assert drape_offset(drape_sphere_mesh(0.1)) < 0.01
    assert abs(drape_offset(drape_sphere_mesh(0.1), shift=0.03) - 0.03) < 0.005
    assert drape_offset(drape_sphere_mesh(0.0)) > 0.2


INCLINE = np.radians(20.0)  # the slope of the inclined plane and box mesh below


def incline_slide(collider, height: float, friction: float, steps: int = 150) -> float:
    """A 0.1 m cloth patch (4 x 4 squares, 0.01 kg) laid at rest ``height`` [m] over the top
    face of a 2 x 0.2 x 2 m box turned INCLINE about z (its top face at y = 0.1 before the
    turn), ``collider`` the box or its top face's plane: implicit Euler at 2 ms for
    ``steps`` steps. Returns how far [m] the patch's centre went down the slope."""
    rot = sb.collision.rotation_about((0, 0, 1), INCLINE)
    sheet = sb.rectangle((0.1, 0.1), (4, 4))
    local = sheet.vertices[:, [0, 2, 1]] * [1.0, 0.0, 1.0] + [0.013, 0.1 + height, 0.021]
    builder = sb.ModelBuilder()
    builder.add_cloth(sb.TriMesh(local @ rot.T, sheet.faces), mass=0.01, stiffness=300.0)
    builder.add_collider(collider)
    model = builder.finalize()
    state = model.state()
    start = state.particle_q.mean(axis=0)
    sb.Simulator(model, integrator="implicit_euler", dt=2e-3).run(state, steps)
    return float((state.particle_q.mean(axis=0) - start) @ (rot @ [-1.0, 0.0, 0.0]))


@pytest.mark.parametrize("friction", [0.0, 0.05, 0.3])
def test_a_patch_slides_down_an_inclined_box_mesh_as_down_the_plane(friction):
    """A cloth patch resting on the top face of an inclined box mesh (20 degrees; 4 x 4
    squares a face, so it slides across the face's tessellation; edge contacts on) slides
    as on a ColliderPlane of the same pose. Reference, closed form of the discrete scheme:
    every vertex touches every step (restitution 0), implicit Euler moves it by dt (v + a
    dt) and the contact keeps c = 1 - friction of its tangential velocity, so after N
    steps of dt the patch went a dt^2 (N - c (1 - c^N) / (1 - c)) / (1 - c) down the slope
    (a = g sin 20 deg; a dt^2 N (N + 1) / 2 frictionless). The plane and the mesh (the
    patch laid within its margin) each match it to 1e-6 of the distance (round-off: the
    scheme is exact; measured 3e-9): the edge contacts add no tangential motion on a
    flat face and remove none."""
    rot = sb.collision.rotation_about((0, 0, 1), INCLINE)
    steps, dt, c = 150, 2e-3, 1.0 - friction
    a = 9.81 * np.sin(INCLINE)
    if friction == 0.0:
        expected = a * dt**2 * steps * (steps + 1) / 2
    else:
        expected = a * dt**2 * (steps - c * (1 - c**steps) / (1 - c)) / (1 - c)
    plane = sb.ColliderPlane(point=rot @ [0.0, 0.1, 0.0], normal=rot @ [0.0, 1.0, 0.0],
                             restitution=0.0, friction=friction)  # fmt: skip
    box = sb.ColliderMesh(sb.box((2.0, 0.2, 2.0), subdivisions=2), rotation=rot,
                          restitution=0.0, friction=friction, margin=1e-4)  # fmt: skip
    assert np.any(box.data.sharp_edges >= 0)  # the edge contacts are on
    np.testing.assert_allclose(incline_slide(plane, 0.0, friction), expected, rtol=1e-6)
    np.testing.assert_allclose(incline_slide(box, 0.5e-4, friction), expected, rtol=1e-6)
