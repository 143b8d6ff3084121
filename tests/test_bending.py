"""Material bending: the discrete-shell energy on a surface's hinges
(``core/terms/bending.hpp``, ``softbody.reference.bending``, ``sb.Bending``).

References, test by test: the NumPy reference (core against it to round-off); calculus
(the force is minus the gradient of the energy, by central differences, whose O(h^2)
error is estimated from two step sizes as in test_terms.py); the Gauss-Newton product's
definition 2 k g g^T p computed here by hand; the plate's closed forms (a cylinder's
energy D / (2 R^2) per area, a sphere's, a cantilever's tip deflection); energy
conservation of velocity Verlet; the stability estimate.
"""

from __future__ import annotations

import numpy as np
import pytest

import softbody as sb
from softbody import _core, core
from softbody.core import core_model
from softbody.reference import bending as rb
from softbody.reference import jacobians
from softbody.sim.control import control_data

EPS = np.finfo(float).eps


# -- models ------------------------------------------------------------------------------
def _surface(mesh: sb.TriMesh, bending: sb.Bending, *, pinned=None) -> sb.Model:
    """``mesh`` as an open surface with material bending and nothing else that pushes: no
    gravity, no pressure, edge springs of stiffness 0 (so at rest velocities the core's
    whole force is the bending force)."""
    b = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    b.add_cloth(mesh, mass=1.0, stiffness=0.0, damping=0.0, bending=bending, pinned=pinned,
                mass_distribution="area")  # fmt: skip
    return b.finalize()


def _sphere_case(rest_shape: str) -> tuple[sb.Model, np.ndarray]:
    """An icosphere (radius 0.3 m, 162 vertices, D = 0.02 N m) and a state with every
    vertex moved by up to 5 mm (seed 5)."""
    model = _surface(sb.icosphere(2, radius=0.3), sb.Bending(0.02, rest_shape=rest_shape))
    rng = np.random.default_rng(5)
    return model, model.particle_q + rng.uniform(-0.005, 0.005, model.particle_q.shape)


def _grid_case(amplitude: float) -> tuple[sb.Model, np.ndarray]:
    """A flat 1 x 0.8 m grid of 10 x 8 squares (D = 0.01 N m, rest flat) and a state with
    every vertex moved in the plane by up to 1 cm and out of it by up to ``amplitude``
    [m] (seed 7): 1e-9 m leaves every hinge within about 1e-8 rad of flat."""
    model = _surface(sb.rectangle((1.0, 0.8), (10, 8)), sb.Bending(0.01))
    rng = np.random.default_rng(7)
    q = model.particle_q.copy()
    q[:, :2] += rng.uniform(-0.01, 0.01, (len(q), 2))
    q[:, 2] += rng.uniform(-amplitude, amplitude, len(q))
    return model, q


CASES = {
    "sphere-rest-mesh": lambda: _sphere_case("mesh"),
    "sphere-rest-flat": lambda: _sphere_case("flat"),
    "grid": lambda: _grid_case(0.02),
    "grid-near-flat": lambda: _grid_case(1e-9),
}


@pytest.fixture(params=core.simd_paths())
def simd(request):
    """Each instruction set this CPU runs, restored afterwards."""
    before = core.simd_path()
    core.use_simd(request.param)
    yield request.param
    core.use_simd(before)


def _core_force(model: sb.Model, q: np.ndarray) -> np.ndarray:
    zero = np.zeros_like(q)
    return _core.eval_forces(core_model(model), control_data(model), 0.0, q, zero)[0]


def _core_energy(model: sb.Model, q: np.ndarray) -> tuple[float, np.ndarray]:
    out = _core.eval_energies(core_model(model), control_data(model), 0.0,
                              np.ascontiguousarray(q))  # fmt: skip
    return out["bending"]


def _force_scale(model: sb.Model, q: np.ndarray) -> np.ndarray:
    """Per particle the magnitudes its bending force sums, 2 k (|theta - theta0| + |theta|
    + 1) |g_a| (N,): theta carries round-off of about eps (|theta| + 1)."""
    theta, g, _ = rb.angles_and_gradients(model, q)
    s = 2.0 * model.bending_stiffness * (np.abs(rb.excess(model, theta)) + np.abs(theta) + 1.0)
    out = np.zeros(model.particle_count)
    np.add.at(out, model.bending_hinges.reshape(-1),
              (s[:, None] * np.linalg.norm(g, axis=2)).reshape(-1))  # fmt: skip
    return out


