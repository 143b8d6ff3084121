"""The implicit solver's multigrid preconditioner: a symmetric positive-definite operator
(what preconditioned CG needs), iteration counts that barely grow with the mesh, and the
same backward Euler step as the Jacobi-preconditioned solve."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import softbody as sb
from conftest import ball_model
from softbody import _core
from softbody.core import core_model
from softbody.sim.control import control_data
from softbody.solvers.multigrid import build_multigrid, set_multigrid_step

DT = 1.0 / 60.0


def level_matrix(mg, level: int = 0) -> sp.csr_matrix:
    n = int(mg.level_size[level])
    r0, z0 = mg.a_row_offset[level], mg.a_nz_offset[level]
    indptr = mg.a_indptr[r0 : r0 + n + 1]
    nnz = int(indptr[-1])
    return sp.csr_matrix(
        (mg.a_data[z0 : z0 + nnz], mg.a_indices[z0 : z0 + nnz], indptr), shape=(n, n)
    )


def v_cycle(model, mg):
    """The core's V-cycle of hierarchy ``mg`` as apply(r, z) on (N, 3) arrays."""

    def apply(r, z):
        z[:] = _core.apply_multigrid(core_model(model), mg, np.ascontiguousarray(r))

    return apply


def dense_operator(apply, n: int) -> np.ndarray:
    """The (3n, 3n) matrix of a linear map on (n, 3) arrays, column by column."""
    out = np.zeros((3 * n, 3 * n))
    e, z = np.zeros((n, 3)), np.zeros((n, 3))
    for col in range(3 * n):
        e[:] = 0.0
        e.flat[col] = 1.0
        apply(e, z)
        out[:, col] = z.ravel()
    return out


def test_finest_level_is_mass_plus_spring_laplacian():
    """A_0 = M + dt L_c + dt^2 L_k: row sums are the masses (a Laplacian's rows sum to
    zero), and the off-diagonal entry of each edge is -(dt c + dt^2 k)."""
    k, c = 500.0, 0.5
    model = ball_model(subdivisions=2, stiffness=k, damping=c)
    mg = build_multigrid(model)
    set_multigrid_step(mg, DT)
    a = level_matrix(mg)
    assert np.allclose(np.asarray(a.sum(axis=1)).ravel(), model.particle_mass, rtol=1e-12)
    i, j = model.spring_indices[0]
    assert a[i, j] == pytest.approx(-(DT * c + DT * DT * k), rel=1e-12)
    assert abs(a - a.T).max() == 0.0


def test_coarsest_level_is_factored_for_its_dense_solve():
    """The coarsest level, solved densely in the V-cycle, holds the Cholesky factor of its
    matrix at the current step: L L^T = A_L to round-off, L lower triangular."""
    model = ball_model(subdivisions=3, stiffness=500.0, damping=0.5)
    mg = build_multigrid(model)
    set_multigrid_step(mg, DT)
    assert mg.coarse_dense
    a = level_matrix(mg, mg.level_count).toarray()
    factor = mg.coarse_cholesky
    assert np.array_equal(factor, np.tril(factor))
    assert np.abs(factor @ factor.T - a).max() <= 1e-12 * np.abs(a).max()


def test_v_cycle_is_symmetric_positive_definite():
    """Forward Gauss-Seidel down, backward up, Galerkin coarse levels and an exact coarsest
    solve make the V-cycle a symmetric positive-definite operator, which preconditioned
    CG requires (checked on its dense matrix, 642 vertices, 3 levels)."""
    model = ball_model(subdivisions=3, stiffness=500.0, damping=0.5)
    mg = build_multigrid(model)
    set_multigrid_step(mg, DT)
    assert mg.level_count >= 1
    n = model.particle_count
    b = dense_operator(v_cycle(model, mg), n)
    assert np.abs(b - b.T).max() <= 1e-12 * np.abs(b).max()
    assert np.linalg.eigvalsh(0.5 * (b + b.T)).min() > 0.0


