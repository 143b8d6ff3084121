"""USD a DCC artist can use (issue 29, item 11): colliders as placed shapes, per-frame
extents, normals and velocities, a map back to the input mesh's vertices, and a chosen
first frame.

Every file is read back with the USD library (usd-core) and compared with the states the
simulation went through: the colliders' world transforms (composed by USD from the
written xformOps) against the states' ``collider_q`` and ``collider_rotation``, the
velocities against ``particle_qd``, the mapped points against the input mesh's vertices.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import softbody as sb
from softbody.collision.colliders import rotation_about

pxr = pytest.importorskip("pxr")
from pxr import Gf, Usd, UsdGeom  # noqa: E402

FPS = 30
FRAMES = 10
START = 1001
GROUND = 5.0


def soup(mesh: sb.TriMesh, inward: bool = False) -> sb.TriMesh:
    """``mesh`` as a triangle soup: three vertices of its own for every triangle (an STL
    file's layout), wound inward when asked; welding merges the copies back."""
    faces = mesh.faces[:, ::-1] if inward else mesh.faces
    return sb.TriMesh(mesh.vertices[faces].reshape(-1, 3), np.arange(3 * len(faces)).reshape(-1, 3))


def build(source: sb.TriMesh) -> sb.Model:
    """A ball from ``source`` over a ground plane, inside a container, with a sphere
    sliding in from +x, and a tilted box spinning about the vertical on the -x side."""
    builder = sb.ModelBuilder()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.MeshWarning)  # welded, flipped
        builder.add_soft_body(source, mass=1.0, stiffness=400.0, damping=0.5, gas=300.0)
    builder.add_collider(sb.ColliderPlane(point=(0.0, 0.0, 0.0)))
    builder.add_collider(
        sb.ColliderSphere(
            center=(2.0, 0.3, 0.0), radius=0.3, motion=sb.MotionTranslation(velocity=(-1, 0, 0))
        )
    )
    builder.add_collider(
        sb.ColliderBox(
            center=(-2.0, 0.5, 0.0),
            half_extents=(0.2, 0.3, 0.4),
            rotation=rotation_about((0.0, 0.0, 1.0), 0.3),
            motion=sb.MotionRotation(angular_velocity=(0.0, 2.0, 0.0)),
        )
    )
    builder.add_collider(
        sb.ColliderBox(center=(0.0, 1.0, 0.0), half_extents=(4.0, 4.0, 4.0), container=True)
    )
    return builder.finalize()


@pytest.fixture(scope="module")
def source() -> sb.TriMesh:
    """The input mesh: an icosphere as an inward-wound soup (240 vertices for 42 points)."""
    return soup(sb.icosphere(1, radius=0.3, center=(0.0, 0.5, 0.0)), inward=True)


@pytest.fixture(scope="module")
def saved(source, tmp_path_factory):
    """FRAMES frames captured at 1/FPS s apart, each state kept, saved from START."""
    model = build(source)
    sim = sb.Simulator(model, integrator="velocity_verlet", dt=1.0 / 1200)
    rec = sb.Recorder(model, fps=FPS, body_names=["ball"], ground_size=GROUND)
    state, states = model.state(), []
    for k in range(FRAMES):
        if k:
            sim.advance(state, 1.0 / FPS)
        rec.capture(state)
        states.append(state.copy())
    path = rec.save(tmp_path_factory.mktemp("usd") / "ball.usdc", start_frame=START)
    rec.close()
    return model, states, Usd.Stage.Open(str(path))


def codes() -> list[float]:
    return [float(START + k) for k in range(FRAMES)]


def test_start_frame_is_the_first_time_code(saved):
    """The stage starts at the start_frame asked for (startTimeCode == 1001, end ==
    1001 + F - 1), at FPS time codes per second, and every time-sampled attribute has its
    first sample there, one per frame."""
    _, _, stage = saved
    assert stage.GetStartTimeCode() == START
    assert stage.GetEndTimeCode() == START + FRAMES - 1
    assert stage.GetTimeCodesPerSecond() == FPS
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/softbody/ball"))
    for attr in (mesh.GetPointsAttr(), mesh.GetNormalsAttr(), mesh.GetVelocitiesAttr(),
                 mesh.GetExtentAttr()):  # fmt: skip
        assert attr.GetTimeSamples() == codes()
    sphere = stage.GetPrimAtPath("/softbody/colliders/sphere_1")
    assert sphere.GetAttribute("xformOp:translate").GetTimeSamples() == codes()