# -- force and energy ----------------------------------------------------------------------
@pytest.mark.parametrize("name", list(CASES))
def test_core_force_and_energy_match_the_reference(name, simd):
    """The core's bending force (the whole force of a model with nothing else) and energy
    (total and per body) equal the reference's to 64 eps times the magnitudes summed
    (``_force_scale``; the energy's k (|theta - theta0| + |theta| + 1) |theta - theta0|);
    the forces are not zero, and sum to zero (no net force on the surface)."""
    model, q = CASES[name]()
    got = _core_force(model, q)
    want = rb.force(model, q)
    scale = _force_scale(model, q)
    assert np.all(np.abs(got - want) <= 64 * EPS * scale[:, None])
    assert np.abs(want).max() > 1e6 * 64 * EPS * scale.max() or name == "grid-near-flat"
    assert np.abs(want).max() > 0.0
    np.testing.assert_allclose(want.sum(axis=0), 0.0, atol=64 * EPS * scale.sum())
    total, body = _core_energy(model, q)
    theta, _, _ = rb.angles_and_gradients(model, q)
    d = np.abs(rb.excess(model, theta))
    e_scale = np.sum(model.bending_stiffness * (d + np.abs(theta) + 1.0) * d)
    assert abs(total - rb.energy(model, q)) <= 64 * EPS * e_scale
    assert body.shape == (1,) and body[0] == total
    assert total > 0.0


@pytest.mark.parametrize("name", list(CASES))
def test_core_force_is_minus_the_gradient_of_the_core_energy(name):
    """-dE/dx . p by central differences of the core's energy along three random
    directions p (seed 11) equals f . p of the core's force, within the differences'
    estimated O(h^2) error (twice |D(h) - D(h/2)| / 3) plus their round-off 64 eps |E| / h;
    the allowance is under 1e-4 of what f . p sums, so the check is sharp. Near flat the
    energy is tiny (about 1e-16 J), so the step there is 1e-10 m."""
    model, q = CASES[name]()
    f = _core_force(model, q)
    h = 1e-10 if name == "grid-near-flat" else 1e-5
    rng = np.random.default_rng(11)

    def energy(x):
        return _core_energy(model, x)[0]

    for _ in range(3):
        p = rng.normal(size=q.shape)
        coarse = (energy(q + h * p) - energy(q - h * p)) / (2 * h)
        fine = (energy(q + h / 2 * p) - energy(q - h / 2 * p)) / h
        exact = -np.sum(f * p)
        allowed = 2 * abs(coarse - fine) / 3 + 64 * EPS * (abs(energy(q)) + 1e-300) / h
        assert abs(fine - exact) <= allowed, (fine, exact, allowed)
        assert allowed < 1e-4 * np.sum(np.abs(f * p))


def test_rest_shape_mesh_is_at_rest_and_flat_is_not():
    """With rest_shape "mesh" the given mesh has zero energy and force up to round-off
    (theta0 is the builder's NumPy angle, theta the core's: they differ by a few eps
    (|theta| + 1)); with "flat" an icosphere has every rest angle 0 and positive energy,
    every hinge bent the same way (theta > 0 on a convex surface wound outward)."""
    mesh = sb.icosphere(2, radius=0.3)
    at_rest = _surface(mesh, sb.Bending(0.02))
    q = at_rest.particle_q
    slack = 16 * EPS * (np.abs(at_rest.bending_rest_angle) + 1.0)
    assert _core_energy(at_rest, q)[0] <= np.sum(at_rest.bending_stiffness * slack**2)
    assert np.all(np.abs(_core_force(at_rest, q)) <= 16 * EPS * _force_scale(at_rest, q)[:, None])
    flat = _surface(mesh, sb.Bending(0.02, rest_shape="flat"))
    assert np.all(flat.bending_rest_angle == 0.0)
    theta, _, live = rb.angles_and_gradients(flat, q)
    assert np.all(live) and np.all(theta > 0.0)
    assert _core_energy(flat, q)[0] > 0.0


def test_hinges_are_the_interior_edges():
    """Model.bending_hinges: one row per interior edge (a closed icosphere: every edge,
    E = 3 F / 2; the grid: its edges less its boundary's), each with (x0, x1, x2) a face
    and (x1, x0, x3) another, as wound; k = D |e0|^2 / (2 A0) at the rest positions."""
    sphere = _surface(sb.icosphere(2), sb.Bending(0.5))
    assert len(sphere.bending_hinges) == 3 * sphere.tri_count // 2
    nx, ny = 10, 8
    grid = _surface(sb.rectangle((1.0, 0.8), (nx, ny)), sb.Bending(0.5))
    edges = nx * (ny + 1) + ny * (nx + 1) + nx * ny
    assert len(grid.bending_hinges) == edges - 2 * (nx + ny)
    for model in (sphere, grid):
        faces = {tuple(np.roll(f, -k)) for f in model.tri_indices for k in range(3)}
        for x0, x1, x2, x3 in model.bending_hinges:
            assert (x0, x1, x2) in faces and (x1, x0, x3) in faces
        q = model.particle_q
        x = q[model.bending_hinges]
        e = x[:, 1] - x[:, 0]
        area = 0.5 * (np.linalg.norm(np.cross(e, x[:, 2] - x[:, 0]), axis=1)
                      + np.linalg.norm(np.cross(x[:, 3] - x[:, 0], e), axis=1))  # fmt: skip
        np.testing.assert_allclose(model.bending_stiffness,
                                   0.5 * np.sum(e * e, axis=1) / (2 * area),
                                   rtol=1e-14)  # fmt: skip


