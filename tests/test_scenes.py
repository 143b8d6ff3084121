"""Scene files: every built-in loads and runs; keys are checked; overrides apply."""

from __future__ import annotations

import numpy as np
import pytest

import softbody as sb
from conftest import BUILT_IN
from softbody.scenes import SceneError, list_scenes, load_scene


def test_all_paper_scenes_are_built_in():
    """The five scenes of the paper's figures, balloon-drop (face drag), the scenes of
    gas that flows (landing-cushion, airbag, punctured-ball, two-balloons) and of
    membranes (balloon-tank, bending-actuator) and of contact (vacuum-gripper, balloon-ring,
    cloth-stair) ship with the package."""
    assert sorted(list_scenes()) == sorted(BUILT_IN)


@pytest.mark.parametrize("name", BUILT_IN)
def test_built_in_scene_runs_stably(name):
    """Each built-in scene builds, its dt is within the stability estimate of its
    integrator, and 200 steps run without blowing up."""
    scene = load_scene(name)
    sim = sb.Simulator(scene.model, integrator=scene.integrator, dt=scene.dt)
    assert scene.dt <= sim.stable_dt
    state = scene.model.state()
    sim.run(state, 200)
    assert np.all(np.isfinite(state.particle_q))


def test_bouncing_balls_matches_the_paper():
    """Five balls of 162 vertices and 320 faces in a container rotating about a
    horizontal axis."""
    model = load_scene("bouncing-balls").model
    assert model.body_count == 5
    assert np.all(np.diff(model.body_particle_range, axis=1) == 162)
    assert np.all(np.diff(model.body_tri_range, axis=1) == 320)
    assert model.collider_kind.tolist() == [sb.collision.ColliderKind.BOX_CONTAINER]
    axis = model.collider_motion_vector[0]
    assert axis[1] == 0.0 and np.linalg.norm(axis) > 0  # horizontal axis


def test_hand_is_closed_manifold_and_paper_sized():
    """The generated hand: 370-390 vertices, 740-780 faces, closed, genus 0, no slivers."""
    scene = load_scene("hand-punch")
    model = scene.model
    (p0, p1), (t0, t1) = model.body_particle_range[0], model.body_tri_range[0]
    assert 370 <= p1 - p0 <= 390 and 740 <= t1 - t0 <= 780
    mesh = sb.TriMesh(model.particle_q[p0:p1], model.tri_indices[t0:t1] - p0)
    report = sb.inspect_mesh(mesh)
    assert report.problems == [] and report.repairs == []
    assert mesh.vertex_count - len(mesh.edges) + mesh.face_count == 2
    x = mesh.vertices[mesh.faces]
    for k in range(3):
        u = x[:, (k + 1) % 3] - x[:, k]
        w = x[:, (k + 2) % 3] - x[:, k]
        cos = np.sum(u * w, 1) / np.linalg.norm(u, axis=1) / np.linalg.norm(w, axis=1)
        assert np.degrees(np.arccos(cos)).min() > 20


def test_overrides_change_the_model():
    """--set style overrides reach the model: gas amount, dt, contact mode, CG tolerance."""
    scene = load_scene(
        "bouncing-balls",
        [
            "bodies.2.gas.nrt=77",
            "simulation.dt=0.0002",
            'contact.mode="surface"',
            "simulation.implicit_tolerance=0.01",
        ],
    )
    assert scene.model.body_gas_value[2] == 77.0
    assert scene.dt == 0.0002
    assert scene.model.soft_contact_mode == 2
    assert scene.implicit_tolerance == 0.01
    assert load_scene("bouncing-balls").implicit_tolerance == 1e-6  # the Simulator's default


@pytest.mark.parametrize(
    "override,match",
    [
        ("simulation.dtt=0.1", r"unknown scene key simulation\.dtt \(valid: dt, duration"),
        ("bodies.0.gass.nrt=1", r"unknown scene key bodies\.0\.gass"),
        ("bodies.9.mass=1", "bodies.9 is not an index of the 5 entries"),
        ('colliders.0.type="cone"', r"colliders\.0\.type: unknown value 'cone' \(valid: plane"),
        ("bodies.0.mass=-1", r"bodies\.0\.mass: must be > 0, got -1"),
        ('bodies.0.gas.law="vdw"', r"bodies\.0\.gas\.law: unknown value 'vdw'"),
        ("simulation", "must look like key=value"),
        ("simulation.implicit_tolerance=1", r"implicit_tolerance: must be < 1, got 1"),
        ('simulation.implicit_tolerance="nan"', r"implicit_tolerance: must be a number"),
    ],
)
def test_bad_overrides_name_the_key(override, match):
    """A misspelt or invalid key is an error naming it (and the valid keys)."""
    with pytest.raises(SceneError, match=match):
        load_scene("bouncing-balls", [override])


def test_unknown_scene_lists_the_built_ins():
    """A scene name that is neither built in nor a file is a SceneError that lists the
    built-in scenes."""
    listed = "unknown scene 'bouncy'; built-in scenes: airbag, balloon-drop, balloon-ring, balloon"
    with pytest.raises(SceneError, match=listed):
        load_scene("bouncy")


def test_scene_file_with_relative_mesh(tmp_path):
    """A scene file may load a mesh file next to it; an open mesh is refused by name."""
    sb.save_mesh(sb.icosphere(2, radius=0.3), tmp_path / "ball.obj")
    m = sb.icosphere(1)
    sb.save_mesh(sb.TriMesh(m.vertices, m.faces[1:]), tmp_path / "open.obj")
    text = """
[simulation]
dt = 0.001
duration = 0.1
[[bodies]]
mesh = { file = "ball.obj" }
mass = 1.0
stiffness = 100.0
gas = 10.0
"""
    (tmp_path / "s.toml").write_text(text)
    assert load_scene(tmp_path / "s.toml").model.particle_count == 162
    (tmp_path / "bad.toml").write_text(text.replace("ball.obj", "open.obj"))
    with pytest.raises(SceneError, match=r"open\.obj cannot hold gas: open: 3 boundary edges"):
        load_scene(tmp_path / "bad.toml")


def test_cloth_wind_force_depends_only_on_the_frame():
    """Uniform pressure on a surface with a fixed boundary: the total force is P times the
    vector area, which depends only on the boundary curve (Stokes), so for a 1.2 m square
    frame it is P x 1.44 m^2 along the frame's normal however the cloth bulges."""
    from conftest import forces

    scene = load_scene(
        "cloth-wind",
        ["bodies.0.stiffness=0", "bodies.0.bend_stiffness=0", "simulation.gravity=[0, 0, 0]"],
    )
    model = scene.model
    state = model.state()
    state.time = 2.0  # the schedule holds 30 Pa from 1 s to 2.5 s
    free = model.particle_inv_mass > 0
    rng = np.random.default_rng(4)
    state.particle_q[free] += rng.uniform(-0.1, 0.1, (free.sum(), 3))
    total = forces(model, state).sum(axis=0)
    assert np.allclose(total, [0.0, 0.0, 30.0 * 1.44], atol=1e-12)