def test_moving_colliders_follow_the_states(saved):
    """A moving collider's transform at time code START + k is the state's pose at frame k:
    the translate op equals ``collider_q``, and the world transform USD composes (translate,
    orient, scale) maps the shape's local corners where ``collider_q + R (size * corner)``
    puts them, for the sliding sphere and the spinning, tilted box."""
    model, states, stage = saved
    sphere = UsdGeom.Sphere(stage.GetPrimAtPath("/softbody/colliders/sphere_1"))
    box = UsdGeom.Cube(stage.GetPrimAtPath("/softbody/colliders/box_2"))
    assert sphere and box
    assert sphere.GetRadiusAttr().Get() == pytest.approx(0.3)
    assert box.GetSizeAttr().Get() == 2.0
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    for k, (state, code) in enumerate(zip(states, codes(), strict=True)):
        translate = np.array(sphere.GetPrim().GetAttribute("xformOp:translate").Get(code))
        np.testing.assert_array_equal(translate, state.collider_q[1])
        m = sphere.ComputeLocalToWorldTransform(code)
        np.testing.assert_allclose(m.Transform(Gf.Vec3d(0, 0, 0)), state.collider_q[1], atol=1e-12)
        m = box.ComputeLocalToWorldTransform(code)
        world = np.array([m.Transform(Gf.Vec3d(*c)) for c in corners])
        want = (
            state.collider_q[2] + (corners * model.collider_size[2]) @ state.collider_rotation[2].T
        )
        np.testing.assert_allclose(world, want, atol=1e-9)
        if k:  # they did move
            assert not np.allclose(state.collider_rotation[2], states[0].collider_rotation[2])
            assert state.collider_q[1][0] < states[0].collider_q[1][0]


def test_still_colliders_ground_and_container(saved):
    """The ground is a square of side ground_size lying in the plane (its world normal is
    the plane's, its points on it); the container is a cube of its half-extents, see-through;
    still colliders hold one transform, not one per frame."""
    model, _, stage = saved
    ground = UsdGeom.Mesh(stage.GetPrimAtPath("/softbody/colliders/ground_0"))
    points = np.array(ground.GetPointsAttr().Get(), dtype=np.float64)
    assert np.ptp(points, axis=0) == pytest.approx([GROUND, 0.0, GROUND])
    m = ground.ComputeLocalToWorldTransform(START)
    normal = np.array(m.TransformDir(Gf.Vec3d(0, 1, 0)))
    np.testing.assert_allclose(normal, model.collider_rotation[0][:, 1], atol=1e-12)
    a, b, c = (np.array(m.Transform(Gf.Vec3d(*p))) for p in points[:3])
    assert np.cross(b - a, c - a) @ normal > 0  # the quad faces the allowed side
    assert ground.GetPrim().GetAttribute("xformOp:translate").GetTimeSamples() == []
    box = UsdGeom.Cube(stage.GetPrimAtPath("/softbody/colliders/container_3"))
    m = box.ComputeLocalToWorldTransform(START + 5)
    np.testing.assert_allclose(m.Transform(Gf.Vec3d(1, 1, 1)), [4.0, 5.0, 4.0], atol=1e-12)
    assert box.GetDisplayOpacityAttr().Get()[0] < 1


def test_extents_normals_velocities_per_frame(saved):
    """At every time code: the extent holds every point (and is their bounding box to
    float32 rounding); normals are unit and point outward (positive dot with the point
    minus the ball's centroid, a convex ball); velocities equal the state's particle_qd
    (float32); points equal the state's particle_q."""
    _, states, stage = saved
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/softbody/ball"))
    assert mesh.GetNormalsInterpolation() == UsdGeom.Tokens.vertex
    for state, code in zip(states, codes(), strict=True):
        points = np.array(mesh.GetPointsAttr().Get(code), dtype=np.float64)
        np.testing.assert_allclose(points, state.particle_q, rtol=0, atol=1e-6)
        lo, hi = np.array(mesh.GetExtentAttr().Get(code), dtype=np.float64)
        assert np.all(points >= lo) and np.all(points <= hi)
        np.testing.assert_allclose([lo, hi], [points.min(0), points.max(0)], atol=1e-6)
        normals = np.array(mesh.GetNormalsAttr().Get(code), dtype=np.float64)
        np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6)
        assert np.all(np.einsum("ij,ij->i", normals, points - points.mean(axis=0)) > 0)
        velocities = np.array(mesh.GetVelocitiesAttr().Get(code), dtype=np.float64)
        np.testing.assert_allclose(velocities, state.particle_qd, rtol=1e-6, atol=1e-6)
    assert np.abs(states[-1].particle_qd).max() > 0.1  # the ball fell: velocities not zero