# -- the implicit solvers' Jacobian ----------------------------------------------------------
def _gauss_newton_by_hand(model, q, p):
    """K p = -sum over hinges 2 k g (g . p), g the 12-vector of theta's gradient, built
    here as a dense matrix from the reference's gradients."""
    _, g, _ = rb.angles_and_gradients(model, q)
    n3 = 3 * model.particle_count
    k_matrix = np.zeros((n3, n3))
    for h, corners in enumerate(model.bending_hinges):
        rows = (3 * corners[:, None] + np.arange(3)).reshape(-1)
        gh = g[h].reshape(-1)
        k_matrix[np.ix_(rows, rows)] -= 2.0 * model.bending_stiffness[h] * np.outer(gh, gh)
    return k_matrix, (k_matrix @ p.reshape(-1)).reshape(-1, 3)


@pytest.mark.parametrize("name", ["sphere-rest-flat", "grid"])
def test_jacobian_product_is_the_gauss_newton_stiffness(name, simd):
    """softbody._core.apply_jacobians (alpha_m = alpha_c = 0, alpha_k = 1.7) on a model
    with only bending equals 1.7 K p for K the Gauss-Newton stiffness -2 k g g^T built
    densely here, to 64 eps times the magnitudes; the reference's product likewise. K is
    symmetric and negative semi-definite (p . K p <= 0 for 20 random p, its largest
    eigenvalue at most round-off), and at a state where every hinge is at its rest angle
    it is the exact Hessian's negative: the force's central differences along p."""
    model, q = CASES[name]()
    rng = np.random.default_rng(13)
    p = rng.normal(size=q.shape)
    inputs = jacobians.prepare(model, control_data(model), 0.0, q)
    out = np.zeros_like(q)
    _core.apply_jacobians(core_model(model), control_data(model), q, p, 0.0, 0.0, 1.7, out,
                          **inputs.core_arguments())  # fmt: skip
    k_matrix, kp = _gauss_newton_by_hand(model, q, p)
    _, g, _ = rb.angles_and_gradients(model, q)
    gnorm = np.linalg.norm(g, axis=2)
    scale = np.zeros(model.particle_count)
    gp = np.einsum("hak,hak->h", np.abs(g), np.abs(p[model.bending_hinges]))
    np.add.at(scale, model.bending_hinges.reshape(-1),
              ((2 * 1.7 * model.bending_stiffness * gp)[:, None] * gnorm).reshape(-1))  # fmt: skip
    assert np.all(np.abs(out - 1.7 * kp) <= 64 * EPS * scale[:, None])
    ref_out = jacobians.apply_jacobians(model, control_data(model), q, p, 0.0, 0.0, 1.7, inputs)
    assert np.all(np.abs(ref_out - 1.7 * kp) <= 64 * EPS * scale[:, None])
    assert np.abs(kp).max() > 0.0
    np.testing.assert_array_equal(k_matrix, k_matrix.T)
    for _ in range(20):
        x = rng.normal(size=q.size)
        assert x @ k_matrix @ x <= 0.0
    assert np.linalg.eigvalsh(k_matrix)[-1] <= 1e-12 * np.abs(k_matrix).max()

    # at rest (theta = theta0: the model's own mesh) K p is d f / dx p exactly
    rest = _surface(sb.icosphere(2, radius=0.3), sb.Bending(0.02))
    q0 = rest.particle_q
    p = rng.normal(size=q0.shape)
    _, kp0 = _gauss_newton_by_hand(rest, q0, p)
    h = 1e-6
    fd = (_core_force(rest, q0 + h * p) - _core_force(rest, q0 - h * p)) / (2 * h)
    np.testing.assert_allclose(fd, kp0, atol=1e-6 * np.abs(kp0).max())


def test_smoother_blocks_hold_the_diagonal_of_the_system(simd):
    """The implicit Euler step with multigrid on a bent bending-only sheet runs (its
    smoother blocks are m I + 2 h^2 k g_a g_a^T) and matches the step with the Jacobi
    preconditioner to the CG tolerance: both solve the same system, M - h^2 K with the
    Gauss-Newton K."""
    model, q = CASES["grid"]()
    states = []
    for preconditioner in ("jacobi", "multigrid"):
        sim = sb.Simulator(model, integrator="implicit_euler", dt=1e-3,
                           implicit_tolerance=1e-12, implicit_max_iterations=2000,
                           implicit_preconditioner=preconditioner)  # fmt: skip
        state = model.state()
        state.particle_q[:] = q
        sim.run(state, 5)
        states.append(state.particle_q.copy())
    moved = np.abs(states[0] - q).max()
    assert moved > 1e-5
    np.testing.assert_allclose(states[1], states[0], atol=1e-8 * moved)


