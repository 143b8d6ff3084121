"""Mesh colliders (``sb.ColliderMesh``): any closed triangle mesh as a rigid collider,
vertex against mesh, continuous, static, moving or driven through Control."""

from __future__ import annotations

import re

import numpy as np
import pytest

import softbody as sb
from softbody.collision.mesh_collider import inside_mesh

G = 9.81


def ball_on(collider, *, center=(0.05, 1.0, 0.02), mass=1.0, damping=2.0, integrator="midpoint",
            dt=5e-4, **kw):  # fmt: skip
    """A 162-vertex ball of radius 0.3 above ``collider``: its model and simulator."""
    builder = sb.ModelBuilder()
    builder.add_soft_body(sb.icosphere(2, radius=0.3, center=center), mass=mass,
                          stiffness=800.0, damping=damping, gas=200.0)  # fmt: skip
    builder.add_collider(collider)
    model = builder.finalize()
    return model, sb.Simulator(model, integrator=integrator, dt=dt, **kw)


def com_height(model, sim, steps, every=10):
    state = model.state()
    heights = []
    for _ in range(steps // every):
        sim.run(state, every)
        heights.append(sb.body_center_of_mass(model, state)[0, 1])
    return np.array(heights), state


def test_ball_bounces_on_a_box_mesh_as_on_the_analytic_box():
    """A ball dropped on the 12-triangle mesh of a 1 x 0.4 x 1 m box rebounds to the height
    it reaches on ColliderBox of the same size. Both catch a vertex by its path during the
    step (continuous), but the mesh puts it its margin (1.5e-4 m) outside the surface, so a
    vertex can be caught one step earlier or later: the rebound agrees within v dt + margin
    (v = sqrt(2 g 0.5) the impact speed; measured: 1.0e-3 m of 1.7e-3 m)."""
    kw = {"restitution": 0.5, "friction": 0.1}
    analytic = ball_on(sb.ColliderBox(half_extents=(0.5, 0.2, 0.5), **kw))
    mesh = ball_on(sb.ColliderMesh(sb.box((1.0, 0.4, 1.0)), **kw))
    margin = float(mesh[0].collider_mesh_margin[0])
    assert margin == pytest.approx(1e-4 * np.sqrt(1.0 + 0.16 + 1.0))
    ya, _ = com_height(*analytic, 3000)
    yb, state = com_height(*mesh, 3000)
    first = int(np.argmin(ya[:100]))
    rebound_a, rebound_b = ya[first : first + 100].max(), yb[first : first + 100].max()
    assert rebound_a > 0.8  # it bounced (from 1.0, the box's top at 0.2, radius 0.3)
    v = np.sqrt(2 * G * 0.5)
    assert rebound_b == pytest.approx(rebound_a, abs=v * 5e-4 + margin)
    assert state.particle_q[:, 1].min() >= 0.2  # no vertex below the box's top


def test_ball_rests_on_a_box_mesh_at_the_analytic_box_height():
    """At rest (restitution 0, friction 0.5, settled 10 s, averaged over 1 s) the ball's
    centre of mass on the box mesh lies where it lies on ColliderBox, within the margin
    the mesh keeps vertices outside (resting vertices within it are held each step as on
    the analytic box, with friction); and the contact force (impulse per second) on each
    equals the weight M g within 0.5 % (measured 0.01 %)."""
    kw = {"restitution": 0.0, "friction": 0.5}
    out = {}
    for name, collider in [("analytic", sb.ColliderBox(half_extents=(0.5, 0.2, 0.5), **kw)),
                           ("mesh", sb.ColliderMesh(sb.box((1.0, 0.4, 1.0)), **kw))]:  # fmt: skip
        model, sim = ball_on(collider, center=(0.05, 0.51, 0.02), mass=2.0, damping=3.0)
        state = model.state()
        sim.run(state, 20000)
        heights, impulse = [], np.zeros(3)
        for _ in range(100):
            sim.run(state, 20)
            heights.append(sb.body_center_of_mass(model, state)[0, 1])
            impulse += state.collider_impulse[0]
        out[name] = (np.mean(heights), impulse / 1.0)  # 2000 steps of 0.5 ms: 1 s
        margin = float(model.collider_mesh_margin[0])
        assert -impulse[1] == pytest.approx(2.0 * G, rel=5e-3)
    assert out["mesh"][0] == pytest.approx(out["analytic"][0], abs=margin)


def test_contact_force_of_a_ball_resting_on_a_mesh_plane_is_its_weight():
    """A ball at rest on a wide flat slab mesh (a 4 x 0.1 x 4 m box turned by 0.3 rad about
    y, so that its triangles' diagonals do not line up with the ball's): the impulse the
    collider receives per second is the weight M g (static equilibrium), within 0.5 %."""
    slab = sb.box((4.0, 0.1, 4.0), center=(0.0, -0.05, 0.0))
    collider = sb.ColliderMesh(slab, restitution=0.0, friction=0.5,
                               rotation=sb.collision.rotation_about((0, 1, 0), 0.3))  # fmt: skip
    model, sim = ball_on(collider, center=(0.2, 0.31, -0.1), mass=2.0, damping=3.0)
    state = model.state()
    sim.run(state, 20000)
    sim.run(state, 2000)  # impulses of this call: 1 s
    assert -state.collider_impulse[0, 1] == pytest.approx(2.0 * G, rel=5e-3)
    assert abs(state.collider_impulse[0, 0]) < 1e-3 * 2.0 * G
    assert abs(state.collider_impulse[0, 2]) < 1e-3 * 2.0 * G


def fast_ball(collider, speed, dt=1e-3):
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.add_soft_body(sb.icosphere(2, radius=0.2), mass=1.0, stiffness=2000.0, damping=2.0,
                          gas=50.0, velocity=(speed, 0.0, 0.0))  # fmt: skip
    builder.add_collider(collider)
    model = builder.finalize()
    return model, sb.Simulator(model, integrator="rk4", dt=dt)


@pytest.mark.parametrize("turn", [0.0, 0.4])
def test_fast_ball_never_ends_a_step_inside_a_thin_mesh_slab(turn):
    """A ball thrown at 30 m/s at a slab mesh 1 cm thick (crossed in a third of a step, so
    an inside test at the step's end alone would miss vertices that passed through): after
    every step no vertex is inside the mesh (an independent ray-parity test) and none got
    to the far side; the ball bounced back. Turned 0.4 rad about z, the slab meets the ball
    at a slant."""
    rot = sb.collision.rotation_about((0, 0, 1), turn)
    slab = sb.box((0.01, 1.0, 1.0))
    collider = sb.ColliderMesh(slab, restitution=0.5, friction=0.1, center=(0.6, 0.0, 0.0),
                               rotation=rot)  # fmt: skip
    model, sim = fast_ball(collider, 30.0)
    data = collider.data
    state = model.state()
    normal = rot[:, 0]
    for _ in range(120):
        sim.step(state)
        local = (state.particle_q - state.collider_q[0]) @ state.collider_rotation[0]
        assert not inside_mesh(data, local).any()
        assert ((state.particle_q - (0.6, 0.0, 0.0)) @ normal).max() <= -0.005
    assert np.mean(state.particle_qd[:, 0]) < 0  # it bounced back


def test_inside_test_of_the_checks_sees_inside():
    """The ray-parity test the checks use says inside for points inside the slab and
    outside for points beside it (so the test above could fail)."""
    data = sb.ColliderMesh(sb.box((0.01, 1.0, 1.0))).data
    points = np.array([[0.0, 0.1, 0.2], [0.004, -0.3, 0.4], [0.006, 0.0, 0.0], [0.0, 0.6, 0.0]])
    assert inside_mesh(data, points).tolist() == [True, True, False, False]


def test_moving_mesh_collider_pushes_a_ball():
    """A box mesh moving at a prescribed 2 m/s (no gravity) catches up with a ball at
    rest and pushes it: the ball ends moving at least as fast as the box, ahead of it and
    outside it, and the impulse the collider reports is minus the momentum the ball gained
    (Newton's third law)."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.add_soft_body(sb.icosphere(2, radius=0.3), mass=1.0, stiffness=800.0,
                          damping=1.0, gas=100.0)  # fmt: skip
    box = sb.box((0.2, 0.8, 0.8), center=(-1.0, 0.0, 0.0))
    collider = sb.ColliderMesh(box, restitution=0.2, friction=0.0,
                               motion=sb.MotionTranslation(velocity=(2.0, 0.0, 0.0)))  # fmt: skip
    builder.add_collider(collider)
    model = builder.finalize()
    sim = sb.Simulator(model, integrator="midpoint", dt=2e-4)
    state = model.state()
    total = np.zeros(3)
    for _ in range(40):  # 0.8 s: the box moves from x = -1 to 0.6
        sim.run(state, 100)
        total += state.collider_impulse[0]
        local = (state.particle_q - state.collider_q[0]) @ state.collider_rotation[0]
        assert not inside_mesh(collider.data, local).any()
    assert state.collider_q[0] == pytest.approx([0.6, 0.0, 0.0])
    momentum = (model.particle_mass[:, None] * state.particle_qd).sum(axis=0)
    assert momentum[0] >= 2.0 * 0.95  # at least the box's speed (restitution 0.2: a bit more)
    assert np.allclose(total, -momentum, atol=1e-9)
    assert state.particle_q[:, 0].min() > 0.6 + 0.1  # ahead of the box's front face


def test_control_drives_a_mesh_collider():
    """Control.collider_target moves a mesh collider's centre in a straight line to the
    target over a call, as for the analytic colliders; the pushed ball gains momentum."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.add_soft_body(sb.icosphere(2, radius=0.3), mass=1.0, stiffness=800.0,
                          damping=1.0, gas=100.0)  # fmt: skip
    builder.add_collider(sb.ColliderMesh(sb.icosphere(2, radius=0.2, center=(-1.0, 0.0, 0.0)),
                                         restitution=0.5, friction=0.0))  # fmt: skip
    model = builder.finalize()
    sim = sb.Simulator(model, integrator="midpoint", dt=2e-4)
    state = model.state()
    control = model.control()
    assert state.collider_q[0] == pytest.approx([-1.0, 0.0, 0.0])
    for k in range(40):
        control.collider_target = np.array([[-1.0 + 0.8 * (k + 1) / 40, 0.0, 0.0]])
        sim.run(state, 50, control)
    assert state.collider_q[0] == pytest.approx([-0.2, 0.0, 0.0])
    momentum = (model.particle_mass[:, None] * state.particle_qd).sum(axis=0)
    assert momentum[0] > 0.1