@pytest.mark.parametrize("subdivisions", [4, 5])
def test_multigrid_cg_iterations_do_not_grow_with_the_mesh(subdivisions):
    """Multigrid's point: CG on A_0 with one V-cycle as preconditioner reaches a relative
    residual of 1e-8 in a number of iterations nearly independent of the mesh size (at
    most 25 here for 2,562 and 10,242 vertices; Jacobi needs ~omega_max dt ~ 300)."""
    model = ball_model(subdivisions=subdivisions, stiffness=500.0, damping=0.5)
    mg = build_multigrid(model)
    set_multigrid_step(mg, DT)
    a = level_matrix(mg)
    n = model.particle_count
    rng = np.random.default_rng(7)
    b = rng.standard_normal((n, 3))
    x, r, z = np.zeros((n, 3)), b.copy(), np.zeros((n, 3))
    apply_multigrid = v_cycle(model, mg)
    apply_multigrid(r, z)
    p, rz = z.copy(), np.sum(r * z)
    iterations = 0
    while iterations < 100:
        iterations += 1
        ap = a @ p
        alpha = rz / np.sum(p * ap)
        x += alpha * p
        r -= alpha * ap
        if np.linalg.norm(r) <= 1e-8 * np.linalg.norm(b):
            break
        apply_multigrid(r, z)
        rz, rz_old = np.sum(r * z), rz
        p = z + rz / rz_old * p
    assert np.linalg.norm(a @ x - b) <= 1e-8 * np.linalg.norm(b)
    assert iterations <= 25


def pinned_attached_ball() -> sb.Model:
    builder = sb.ModelBuilder(gravity=(0.0, -9.81, 0.0))
    mesh = sb.icosphere(3, radius=0.5, center=(0.0, 1.0, 0.0))
    top = np.flatnonzero(mesh.vertices[:, 1] > 1.45)
    builder.add_soft_body(
        mesh, mass=1.0, stiffness=400.0, damping=0.4, gas=40.0, pinned=top, bend_stiffness=2.0
    )
    side = int(np.argmax(mesh.vertices[:, 0]))
    builder.add_attachment(side, (1.0, 1.0, 0.0), stiffness=50.0, damping=0.2, rest_length=0.2)
    return builder.finalize()


def test_hybrid_preconditioner_is_spd_on_the_free_particles():
    """The solver's preconditioner (block Gauss-Seidel with the true spring blocks, then
    the Laplacian hierarchy) is symmetric, zero on pinned rows and positive definite on
    the free ones, with pins, bending springs and an attachment: what preconditioned CG
    requires. Its blocks are taken at the ball after five implicit steps."""
    model = pinned_attached_ball()
    sim = sb.Simulator(model, integrator="implicit_euler", dt=DT)
    state = model.state()
    sim.run(state, 5)
    core = sim.solver._core
    control = control_data(model)
    n = model.particle_count

    def apply(r, z):
        z[:] = core.apply_preconditioner(control, state.time, DT, state.particle_q, r)

    b = dense_operator(apply, n)
    free = np.repeat(model.particle_inv_mass > 0, 3)
    assert np.abs(b[~free]).max() == 0.0 and np.abs(b[:, ~free]).max() == 0.0
    bf = b[np.ix_(free, free)]
    assert np.abs(bf - bf.T).max() <= 1e-12 * np.abs(bf).max()
    assert np.linalg.eigvalsh(0.5 * (bf + bf.T)).min() > 0.0


def crumpled_ball() -> tuple[sb.Model, sb.State, sb.Simulator]:
    """A 642-vertex ball with self-contact, its gas drawn down under a 500 Pa ambient
    pressure (the vacuum-packed ball of benchmarks/self_contact.py, smaller), after 0.3 s of
    implicit Euler at 1/240 s (the simulator returned with it): folded, its sheets pressed
    together h apart in many pairs."""
    ambient = 500.0
    nrt = ambient * 4.0 / 3.0 * np.pi * 0.5**3
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.set_soft_contact("surface", self_contact=True, restitution=0.0, friction=0.1)
    builder.add_soft_body(
        sb.icosphere(3, radius=0.5), mass=1.0, stiffness=200.0, damping=0.5,
        gas=sb.Gas.isothermal(
            nrt, ambient_pressure=ambient, schedule=[(0.0, nrt), (0.2, 0.02 * nrt)]
        ),
    )  # fmt: skip
    model = builder.finalize()
    state = model.state()
    sim = sb.Simulator(model, integrator="implicit_euler", dt=1 / 240)
    sim.run(state, 72)
    return model, state, sim