# -- input -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: sb.Bending(-1.0), "bending stiffness must be > 0"),
        (lambda: sb.Bending(0.0), "bending stiffness must be > 0"),
        (lambda: sb.Bending(float("nan")), "bending stiffness must be finite"),
        (lambda: sb.Bending("soft"), "bending stiffness must be a number"),
        (lambda: sb.Bending(1.0, rest_shape="round"), "rest_shape must be 'mesh' or 'flat'"),
        (lambda: sb.Bending.from_material(-2e9, 0.3, 1e-4), "youngs_modulus must be > 0"),
        (lambda: sb.Bending.from_material(2e9, 0.7, 1e-4), r"poisson_ratio must lie in \(-1"),
        (lambda: sb.Bending.from_material(2e9, -1.0, 1e-4), r"poisson_ratio must lie in \(-1"),
        (lambda: sb.Bending.from_material(2e9, 0.3, 0.0), "thickness must be > 0"),
        (lambda: sb.Bending.from_material(2e9, 0.3, float("inf")), "thickness must be finite"),
    ],
)  # fmt: skip
def test_bad_bending_input_is_refused(make, message):
    """A ValueError naming the parameter for each bad value."""
    with pytest.raises(ValueError, match=message):
        make()


def test_builder_refuses_what_is_not_a_bending():
    """add_soft_body / add_cloth: bending=<a number> is a ValueError that says what to
    give, and the builder is left as it was."""
    b = sb.ModelBuilder()
    with pytest.raises(ValueError, match="bending must be a softbody.Bending"):
        b.add_cloth(sb.rectangle(), mass=1.0, stiffness=1.0, damping=0.0, bending=0.01)
    with pytest.raises(ValueError, match="bending must be a softbody.Bending"):
        b.add_soft_body(sb.icosphere(1), mass=1.0, stiffness=1.0, damping=0.0, gas=1.0,
                        bending=0.01)  # fmt: skip
    assert b.particle_count == 0 and b.body_count == 0


def test_from_material_is_the_plate_formula():
    """D = E H^3 / (12 (1 - nu^2)): a 0.1 mm PET film (E = 4 GPa, nu = 0.4) has
    D = 4e9 1e-12 / (12 0.84) = 3.968e-4 N m."""
    d = sb.Bending.from_material(4e9, 0.4, 1e-4).stiffness
    assert d == pytest.approx(4e9 * 1e-12 / (12 * 0.84), rel=1e-15)
    assert sb.Bending.from_material(4e9, 0.4, 1e-4, rest_shape="flat").rest_shape == "flat"


# -- closed forms ----------------------------------------------------------------------------
def _triangle_grid(nx: int, ny: int, a: float) -> sb.TriMesh:
    """A flat sheet of equilateral triangles of side ``a`` [m] in the xy plane facing +z:
    ny + 1 rows of nx + 1 vertices along x, row j at y = j a sqrt(3) / 2 and shifted by
    a / 2 when j is odd."""
    j, i = np.meshgrid(np.arange(ny + 1), np.arange(nx + 1), indexing="ij")
    x = i * a + 0.5 * a * (j % 2)
    v = np.stack([x.ravel(), (j * a * np.sqrt(3) / 2).ravel(), np.zeros(x.size)], axis=1)
    faces = []
    for row in range(ny):
        for col in range(nx):
            p, q = row * (nx + 1) + col, (row + 1) * (nx + 1) + col
            if row % 2 == 0:
                faces += [(p, p + 1, q), (p + 1, q + 1, q)]
            else:
                faces += [(p, q + 1, q), (p, p + 1, q + 1)]
    return sb.TriMesh(v, np.array(faces))


def _area(mesh: sb.TriMesh) -> float:
    v, f = mesh.vertices, mesh.faces
    return 0.5 * float(np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]),
                                      axis=1).sum())  # fmt: skip


def _rolled(q: np.ndarray, radius: float, angle: float) -> np.ndarray:
    """Flat positions q (N, 3) (z = 0) wrapped onto a cylinder of ``radius`` [m] whose
    axis lies in the plane at ``angle`` [rad] from y: lengths are kept (an isometry)."""
    q = q - q.mean(axis=0)
    c, s = np.cos(angle), np.sin(angle)
    u = q[:, 0] * c + q[:, 1] * s  # across the axis: the arc length
    w = -q[:, 0] * s + q[:, 1] * c  # along the axis
    phi = u / radius
    return np.stack([radius * np.sin(phi) * c - w * s, radius * np.sin(phi) * s + w * c,
                     radius * (1.0 - np.cos(phi))], axis=1)  # fmt: skip


@pytest.mark.parametrize("angle", [0.0, 30.0, 45.0, 90.0])
def test_cylinder_energy_is_the_plates_on_equilateral_triangles(angle):
    """A flat sheet of equilateral triangles (n x n, side 1/n m, D = 0.01 N m, rest flat)
    rolled onto a cylinder of radius R = 0.5 m about an axis at ``angle`` degrees in its
    plane: the energy is the plate's D / (2 R^2) times the area (zero Gaussian curvature).
    The hinges cover the sheet but for a boundary strip about one row wide, so the energy
    falls short by at most 1 / n relative: here within 1.05 / n at n = 16 and 32, and the
    error shrinks as n grows."""
    d, radius = 0.01, 0.5
    errors = []
    for n in (16, 32):
        mesh = _triangle_grid(n, n, 1.0 / n)
        model = _surface(mesh, sb.Bending(d))
        q = _rolled(model.particle_q, radius, np.radians(angle))
        ratio = rb.energy(model, q) / (d / (2 * radius**2) * _area(mesh))
        errors.append(abs(ratio - 1.0))
        assert errors[-1] <= 1.05 / n, (n, ratio)
    assert errors[1] < errors[0]


