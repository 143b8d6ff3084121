"""Bad input gets a clear error that names the problem."""

from __future__ import annotations

import numpy as np
import pytest

import softbody as sb


def add(builder=None, **overrides):
    builder = builder or sb.ModelBuilder()
    kwargs = dict(mass=1.0, stiffness=100.0, damping=0.1, gas=100.0)
    kwargs.update(overrides)
    return builder.add_soft_body(kwargs.pop("mesh", sb.icosphere(1)), **kwargs)


@pytest.mark.parametrize(
    "overrides,match",
    [
        ({"mass": 0.0}, "mass must be > 0"),
        ({"mass": -2.0}, "mass must be > 0"),
        ({"mass": float("nan")}, "mass must be finite"),
        ({"stiffness": float("nan")}, "stiffness must be finite"),
        ({"stiffness": -1.0}, "stiffness must be >= 0"),
        ({"damping": -0.5}, "damping must be >= 0"),
        ({"damping": float("inf")}, "damping must be finite"),
        ({"gas": float("nan")}, "gas nRT must be finite"),
        ({"gas": -3.0}, "gas nRT must be >= 0"),
        ({"volume_method": "bounding_torus"}, "unknown volume method"),
        ({"pinned": [0, 500]}, r"pinned vertex indices must lie in \[0, 41\]"),
        ({"mass_distribution": "random"}, "mass_distribution must be"),
        ({"velocity": (0, np.nan, 0)}, "velocity must be 3 finite numbers"),
        ({"bend_stiffness": -1.0}, "bend_stiffness must be >= 0"),
    ],
)
def test_bad_body_parameters(overrides, match):
    """Each bad parameter raises ValueError naming it."""
    with pytest.raises(ValueError, match=match):
        add(**overrides)


def test_open_and_inverted_meshes_through_builder():
    """An open mesh is refused with its boundary-edge count; an inverted one is flipped
    with a warning and then encloses positive volume."""
    m = sb.icosphere(1)
    with pytest.raises(sb.MeshError, match="body 0 mesh cannot hold gas: open: 3 boundary"):
        add(mesh=sb.TriMesh(m.vertices, m.faces[1:]))
    builder = sb.ModelBuilder()
    with pytest.warns(sb.MeshWarning, match="flipped inward-facing"):
        add(builder, mesh=m.flipped())
    assert builder.finalize().body_rest_volume[0] == pytest.approx(m.volume)


def test_degenerate_mesh_through_builder():
    """Zero-area triangles are refused with their count."""
    m = sb.box()
    v = m.vertices.copy()
    v[m.faces[0, 2]] = 0.5 * (v[m.faces[0, 0]] + v[m.faces[0, 1]])
    with pytest.raises(sb.MeshError, match="degenerate"):
        add(mesh=sb.TriMesh(v, m.faces))


@pytest.mark.parametrize(
    "dt,match",
    [
        (0.0, "dt must be finite and > 0"),
        (-1e-3, "dt must be finite and > 0"),
        (float("nan"), "dt must be finite and > 0"),
        ("fast", "dt must be a number"),
    ],
)
def test_bad_dt(dt, match):
    """dt <= 0, NaN or not a number is refused."""
    builder = sb.ModelBuilder()
    add(builder)
    with pytest.raises(ValueError, match=match):
        sb.Simulator(builder.finalize(), dt=dt)


def test_unknown_integrator():
    """The error lists the valid integrators."""
    builder = sb.ModelBuilder()
    add(builder)
    with pytest.raises(ValueError, match="unknown integrator 'leapfrog2'.*rk4"):
        sb.Simulator(builder.finalize(), integrator="leapfrog2", dt=1e-3)


def test_bad_particles_springs_attachments():
    """Free particles, springs and attachments validate their inputs."""
    b = sb.ModelBuilder()
    with pytest.raises(ValueError, match="mass must be > 0"):
        b.add_particle((0, 0, 0), mass=0.0)
    i = b.add_particle((0, 0, 0), mass=1.0)
    with pytest.raises(ValueError, match="two different particles"):
        b.add_spring(i, i, stiffness=1.0)
    with pytest.raises(ValueError, match=r"spring particle must lie in \[0, 0\]"):
        b.add_spring(i, 7, stiffness=1.0)
    with pytest.raises(ValueError, match="anchor must be 3 finite numbers"):
        b.add_attachment(i, (0, 0), stiffness=1.0)
    with pytest.raises(ValueError, match="stiffness must be > 0"):
        b.add_attachment(i, (0, 1, 0), stiffness=0.0)
    with pytest.raises(ValueError, match="gravity must be 3 finite numbers"):
        sb.ModelBuilder(gravity=(0, np.inf, 0))
    with pytest.raises(ValueError, match="the model is empty"):
        sb.ModelBuilder().finalize()


def test_bad_control():
    """Control arrays of the wrong shape or with NaN forces are refused before stepping."""
    builder = sb.ModelBuilder()
    add(builder)
    model = builder.finalize()
    sim = sb.Simulator(model, dt=1e-4)
    control = model.control()
    control.particle_f = np.zeros((3, 3))
    with pytest.raises(ValueError, match=r"Control.particle_f must have shape \(42, 3\)"):
        sim.step(model.state(), control)
    control = model.control()
    control.particle_f[4, 0] = np.nan
    with pytest.raises(ValueError, match="particle_f holds NaN"):
        sim.step(model.state(), control)


def test_model_is_immutable():
    """Model arrays are read-only: a step can never change the model."""
    builder = sb.ModelBuilder()
    add(builder)
    model = builder.finalize()
    with pytest.raises(ValueError, match="read-only"):
        model.spring_stiffness[0] = 5.0
