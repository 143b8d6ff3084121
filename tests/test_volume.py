"""Volume methods against closed forms: exact, bounding box/sphere/ellipsoid, Monte Carlo."""

from __future__ import annotations

import numpy as np
import pytest

import softbody as sb


def volume_of(mesh: sb.TriMesh, method: str, **kwargs) -> float:
    builder = sb.ModelBuilder()
    builder.add_soft_body(
        mesh, mass=1.0, stiffness=1.0, damping=0.0, gas=1.0, volume_method=method, **kwargs
    )
    model = builder.finalize()
    return float(sb.body_volume(model, model.state())[0])


BOX = sb.box((2.0, 3.0, 0.5), center=(10.0, -4.0, 2.0), subdivisions=1)
HX, HY, HZ = 1.0, 1.5, 0.25


def test_exact_volume_of_box_and_model_agree():
    """Divergence theorem on a 2 x 3 x 0.5 box: V = 3 (to round-off)."""
    assert volume_of(BOX, "exact") == pytest.approx(3.0, rel=1e-13)


def test_volume_alone_equals_the_gradient_pass():
    """The volume-only pass (checks, diagnostics) and the pass that also gives dV/dx (the
    pressure force) sum the same divergence-theorem terms, written differently ((a - r) .
    (b - r) x (c - r) against (a - r) . (b - a) x (c - a)): equal to round-off on two
    randomly deformed bodies (seeded)."""
    from softbody import _core
    from softbody.core import core_model
    from softbody.sim.control import control_data

    builder = sb.ModelBuilder()
    builder.add_soft_body(BOX, mass=1.0, stiffness=1.0, damping=0.0, gas=1.0)
    builder.add_soft_body(
        sb.icosphere(2, center=(3.0, 0.0, 0.0)), mass=1.0, stiffness=1.0, damping=0.0, gas=1.0
    )
    model = builder.finalize()
    q = model.particle_q + np.random.default_rng(5).normal(0.0, 0.05, model.particle_q.shape)
    exact = np.zeros(2, dtype=np.int64)
    alone = _core.body_volumes(q, model.tri_indices, model.body_particle_range,
                               model.body_tri_range, exact, model.body_mc_range,
                               model.mc_samples)  # fmt: skip
    with_gradient = _core.eval_volumes(core_model(model), control_data(model), 0.0, q)[0]
    assert alone == pytest.approx(with_gradient, rel=1e-12)
    assert alone[1] == pytest.approx(4.0 / 3.0 * np.pi, rel=0.05)  # an icosphere of radius 1


def test_bounding_box_of_box_is_the_box():
    """The bounding box of a box is the box: V = 8 hx hy hz."""
    assert volume_of(BOX, "bounding_box") == pytest.approx(8 * HX * HY * HZ, rel=1e-13)


def test_bounding_sphere_of_box():
    """Sphere about the box centre through the corners: r = half diagonal."""
    r = np.sqrt(HX**2 + HY**2 + HZ**2)
    assert volume_of(BOX, "bounding_sphere") == pytest.approx(4 / 3 * np.pi * r**3, rel=1e-13)


def test_bounding_ellipsoid_of_box():
    """Ellipsoid with the box's aspect ratio through the corners: semi-axes sqrt(3) h."""
    expected = 4 / 3 * np.pi * 3 * np.sqrt(3) * HX * HY * HZ
    assert volume_of(BOX, "bounding_ellipsoid") == pytest.approx(expected, rel=1e-13)


def test_bounding_objects_of_ellipsoid_mesh():
    """A UV sphere scaled to semi-axes (a, b, c) has vertices at all six axis extremes
    (even rings, segments divisible by 4), so: box 8abc, ellipsoid 4/3 pi abc (equation 6 of
    the paper), sphere 4/3 pi max(a, b, c)^3."""
    a, b, c = 1.5, 0.8, 0.6
    mesh = sb.uv_sphere(rings=16, segments=32).scaled((a, b, c)).translated((0.3, 5.0, -1.0))
    assert volume_of(mesh, "bounding_box") == pytest.approx(8 * a * b * c, rel=1e-13)
    assert volume_of(mesh, "bounding_ellipsoid") == pytest.approx(
        4 / 3 * np.pi * a * b * c, rel=1e-13
    )
    assert volume_of(mesh, "bounding_sphere") == pytest.approx(4 / 3 * np.pi * a**3, rel=1e-13)


def test_bounding_sphere_of_icosphere_is_the_sphere():
    """Every icosphere vertex lies on the sphere and the mesh is centrally symmetric."""
    mesh = sb.icosphere(2, radius=0.7, center=(1, 2, 3))
    assert volume_of(mesh, "bounding_sphere") == pytest.approx(4 / 3 * np.pi * 0.7**3, rel=1e-13)


def test_monte_carlo_is_exact_for_a_box():
    """Every vertical line through an axis-aligned box is inside for exactly its height,
    so the line-sampling estimator has zero variance there: V = 3 to round-off."""
    assert volume_of(BOX, "monte_carlo", monte_carlo_samples=64) == pytest.approx(3.0, rel=1e-12)


def test_monte_carlo_is_seeded_and_unbiased():
    """Same seed, same volume; across 40 seeds the mean is within 4 standard errors of
    the exact polyhedron volume (unbiased estimator), and the spread shrinks like
    1/sqrt(samples) (ratio 2 for 4x the samples, within the sampling error of the spread)."""
    mesh = sb.icosphere(3, radius=1.0)
    exact = mesh.volume
    assert volume_of(mesh, "monte_carlo", seed=7) == volume_of(mesh, "monte_carlo", seed=7)
    small = np.array(
        [volume_of(mesh, "monte_carlo", monte_carlo_samples=256, seed=s) for s in range(40)]
    )
    large = np.array(
        [volume_of(mesh, "monte_carlo", monte_carlo_samples=1024, seed=s) for s in range(40)]
    )
    for est in (small, large):
        assert abs(est.mean() - exact) <= 4 * est.std(ddof=1) / np.sqrt(len(est))
    ratio = small.std(ddof=1) / large.std(ddof=1)
    # the sample std of 40 draws has relative error ~ 1/sqrt(2*39) = 11%; allow 3 of those
    assert 2 * (1 - 0.34) <= ratio <= 2 * (1 + 0.34)


def test_monte_carlo_of_spot_cow_non_convex():
    """A non-convex mesh (legs, ears): lines crossing it several times still sum right:
    within 4 standard errors of the exact volume with 20,000 lines."""
    import warnings
    from pathlib import Path

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.MeshWarning)
        spot = sb.load_mesh(Path(__file__).parent / "data" / "spot_triangulated.obj")
    estimates = [
        volume_of(spot, "monte_carlo", monte_carlo_samples=20000, seed=s) for s in range(6)
    ]
    err = np.std(estimates, ddof=1) / np.sqrt(len(estimates))
    assert abs(np.mean(estimates) - spot.volume) <= 4 * err + 1e-12
    assert abs(np.mean(estimates) - spot.volume) / spot.volume < 0.01


def test_volume_method_names():
    """Unknown volume methods are refused with the list of valid ones."""
    with pytest.raises(ValueError, match="unknown volume method 'bounding_cone'.*exact"):
        volume_of(BOX, "bounding_cone")