def test_cylinder_on_a_right_triangle_grid_depends_on_the_direction():
    """The mesh dependence the guide states: sb.rectangle's grid (squares cut along one
    diagonal) rolled about a grid line gives the plate's energy to 1 / n (n = 48), but
    rolled about the other diagonal, across the cut, about 3 times it (2.96 measured)."""
    d, radius, n = 0.01, 0.5, 48
    mesh = sb.rectangle((1.0, 1.0), (n, n))
    model = _surface(mesh, sb.Bending(d))
    plate = d / (2 * radius**2) * _area(mesh)
    for angle in (0.0, 90.0):
        ratio = rb.energy(model, _rolled(model.particle_q, radius, np.radians(angle))) / plate
        assert abs(ratio - 1.0) <= 1.05 / n
    ratio = rb.energy(model, _rolled(model.particle_q, radius, np.radians(45.0))) / plate
    assert 2.8 < ratio < 3.1


def test_sphere_energy_with_flat_rest_angles():
    """An icosphere of radius 0.3 m with rest angles 0 (rest_shape "flat"): the discrete
    energy on near-equilateral triangles is D / 2 [(2H)^2 - (8/3) K] per area (its
    cylinder is the plate's, test above; its sphere carries the rest), so a sphere's is
    (D / 2)(4 - 8/3) / R^2 4 pi R^2 = 8 pi D / 3, independent of R. The icosphere's
    triangles are not all equilateral, and the sum converges to 1.5% above that:
    measured 1.0157 at 3 subdivisions and 1.0153 at 4. Checked: within [1, 1.02] at both,
    and the two within 0.1% (converged). The plate with the Gaussian term, 4 pi D (1 +
    nu), differs by a constant for a closed surface (Gauss-Bonnet), which exerts no force."""
    d = 0.02
    ratios = []
    for level in (3, 4):
        model = _surface(sb.icosphere(level, radius=0.3), sb.Bending(d, rest_shape="flat"))
        total, _ = _core_energy(model, model.particle_q)
        ratios.append(total / (8 * np.pi * d / 3))
        assert 1.0 <= ratios[-1] <= 1.02, ratios
    assert abs(ratios[1] - ratios[0]) < 1e-3


def _cantilever(
    a: float, integrator: str = "implicit_euler", steps: int = 100
) -> tuple[float, float, float]:
    """A plate 0.2 m wide and about 0.2 m long of equilateral triangles of side a [m],
    0.2 kg/m^2, D = 0.1 N m, stiff in its plane (edge springs 2000 N/m, 0.5 N s/m),
    clamped by pinning its first two rows, sagging under gravity: ``integrator`` (implicit
    Euler, or BDF2) at dt = 0.01 s for ``steps`` + 50 steps. Returns (tip deflection [m],
    free length L from the second row to the tip [m], row spacing s [m]); the tip's last
    50 steps moved it by < 1e-6 of itself (settled)."""
    nx, ny = round(0.2 / a), round(0.2 / (a * np.sqrt(3) / 2))
    mesh = _triangle_grid(nx, ny, a)
    rows = np.arange(mesh.vertex_count) // (nx + 1)
    b = sb.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    b.add_cloth(mesh, mass=0.2 * _area(mesh), stiffness=2000.0, damping=0.5,
                bending=sb.Bending(0.1), pinned=np.flatnonzero(rows <= 1),
                mass_distribution="area")  # fmt: skip
    model = b.finalize()
    sim = sb.Simulator(model, integrator=integrator, dt=0.01, implicit_max_iterations=2000)
    state = model.state()
    sim.run(state, steps)
    before = state.particle_q[rows == ny, 2].mean()
    sim.run(state, 50)
    tip = state.particle_q[rows == ny, 2].mean()
    assert abs(tip - before) < 1e-6 * abs(tip)
    y = mesh.vertices[:, 1]
    return -tip, y[rows == ny].mean() - y[rows == 1].mean(), a * np.sqrt(3) / 2


def test_cantilever_tip_deflection_is_euler_bernoulli():
    """A clamped plate sagging under its weight q = rho_A g per area: the tip deflection
    of Euler-Bernoulli, w = q L^4 / (8 D) (q L^4 / (8 D b) per width b), small here
    (w / L about 2%). The discrete clamp: the hinges on the last pinned row stand for the
    curvature of a strip s / 2 either side of it (s the row spacing), so the plate is
    clamped half a row before that row, L_eff = L + s / 2; with it the deflection is
    within 6% at a = 2 cm and 1 cm (1.040 and 1.035 of w measured: the rest is the
    plate's sides, free to curve across), and without it the error halves with a."""
    rho, g, d = 0.2, 9.81, 0.1
    plain = []
    for a in (0.02, 0.01):
        tip, length, s = _cantilever(a)
        plain.append(tip / (rho * g * length**4 / (8 * d)))
        assert tip / (rho * g * (length + s / 2) ** 4 / (8 * d)) == pytest.approx(1.0, abs=0.06)
        assert tip < 0.03 * length  # small deflection
    assert plain[1] - 1.0 < 0.6 * (plain[0] - 1.0)