def test_index_map_gives_back_the_input_mesh(saved, source):
    """The input was a 240-vertex soup welded to 42 points (and flipped outward).
    ``primvars:softbody:sourceVertex`` maps each point to an input vertex with its position
    at frame 0; ``primvars:softbody:sourceCornerVertex`` (faceVarying) maps each triangle
    corner to the input vertex at that corner: the input's own triangles, reversed, and
    per-input-vertex UVs placed through it land on the corners they were made for."""
    _, _, stage = saved
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/softbody/ball"))
    api = UsdGeom.PrimvarsAPI(mesh)
    per_point = api.GetPrimvar("softbody:sourceVertex")
    per_corner = api.GetPrimvar("softbody:sourceCornerVertex")
    assert per_point.GetInterpolation() == UsdGeom.Tokens.vertex
    assert per_corner.GetInterpolation() == UsdGeom.Tokens.faceVarying
    point_map = np.array(per_point.Get())
    corner_map = np.array(per_corner.Get())
    points = np.array(mesh.GetPointsAttr().Get(START), dtype=np.float64)
    faces = np.array(mesh.GetFaceVertexIndicesAttr().Get())
    assert source.vertex_count == 240 and len(points) == 42
    np.testing.assert_allclose(points, source.vertices[point_map], atol=1e-7)
    np.testing.assert_allclose(points[faces], source.vertices[corner_map], atol=1e-7)
    np.testing.assert_array_equal(corner_map.reshape(-1, 3), source.faces[:, ::-1])
    uv = np.random.default_rng(0).random((source.vertex_count, 2))  # one UV per input vertex
    face_uv = uv[corner_map].reshape(-1, 3, 2)
    np.testing.assert_array_equal(face_uv, uv[source.faces[:, ::-1]])


def test_model_keeps_the_weld_map():
    """Model.particle_source_vertex and tri_source_vertex: identity for a mesh welding
    leaves alone, the first copy of each welded group for a soup, -1 for a particle added
    by itself; the first welded vertex keeps its input position exactly."""
    ico = sb.icosphere(1)
    builder = sb.ModelBuilder()
    builder.add_soft_body(ico, mass=1.0, stiffness=100.0, damping=0.1, gas=100.0)
    with pytest.warns(sb.MeshWarning, match="welded 198 duplicate vertices"):
        builder.add_soft_body(
            soup(sb.icosphere(1, center=(3, 0, 0))), mass=1.0, stiffness=100.0, damping=0.1,
            gas=100.0,
        )  # fmt: skip
    builder.add_particle((0.0, 5.0, 0.0), mass=1.0)
    model = builder.finalize()
    n = ico.vertex_count
    np.testing.assert_array_equal(model.particle_source_vertex[:n], np.arange(n))
    np.testing.assert_array_equal(model.tri_source_vertex[: ico.face_count], ico.faces)
    second = model.particle_source_vertex[n : 2 * n]
    welded = soup(sb.icosphere(1, center=(3, 0, 0)))
    np.testing.assert_array_equal(model.particle_q[n : 2 * n], welded.vertices[second])
    assert model.particle_source_vertex[-1] == -1
    assert model.particle_source_vertex.shape == (model.particle_count,)
    assert model.tri_source_vertex.shape == (model.tri_count, 3)


def test_vertex_normals_of_an_icosahedron():
    """Each vertex of a regular icosahedron meets five equal triangles, so its area-weighted
    normal is its own direction from the centre, by symmetry: unit and radial."""
    from softbody.io.usd import vertex_normals

    ico = sb.icosphere(0, radius=2.0, center=(1.0, -1.0, 0.5))
    n = vertex_normals(ico.vertices, ico.faces)
    radial = ico.vertices - np.array([1.0, -1.0, 0.5])
    np.testing.assert_allclose(
        n, radial / np.linalg.norm(radial, axis=1, keepdims=True), atol=1e-12
    )


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), True, "1001", 1e300])
def test_bad_start_frame_is_refused_and_writes_nothing(bad, tmp_path):
    """A start_frame that is not a finite number is a ValueError naming it, before any
    file is written."""
    model = build(sb.icosphere(1, radius=0.3, center=(0.0, 0.5, 0.0)))
    with sb.Recorder(model, fps=FPS) as rec:
        rec.capture(model.state())
        with pytest.raises(ValueError, match="start_frame"):
            rec.save(tmp_path / "x.usda", start_frame=bad)
    assert list(tmp_path.iterdir()) == []