def test_preconditioner_with_the_contact_pairs_is_spd():
    """With the thickness contacts' pairs near at a crumpled ball's positions, the
    multigrid preconditioner (its finest sweeps reading the pairs' blocks between particles,
    each particle's pairs with one other particle summed into one block, forward over the
    earlier particles, backward over all) is still symmetric to round-off (1e-12 relative)
    and positive definite, as preconditioned CG requires; and the pairs change it (by more
    than 1 % of its largest entry), so they are in it."""
    model, state, sim = crumpled_ball()
    core = sim.solver._core
    control = control_data(model)
    n = model.particle_count
    h = 1 / 240
    operators = []
    for contacts in (False, True):

        def apply(r, z, contacts=contacts):
            z[:] = core.apply_preconditioner(
                control, state.time, h, state.particle_q, r, contacts=contacts
            )

        operators.append(dense_operator(apply, n))
    plain, b = operators
    assert np.abs(b - plain).max() > 0.01 * np.abs(plain).max()
    assert np.abs(b - b.T).max() <= 1e-12 * np.abs(b).max()
    assert np.linalg.eigvalsh(0.5 * (b + b.T)).min() > 0.0


def test_multigrid_and_jacobi_take_the_same_backward_euler_step():
    """Both preconditioners solve the same linear system of backward Euler, so with the
    CG tolerance at 1e-12 one second of a pinned, attached, falling ball agrees to 1e-8 m
    (round-off amplified over 60 steps), pinned particles untouched."""
    model = pinned_attached_ball()
    states = []
    for pre in ("multigrid", "jacobi"):
        sim = sb.Simulator(
            model,
            integrator="implicit_euler",
            dt=DT,
            implicit_tolerance=1e-12,
            implicit_max_iterations=2000,
            implicit_preconditioner=pre,
        )
        state = model.state()
        sim.run(state, 60)
        states.append(state)
    assert np.abs(states[0].particle_q - states[1].particle_q).max() < 1e-8
    pinned = model.particle_inv_mass == 0
    assert np.array_equal(states[0].particle_q[pinned], model.particle_q[pinned])


def test_multigrid_needs_far_fewer_iterations_than_jacobi():
    """On the issue's stiff 2,562-vertex ball (k = 500 N/m, omega_max dt ~ 100 at 1/60 s),
    the multigrid preconditioner cuts the mean CG iterations per step at tolerance 1e-6 at
    least threefold (measured here: ~14 against ~80)."""
    builder = sb.ModelBuilder()
    builder.add_soft_body(
        sb.icosphere(4, radius=1.0, center=(0.0, 2.0, 0.0)),
        mass=1.0,
        stiffness=500.0,
        damping=0.5,
        gas=sb.Gas.isothermal(300.0),
    )
    builder.add_collider(sb.ColliderPlane(restitution=0.5, friction=0.1))
    model = builder.finalize()
    means = {}
    for pre in ("multigrid", "jacobi"):
        sim = sb.Simulator(model, integrator="implicit_euler", dt=DT, implicit_preconditioner=pre)
        sim.run(model.state(), 30)
        means[pre] = sim.solver_iterations[0]
    assert means["multigrid"] * 3 <= means["jacobi"], means


def test_unknown_preconditioner_is_refused():
    """Bad input: a preconditioner name that does not exist."""
    with pytest.raises(ValueError, match="implicit_preconditioner must be"):
        sb.Simulator(
            ball_model(), integrator="implicit_euler", dt=DT, implicit_preconditioner="ilu"
        )


def test_every_coupling_term_has_a_stencil():
    """The smoother's stencil builders (softbody.solvers.multigrid.STENCILS) are exactly
    the core's terms with blocks between particles in the smoother (stencil_width > 0,
    softbody._core.term_table), in the registry's order, and a hierarchy holds one stencil
    per such term whose map the core accepts: a coupling term without one would leave its
    blocks out of the smoother (the core refuses such a hierarchy)."""
    from softbody.solvers.multigrid import STENCILS

    coupled = [t["name"] for t in _core.term_table() if t["stencil_width"] > 0]
    assert list(STENCILS) == coupled
    model = ball_model(subdivisions=2)
    mg = build_multigrid(model)
    assert list(mg.stencils) == coupled
    assert _core.ImplicitSolver(core_model(model), multigrid=mg).uses_multigrid