# -- time stepping -------------------------------------------------------------------------
def _bent_sheet(spring_stiffness: float, d: float) -> tuple[sb.Model, np.ndarray]:
    """A free 0.4 x 0.35 m sheet of equilateral triangles (8 x 8, 0.1 kg, edge springs of
    ``spring_stiffness`` [N/m], no damping, no gravity, D = ``d`` [N m], rest flat) and its
    start: rolled onto a cylinder of radius 0.3 m, at rest."""
    b = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    b.add_cloth(_triangle_grid(8, 8, 0.05), mass=0.1, stiffness=spring_stiffness, damping=0.0,
                bending=sb.Bending(d))  # fmt: skip
    model = b.finalize()
    return model, _rolled(model.particle_q, 0.3, 0.0)


def test_velocity_verlet_conserves_energy_to_second_order():
    """Velocity Verlet on the free bent sheet unrolling (springs 50 N/m, D = 0.01 N m)
    for 0.5 s: the largest change of the total energy (kinetic + springs + bending) over
    the run is O(dt^2): it falls by 4 (3.5 to 4.5) when dt halves, from a quarter of the
    stable-step estimate, and stays below 1e-3 of the bending energy at the start."""
    model, q0 = _bent_sheet(50.0, 0.01)
    dt0 = sb.stable_dt(model, "velocity_verlet", q=q0) / 4
    drift = []
    for dt in (dt0, dt0 / 2):
        sim = sb.Simulator(model, integrator="velocity_verlet", dt=dt)
        state = model.state()
        state.particle_q[:] = q0
        start = sb.energies(model, state)
        steps = round(0.5 / dt0)
        worst = 0.0
        for _ in range(25):
            sim.run(state, steps * (dt0 / dt) // 25)
            worst = max(worst, abs(sb.energies(model, state).total - start.total))
        drift.append(worst)
        bending_start = start.terms["bending"]
        assert worst < 1e-3 * bending_start
        assert sb.energies(model, state).kinetic > 0.05 * bending_start  # it moved
    assert 3.5 < drift[0] / drift[1] < 4.5


@pytest.mark.parametrize("integrator", ["velocity_verlet", "symplectic_euler", "rk4"])
def test_stable_step_estimate_includes_bending(integrator):
    """A bending-dominated sheet (springs 5 N/m, D = 0.05 N m, started bent): its mode
    bound's omega_terms["bending"] is the square root of the core's bending rows; the estimate
    with bending (at its flat rest, as Simulator takes it) is over 3 times shorter than
    without it (the springs' alone); 3000 steps at the estimate keep the energy within
    30% of its start, and 3000 steps at the estimate without bending (the step it would
    have taken) blow it up by 100 times or more."""
    model, q0 = _bent_sheet(5.0, 0.05)
    b = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    b.add_cloth(_triangle_grid(8, 8, 0.05), mass=0.1, stiffness=5.0, damping=0.0)
    springs_only = b.finalize()
    dt = sb.stable_dt(model, integrator)  # at the model's positions, as Simulator takes it
    rows = _core.stiffness_bounds(core_model(model), control_data(model),
                                  model.particle_q)["terms"]["bending"][1]  # fmt: skip
    mode = sb.stability.stiffest_mode(model, spectral=False)
    assert mode.omega_terms["bending"] == pytest.approx(np.sqrt(rows), rel=1e-15) and rows > 0
    dt_springs = sb.stable_dt(springs_only, integrator)
    assert dt < dt_springs / 3
    sim = sb.Simulator(model, integrator=integrator, dt=dt)
    state = model.state()
    state.particle_q[:] = q0
    start = sb.energies(model, state).total
    sim.run(state, 3000)
    assert abs(sb.energies(model, state).total - start) < 0.3 * start
    with pytest.warns(sb.StabilityWarning):
        sim = sb.Simulator(model, integrator=integrator, dt=dt_springs)
    state = model.state()
    state.particle_q[:] = q0
    try:
        sim.run(state, 3000)
        assert not sb.energies(model, state).total < 100 * start
    except sb.SimulationError:
        pass  # stopped as it blew up


def test_bdf2_settles_to_the_implicit_euler_deflection():
    """BDF2 (the same Jacobian product and smoother blocks, its own history) settles the
    clamped plate (a = 2 cm) to implicit Euler's tip deflection, to 0.1%: the static
    equilibrium f = 0 does not depend on the scheme. BDF2 damps far less, so it is given
    1000 steps to settle."""
    tip, _, _ = _cantilever(0.02)
    assert _cantilever(0.02, "bdf2", steps=1000)[0] == pytest.approx(tip, rel=1e-3)


def test_projective_dynamics_steps_bending_explicitly():
    """Projective dynamics takes the bending force explicitly in its iterations (no
    projection, as the gas): on the clamped plate of the cantilever (a = 2 cm) it
    settles, with its damping, to the same tip deflection as implicit Euler, to 1%, at a
    step 17 times 1 / omega_terms["bending"] (the bending's bound against the masses alone): its
    global step holds every edge spring's full stiffness in every direction, which
    resists the stiff bending modes, so its step rule counts the gas's volume mode only."""
    a = 0.02
    tip, _, _ = _cantilever(a)
    nx, ny = round(0.2 / a), round(0.2 / (a * np.sqrt(3) / 2))
    mesh = _triangle_grid(nx, ny, a)
    rows = np.arange(mesh.vertex_count) // (nx + 1)
    b = sb.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    b.add_cloth(mesh, mass=0.2 * _area(mesh), stiffness=2000.0, damping=0.5,
                bending=sb.Bending(0.1), pinned=np.flatnonzero(rows <= 1),
                mass_distribution="area")  # fmt: skip
    model = b.finalize()
    assert "bending" in sb.diagnostics.active_terms(model)
    sim = sb.Simulator(model, integrator="projective", dt=1e-3, projective_iterations=10)
    assert sim.stiffest_mode.omega_terms["bending"] * 1e-3 > 15.0
    state = model.state()
    sim.run(state, 3000)
    assert -state.particle_q[rows == ny, 2].mean() == pytest.approx(tip, rel=0.01)


# -- scene files ---------------------------------------------------------------------------
def test_scene_bending_table_builds_the_same_model_as_the_library():
    """A body's ``bending`` table in a scene (here by --set overrides on cloth-wind): with
    stiffness D, or with youngs_modulus, poisson_ratio and thickness, the model's hinges
    and their stiffnesses are those of add_cloth(bending=Bending(...)) on the same mesh;
    rest_shape passes through."""
    from softbody.scenes import load_scene

    by_d = load_scene("cloth-wind", ["bodies.0.bending.stiffness=0.01"]).model
    material = load_scene("cloth-wind", [
        "bodies.0.bending={youngs_modulus=2e9, poisson_ratio=0.3, thickness=1e-4, "
        "rest_shape='flat'}"])  # fmt: skip
    mesh = sb.rectangle((1.2, 1.2), (24, 24)).translated(np.array([0.0, 1.0, 0.0]))
    b = sb.ModelBuilder()
    b.add_cloth(mesh, mass=0.3, stiffness=120.0, damping=0.1, bending=sb.Bending(0.01))
    want = b.finalize()
    np.testing.assert_array_equal(by_d.bending_hinges, want.bending_hinges)
    np.testing.assert_allclose(by_d.bending_stiffness, want.bending_stiffness, rtol=1e-15)
    d = 2e9 * 1e-12 / (12 * (1 - 0.09))
    np.testing.assert_allclose(material.model.bending_stiffness, want.bending_stiffness * d / 0.01,
                               rtol=1e-14)  # fmt: skip
    assert np.all(material.model.bending_rest_angle == 0.0)
    assert load_scene("cloth-wind").model.bending_hinges.shape == (0, 4)


@pytest.mark.parametrize(
    ("override", "expected"),
    [
        ("bodies.0.bending.stiffness=-1", "bodies.0.bending.stiffness: must be > 0, got -1"),
        ("bodies.0.bending={stiffness=0.01, thickness=1e-4}",
         "bodies.0.bending.stiffness: give stiffness, or youngs_modulus, poisson_ratio and "
         "thickness, not both"),
        ("bodies.0.bending={youngs_modulus=2e9}",
         "bodies.0.bending.stiffness: give stiffness, or all of youngs_modulus, "
         "poisson_ratio and thickness"),
        ("bodies.0.bending={stiffness=1, poisson_ratio=0.7}",
         "bodies.0.bending.poisson_ratio: must be <= 0.5, got 0.7"),
        ("bodies.0.bending={stiffness=1, rest_shape='round'}",
         "bodies.0.bending.rest_shape: must be one of 'mesh' or 'flat', got 'round'"),
        ("bodies.0.bending.stifness=1", "unknown scene key bodies.0.bending.stifness (valid: "
         "poisson_ratio, rest_shape, stiffness, thickness, youngs_modulus)"),
    ],
)  # fmt: skip
def test_scene_bending_table_is_checked(override, expected):
    """Each bad ``bending`` table is one line naming the dotted key and the reason."""
    from softbody.scenes import load_scene

    with pytest.raises(ValueError) as info:
        load_scene("cloth-wind", [override])
    assert str(info.value) == expected


# -- one step against the reference steps ------------------------------------------------------
def _step_case():
    """The sheet of _bent_sheet under gravity (springs 50 N/m and 0.2 N s/m, D = 0.01
    N m), two corners pinned, started rolled with a random velocity (seed 17, 0.1 m/s):
    (model, q0, v0)."""
    b = sb.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    b.add_cloth(_triangle_grid(8, 8, 0.05), mass=0.1, stiffness=50.0, damping=0.2,
                bending=sb.Bending(0.01), pinned=[0, 8])  # fmt: skip
    model = b.finalize()
    q0 = _rolled(model.particle_q, 0.3, 0.0)
    v0 = np.random.default_rng(17).normal(0.0, 0.1, q0.shape)
    v0[[0, 8]] = 0.0
    return model, q0, v0


def test_one_backward_euler_step_matches_the_reference(simd):
    """One implicit Euler step with bending equals softbody.reference.steps' dense Newton
    step (M - h C - h^2 K) dv = h (f0 + K h v0), K with the bending's Gauss-Newton part,
    solved by numpy: CG stops at |r| <= tol |b|, so |dv - dv_ref| <= tol |b| / sigma_min
    (as test_reference.py's step test)."""
    from softbody import reference as ref
    from softbody.reference import steps

    model, q0, v0 = _step_case()
    dt, tolerance = 5e-3, 1e-12
    sim = sb.Simulator(model, integrator="implicit_euler", dt=dt, implicit_tolerance=tolerance,
                       implicit_max_iterations=5000)  # fmt: skip
    state = model.state()
    state.particle_q[:], state.particle_qd[:] = q0, v0
    sim.step(state)
    expected = steps.backward_euler_step(model, ref.control_arrays(model), 0.0, dt, q0, v0)
    sigma_min = np.linalg.svd(expected.matrix, compute_uv=False)[-1]
    bound = tolerance * np.linalg.norm(expected.rhs) / sigma_min
    bound += 16 * EPS * np.abs(expected.qd).max()
    assert bound < 1e-8 * np.abs(expected.qd - v0).max()
    assert np.linalg.norm(state.particle_qd - expected.qd) <= bound
    # the bending is in it: the same step without bending's force and stiffness differs
    b = sb.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    b.add_cloth(_triangle_grid(8, 8, 0.05), mass=0.1, stiffness=50.0, damping=0.2,
                pinned=[0, 8])  # fmt: skip
    without = steps.backward_euler_step(b.finalize(), ref.control_arrays(model), 0.0, dt, q0, v0)
    assert np.linalg.norm(without.qd - expected.qd) > 1e3 * bound


def test_one_projective_step_matches_the_reference(simd):
    """One projective-dynamics step (3 iterations) with bending equals the reference's
    dense local-global iterations, bending among the forces kept explicit in each
    iteration, to ULPS eps cond(A) |x| per iteration (test_reference.py's bound)."""
    from softbody import reference as ref
    from softbody.reference import steps

    model, q0, v0 = _step_case()
    dt = 5e-3
    sim = sb.Simulator(model, integrator="projective", dt=dt, projective_iterations=3)
    state = model.state()
    state.particle_q[:], state.particle_qd[:] = q0, v0
    sim.step(state)
    x, _ = steps.projective_step(model, ref.control_arrays(model), 0.0, dt, q0, v0, 3)
    cond = np.linalg.cond(steps.projective_matrix(model, dt))
    bound = 3 * 16 * EPS * cond * np.abs(x).max()
    assert bound < 1e-6 * np.abs(x - q0).max()
    assert np.abs(state.particle_q - x).max() <= bound


def _hessian_frequency(model: sb.Model, q: np.ndarray) -> float:
    """Largest eigenvalue [1/s^2] of M^-1/2 H M^-1/2, H = -df/dx the bending energy's
    whole Hessian at q by central differences of the reference force (h = 1e-7 m),
    symmetrised; pinned particles left out."""
    n, h = model.particle_count, 1e-7
    hessian = np.zeros((3 * n, 3 * n))
    for k in range(3 * n):
        d = np.zeros(3 * n)
        d[k] = h
        d = d.reshape(-1, 3)
        hessian[:, k] = -(rb.force(model, q + d) - rb.force(model, q - d)).ravel() / (2 * h)
    s = np.repeat(np.sqrt(model.particle_inv_mass), 3)
    a = s[:, None] * 0.5 * (hessian + hessian.T) * s[None, :]
    return float(np.linalg.eigvalsh(a)[-1])


@pytest.mark.parametrize("case", ["sphere-flat", "grid-perturbed", "grid-folded"])
def test_bound_rows_cover_the_whole_hessian(case):
    """The stability estimate's bending rows (softbody._core.stiffness_bounds) bound the
    largest eigenvalue of M^-1/2 H M^-1/2 for H the whole Hessian of the bending energy
    (not the Gauss-Newton part alone): on an icosphere with flat rest angles (every hinge
    0.31 to 0.39 rad from rest), a grid moved out of its plane by up to 5 cm, and a grid folded
    by 0.67 rad along a line. stiffest_mode's undamped bound holds it too."""
    if case == "sphere-flat":
        model = _surface(sb.icosphere(1, radius=0.3), sb.Bending(0.02, rest_shape="flat"))
        q = model.particle_q
    else:
        model = _surface(sb.rectangle((1.0, 0.8), (6, 5)), sb.Bending(0.01))
        q = model.particle_q.copy()
        if case == "grid-perturbed":
            q[:, 2] += np.random.default_rng(7).uniform(-0.05, 0.05, len(q))
        else:
            q[:, 2] = np.where(q[:, 0] > 0.0, 0.8 * q[:, 0], 0.0)
    rows = _core.stiffness_bounds(core_model(model), control_data(model), q)["terms"]["bending"][1]
    whole = _hessian_frequency(model, q)
    assert whole > 0.0
    assert rows >= whole, (rows, whole)
    assert sb.stability.stiffest_mode(model, q).omega_undamped ** 2 >= whole