def _open_box() -> sb.TriMesh:
    box = sb.box((1.0, 1.0, 1.0))
    return sb.TriMesh(box.vertices, box.faces[:-1])


def _self_intersecting_box() -> sb.TriMesh:
    """One closed surface that passes through itself: a box whose corner is pulled through
    the opposite face."""
    box = sb.box((1.0, 1.0, 1.0))
    v = box.vertices.copy()
    corner = int(np.argmax(v.sum(axis=1)))
    v[corner] = (-1.0, 0.2, 0.2)
    return sb.TriMesh(v, box.faces)


def test_open_and_self_intersecting_meshes_are_refused_naming_the_file(tmp_path):
    """A mesh collider must be one closed surface that does not cross itself: an open
    mesh and a self-intersecting one are refused with a one-line ValueError naming the
    file (or "mesh" for one in memory)."""
    cases = [("open.obj", _open_box(), "open: 3 boundary edges"),
             ("crossed.obj", _self_intersecting_box(), "must not cross itself")]  # fmt: skip
    for name, mesh, reason in cases:
        path = tmp_path / name
        sb.save_mesh(mesh, path)
        with pytest.raises(ValueError, match=reason) as err:
            sb.ColliderMesh(path)
        assert str(err.value).startswith(str(path))
        assert "\n" not in str(err.value)
        with pytest.raises(ValueError, match=f"^mesh: .*{reason}"):
            sb.ColliderMesh(mesh)
    with pytest.raises(ValueError, match="no such file"):
        sb.ColliderMesh(tmp_path / "missing.obj")
    with pytest.raises(ValueError, match="margin must be finite and > 0"):
        sb.ModelBuilder().add_collider(sb.ColliderMesh(sb.box((1, 1, 1)), margin=-1.0))