def test_scene_run_writes_colliders_and_start_frame(tmp_path):
    """``softbody run --usd-start-frame 1001`` (the scene key ``render.usd_start_frame``;
    the flag implies ``--usd``) starts the cache at 1001 and writes the scene's colliders,
    the oscillating ball at its centre per frame (the summary's final collider centre at
    the last code)."""
    import json

    from softbody.cli import main

    out = tmp_path / "out"
    code = main(
        ["run", "hand-punch", "--out", str(out), "--duration", "0.1", "--no-video",
         "--no-gif", "--usd-start-frame", "1001"]
    )  # fmt: skip
    assert code == 0
    stage = Usd.Stage.Open(str(next(out.rglob("hand-punch.usdc"))))
    summary = json.loads(next(out.rglob("hand-punch-summary.json")).read_text())
    assert stage.GetStartTimeCode() == 1001
    last = 1001 + summary["frames"] - 1
    assert stage.GetEndTimeCode() == last
    ball = UsdGeom.Sphere(stage.GetPrimAtPath("/softbody/colliders/sphere_1"))
    assert ball and stage.GetPrimAtPath("/softbody/colliders/ground_0").IsA(UsdGeom.Mesh)
    translate = ball.GetPrim().GetAttribute("xformOp:translate")
    assert translate.GetTimeSamples()[0] == 1001 and translate.GetTimeSamples()[-1] == last
    np.testing.assert_allclose(translate.Get(last), summary["colliders"][1]["center_m"])
    hand = UsdGeom.Mesh(stage.GetPrimAtPath("/softbody/hand"))
    assert hand.GetVelocitiesAttr().GetTimeSamples()[0] == 1001


@pytest.mark.parametrize(
    "args, reason",
    [
        (["--usd-start-frame", "nan"], "must be finite"),
        (["--usd", "--set", "render.usd_start_frame=1e300"], "must be <= 1e+15"),
    ],
)
def test_scene_run_refuses_a_bad_start_frame(args, reason, tmp_path, capsys):
    """A start frame that is not finite, or past 1e15, is a one-line error naming the key
    and a non-zero exit before anything runs; no file is written."""
    from softbody.cli import main

    out = tmp_path / "out"
    code = main(["run", "hand-punch", "--out", str(out), "--duration", "0.1", "--no-video",
                 "--no-gif", *args])  # fmt: skip
    err = capsys.readouterr().err
    assert code != 0
    assert f"render.usd_start_frame: {reason}" in err and len(err.strip().splitlines()) == 1
    assert not out.exists() or not any(out.rglob("*"))


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan")])
def test_recorder_refuses_a_bad_ground_size(bad):
    """The ground square's side must be finite and > 0: a ValueError naming ground_size."""
    model = build(sb.icosphere(1, radius=0.3, center=(0.0, 0.5, 0.0)))
    with pytest.raises(ValueError, match="ground_size"):
        sb.Recorder(model, ground_size=bad)


def test_a_body_named_colliders_keeps_the_colliders_scope(tmp_path):
    """A body called "colliders" is written as /softbody/colliders_1, so the colliders'
    scope /softbody/colliders stays the colliders' (prim names are unique)."""
    model = build(sb.icosphere(1, radius=0.3, center=(0.0, 0.5, 0.0)))
    with sb.Recorder(model, fps=FPS, body_names=["colliders"]) as rec:
        rec.capture(model.state())
        stage = Usd.Stage.Open(str(rec.save(tmp_path / "x.usda")))
    assert stage.GetPrimAtPath("/softbody/colliders_1").IsA(UsdGeom.Mesh)
    assert stage.GetPrimAtPath("/softbody/colliders").GetTypeName() == "Scope"
    assert stage.GetPrimAtPath("/softbody/colliders/ground_0").IsA(UsdGeom.Mesh)