def test_trimesh_and_inward_meshes_are_taken():
    """A trimesh.Trimesh is taken as it is, and an inward-wound mesh is turned outward (a
    ball dropped on it still stays above it)."""
    import trimesh

    box = sb.box((1.0, 0.4, 1.0))
    from_trimesh = sb.ColliderMesh(trimesh.Trimesh(box.vertices, box.faces, process=False))
    assert len(from_trimesh.data.triangles) == 12
    model, sim = ball_on(sb.ColliderMesh(box.flipped()))
    _, state = com_height(model, sim, 2000)
    assert state.particle_q[:, 1].min() >= 0.2


@pytest.mark.parametrize(
    ("integrator", "dt", "kw"),
    [
        ("midpoint", 5e-4, {}),
        ("rk4", 5e-4, {}),
        ("velocity_verlet", 5e-4, {}),
        ("implicit_euler", 2e-3, {}),
        ("bdf2", 2e-3, {}),
        ("projective", 2e-3, {"projective_iterations": 10}),
    ],
)
def test_every_solver_runs_against_a_mesh_collider(integrator, dt, kw):
    """Explicit, implicit and projective solvers all end their steps with the contact
    stage: a ball dropped on a box mesh (turned 0.5 rad about y, its top at y = 0) ends
    every sampled step outside it (ray-parity test) and comes to lie on it: its lowest
    vertex within 0.01 m of the top after 2 s (the implicit and projective solvers' larger
    steps let a resting vertex sink up to g dt^2 before it is caught)."""
    box = sb.box((1.0, 0.4, 1.0), center=(0.0, -0.2, 0.0))
    collider = sb.ColliderMesh(box, restitution=0.0, friction=0.8,
                               rotation=sb.collision.rotation_about((0, 1, 0), 0.5))  # fmt: skip
    model, sim = ball_on(collider, center=(0.0, 0.5, 0.0), integrator=integrator, dt=dt, **kw)
    state = model.state()
    steps = round(0.05 / dt)
    for _ in range(40):
        sim.run(state, steps)
        local = (state.particle_q - state.collider_q[0]) @ state.collider_rotation[0]
        assert not inside_mesh(collider.data, local).any()
    assert state.particle_q[:, 1].min() >= 0.0
    assert state.particle_q[:, 1].min() == pytest.approx(0.0, abs=0.01)
    assert sb.body_center_of_mass(model, state)[0, 1] < 0.35  # it fell and lies there


SCENE = """
[simulation]
integrator = "midpoint"
dt = 0.0005
duration = 0.05

[[colliders]]
type = "mesh"
{mesh}
restitution = 0.2

[[bodies]]
mesh = {{ shape = "icosphere", subdivisions = 2, radius = 0.3 }}
position = [0.0, 0.8, 0.0]
mass = 1.0
stiffness = 800.0
damping = 2.0
gas = {{ law = "isothermal", nrt = 200.0 }}
"""


def test_scene_colliders_of_type_mesh(tmp_path):
    """``[[colliders]] type = "mesh"`` takes a file relative to the scene file (the path
    reaches ColliderMesh: its triangles are the file's) or a generated shape table, with
    center, rotation and margin; a ball dropped on it stays outside."""
    from softbody.scenes.loader import load_scene

    (tmp_path / "meshes").mkdir()
    sb.save_mesh(sb.box((1.0, 0.4, 1.0)), tmp_path / "meshes" / "table.obj")
    (tmp_path / "a.toml").write_text(SCENE.format(mesh='file = "meshes/table.obj"'))
    (tmp_path / "b.toml").write_text(SCENE.format(
        mesh='mesh = { shape = "box", extents = [1.0, 0.4, 1.0] }\ncenter = [0.0, 0.1, 0.0]\n'
             "rotation = [0.0, 1.0, 0.0, 30.0]\nmargin = 0.001"))  # fmt: skip
    a, b = load_scene(tmp_path / "a.toml"), load_scene(tmp_path / "b.toml")
    assert a.model.collider_kind.tolist() == [sb.collision.ColliderKind.MESH] == \
        b.model.collider_kind.tolist()  # fmt: skip
    assert len(a.model.collider_mesh_triangles) == 12
    assert a.model.collider_center[0] == pytest.approx([0.0, 0.0, 0.0])
    assert b.model.collider_center[0] == pytest.approx([0.0, 0.1, 0.0])
    assert b.model.collider_mesh_margin[0] == 0.001
    assert b.model.collider_rotation[0] == pytest.approx(
        sb.collision.rotation_about((0, 1, 0), np.radians(30.0)))  # fmt: skip
    sim = sb.Simulator(a.model, integrator="midpoint", dt=5e-4)
    state = a.model.state()
    sim.run(state, 1000)
    assert state.particle_q[:, 1].min() >= 0.2


@pytest.mark.parametrize(
    ("mesh", "match"),
    [
        ('file = "missing.obj"', r"colliders\.0: .*missing\.obj: no such file"),
        ('file = "open.obj"', r"colliders\.0: .*open\.obj: a mesh collider must be one closed "
                              r"surface: open: 3 boundary edges"),
        ('mesh = { file = "open.obj" }', r"colliders\.0: .*open\.obj: a mesh collider"),
        ('mesh = { shape = "rectangle", size = [1.0, 1.0] }',
         r"colliders\.0: mesh: a mesh collider must be one closed surface: open"),
        ('file = "open.obj"\nmesh = { shape = "box" }', r"colliders\.0\.file: give exactly one"),
        ("", r"colliders\.0\.file: give exactly one"),
        ('file = "open.obj"\nmargin = -1.0', r"colliders\.0\.margin"),
        ('file = "open.obj"\nshape = "box"', r"unknown scene key colliders\.0\.shape"),
    ],
)  # fmt: skip
def test_bad_mesh_colliders_in_scenes_are_one_line_cli_errors(tmp_path, capsys, mesh, match):
    """A scene's bad mesh collider (missing file, open mesh, both or neither of file and
    mesh, a bad margin, an unknown key) is one line on stderr from ``softbody run`` naming
    the key and the file, exit 2, and nothing written."""
    from softbody.cli import main

    sb.save_mesh(_open_box(), tmp_path / "open.obj")
    scene = tmp_path / "bad.toml"
    scene.write_text(SCENE.format(mesh=mesh))
    out = tmp_path / "out"
    code = main(["run", str(scene), "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert err.startswith("softbody: error:") and "\n" not in err
    assert re.search(match, err), err
    assert not out.exists() or not any(out.iterdir())


def _mesh_scene_for_drawing():
    builder = sb.ModelBuilder()
    builder.add_soft_body(sb.icosphere(2, radius=0.3, center=(1.5, 0.5, 0.0)), mass=1.0,
                          stiffness=800.0, damping=2.0, gas=200.0)  # fmt: skip
    turn = sb.collision.rotation_about((0, 1, 0), 0.4)
    builder.add_collider(sb.ColliderMesh(sb.box((1.0, 0.6, 1.0)), center=(0.0, 0.3, 0.0),
                                         rotation=turn))  # fmt: skip
    return builder.finalize()


def test_renderer_draws_a_mesh_collider():
    """The frame shows the mesh collider's triangles at its pose: the pixel the box's
    centre projects to is grey (the collider colour, shaded), not the background, and the
    box's projected outline covers the pixels around it."""
    from softbody.render.frame import FrameRenderer, RenderSettings
    from softbody.render.raster import Camera

    model = _mesh_scene_for_drawing()
    camera = Camera(eye=(0.0, 1.5, 4.0), target=(0.0, 0.3, 0.0), fov=40.0)
    image = FrameRenderer(model, RenderSettings(width=160, height=120, camera=camera)).render(
        model.state())  # fmt: skip
    r, g, b = image[60, 80].astype(int)  # the image centre: the camera's target
    assert abs(r - g) < 12 and abs(g - b) < 12 and 40 < r < 200  # grey, shaded
    assert image[60, 80].tolist() != image[5, 80].tolist()  # not the sky above


def test_usd_export_writes_the_mesh_collider_triangles(tmp_path):
    """USD: a mesh collider is a Mesh prim of its triangles in its local frame, placed by
    the collider's translate and orient; its points put at the pose are the box's corners
    in the world."""
    pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom

    from softbody.io.usd import write_usd

    model = _mesh_scene_for_drawing()
    path = tmp_path / "scene.usda"
    write_usd(path, model, model.particle_q[None], 30.0, ["ball"])
    stage = Usd.Stage.Open(str(path))
    prim = stage.GetPrimAtPath("/softbody/colliders/mesh_0")
    mesh = UsdGeom.Mesh(prim)
    assert list(mesh.GetFaceVertexCountsAttr().Get()) == [3] * 12
    points = np.array(mesh.GetPointsAttr().Get())
    world = UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    placed = np.array([list(world.Transform(p)) for p in points.tolist()])
    rot = model.collider_rotation[0]
    expected = model.collider_center[0] + model.collider_mesh_vertices @ rot.T
    assert np.allclose(np.sort(placed, axis=0), np.sort(expected, axis=0), atol=1e-6)


def test_a_vertex_placed_deep_inside_is_pushed_out_through_the_nearest_face():
    """A particle that starts deep inside a box mesh (0.4 m from its nearest face, far more
    than its path of one step) is found inside (by the crossing parity of a ray, then the
    closest feature) and put on the nearest face plus the margin, as the analytic box puts
    it on its nearest face."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.add_particle((0.1, 0.05, 0.0), mass=1.0)
    builder.add_collider(sb.ColliderMesh(sb.box((1.0, 1.0, 1.0)), restitution=0.0,
                                         friction=0.0))  # fmt: skip
    model = builder.finalize()
    state = model.state()
    sb.Simulator(model, integrator="symplectic_euler", dt=1e-3).step(state)
    margin = model.collider_mesh_margin[0]
    assert state.particle_q[0] == pytest.approx([0.5 + margin, 0.05, 0.0], abs=1e-12)
