"""Projective dynamics' set-up: the global matrix, its nested-dissection order and its
factor (the iterations are the core's, core/solvers/projective.hpp).

Projective dynamics is backward Euler by local-global iterations on a prefactored matrix.

Liu, Bargteil, O'Brien & Kavan (2013), "Fast simulation of mass-spring systems", and
Bouaziz et al. (2014), "Projective dynamics". Backward Euler, x1 = x0 + h v1 with
M (v1 - v0) = h f(x1, v1), is the minimum of

    1 / (2 h^2) |x - y|_M^2 + sum_s [k_s / 2 |d_s - p_s|^2 + c_s / (2 h) |d_s - q_s|^2] - (rest),

y = x0 + h v0, d_s = x_j - x_i the spring's edge vector, p_s its projection onto the
sphere of radius L0 (the rest length along d_s) and q_s its projection onto the plane
u . (d - d0) = 0 (u = d_s / |d_s|, d0 the edge at the step's start): the first term is
Hooke's energy 1/2 k (|d| - L0)^2, the second the damper c (u . (v_j - v_i)) u. Each
iteration fixes p, q at the current iterate (the local step) and solves

    (M / h^2 + sum_s (k_s + c_s / h) A_s^T A_s) x
        = M y / h^2 + sum_s A_s^T (k_s p_s + c_s / h q_s) + f

for x (the global step), f being the rest of the forces (gravity, pressure, external and
grab forces) at the iterate. The matrix is the same at every step and for x, y and z,
so it is factored once (LDL^T, by SuperLU in a nested-dissection order) and each
iteration costs two triangular solves (``dissection_order``, supernodes). Attachments
add k + c / h to their particle's diagonal; pinned particles (zero inverse mass) move
with their set velocity, their rows replaced by the identity and their springs' pull
moved to the right-hand side.

A fixed point is exactly backward Euler with this library's forces: the spring and
damper terms above then equal f_spring(x1, v1) with v1 = (x1 - x0) / h (tested). With
few iterations the stiff, local motion is resolved and the slow, global motion lags: the
ball bounces lower and settles more softly than under converged backward Euler; more
iterations converge to it. The springs are implicit whatever the step; the pressure and
the other forces are explicit within each iteration, which limits the step to about
1 / omega_gas, the gas's volume mode (``ProjectiveSolver.step_limit``).

Membranes (``core/terms/membrane.hpp``) join by a quasi-Newton splitting rather than a
projection: the matrix holds W_t G_t^T G_t per membrane triangle (G_t the map from its
corners to its deformation gradient, a scalar 3 x 3 block g_a . g_b per coordinate;
W_t = 3 A0 H 2 (G_s + lam_s) (1 + beta / h): three times the bound on the triangle's
small-strain stiffness and damping, since a stretched sheet stiffens:
``softbody.membrane.PROJECTIVE_MARGIN``), and each iteration's right-hand side adds
W_t G_t^T G_t x + f_membrane(x, (x - x0) / h) at the iterate. A fixed point is again
backward Euler with the true material (any membrane model, not an as-rigid-as-possible
stand-in), and the iteration contracts while the material's tangent stays below W_t.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from softbody import _core


class Projective(NamedTuple):
    """The factored matrix of projective dynamics for one model and step.

    A = P^T L D L^T P: ``perm[r]`` is the particle at row r of the factor; ``inv_diag`` =
    1 / diag(D). L (unit lower triangular) is stored by supernodes, runs of columns
    c0..c1 - 1 (``node_col[s]``, ``node_col[s + 1]``) whose rows below the diagonal are
    the same: node s's rows are ``node_row[node_row_ptr[s]:node_row_ptr[s + 1]]`` (its
    own columns first, then the rows below), and its values a dense row-major block of
    (rows, c1 - c0) at ``node_value[node_value_ptr[s]:]`` (upper triangle of the square
    part unused). The wide supernodes of the separators hold most of the factor, so the
    solves run mostly over dense, contiguous rows.
    """

    size: int
    dt: float  # [s] the step the matrix was built for
    perm: np.ndarray  # (N,) int64
    inv_diag: np.ndarray  # (N,) float64
    node_col: np.ndarray  # (S + 1,) int64
    node_row_ptr: np.ndarray  # (S + 1,) int64
    node_row: np.ndarray  # (R,) int64
    node_value_ptr: np.ndarray  # (S + 1,) int64
    node_value: np.ndarray  # (V,) float64
    nonzeros: int  # entries of L below the diagonal

    @property
    def factor_nonzeros(self) -> int:
        """Entries of L below the diagonal."""
        return self.nonzeros


def _spring_part(model, dt: float, free: np.ndarray, diag: np.ndarray):
    """The springs' (k + c / dt) A_s^T A_s: their weights added into diag (N,) at free
    ends, and their off-diagonal entries (rows, cols, values) between free ends."""
    i, j = model.spring_indices[:, 0], model.spring_indices[:, 1]
    wgt = model.spring_stiffness + model.spring_damping / dt
    both = free[i] & free[j]
    np.add.at(diag, i[free[i]], wgt[free[i]])
    np.add.at(diag, j[free[j]], wgt[free[j]])
    return (np.concatenate([i[both], j[both]]), np.concatenate([j[both], i[both]]),
            np.concatenate([-wgt[both], -wgt[both]]))  # fmt: skip


def _attachment_part(model, dt: float, free: np.ndarray, diag: np.ndarray):
    """The attachments' k + c / dt on their free particles' diagonal; no other entry."""
    a = model.attachment_particle
    att = model.attachment_stiffness + model.attachment_damping / dt
    np.add.at(diag, a[free[a]], att[free[a]])
    return _NO_ENTRIES


def _membrane_part(model, dt: float, free: np.ndarray, diag: np.ndarray):
    """The membranes' W_t (1 + beta / dt) g_a . g_b entries (rows, cols, values) between
    free corners (module docstring; core/terms/membrane.hpp: projective_weight)."""
    if not model.membrane_count:
        return _NO_ENTRIES
    from softbody.membrane import scalar_blocks

    rows, cols, stiffness, damping = scalar_blocks(model, projective=True)
    keep = free[rows] & free[cols]
    return rows[keep], cols[keep], (stiffness + damping / dt)[keep]


_NO_ENTRIES = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0))

MATRIX_PARTS = {
    "springs": _spring_part,
    "attachments": _attachment_part,
    "membrane": _membrane_part,
}
"""Each projected term's part of the global matrix (the core's terms with the trait
``projected``, ``softbody._core.term_table``; a test holds the two sets equal), by name in
the registry's order: ``part(model, dt, free, diag)`` adds its diagonal into ``diag`` (N,)
and returns its other entries (rows, cols, values) [kg/s^2] between free particles."""


def system_matrix(model, dt: float) -> sp.csc_matrix:
    """The global step's matrix M / dt^2 + every projected term's part
    (:data:`MATRIX_PARTS`: sum_s (k + c / dt) A_s^T A_s, attachments' (k + c / dt) on their
    diagonal, the membranes' weights), with pinned particles' rows and columns replaced by
    the identity; (N, N) CSC [kg/s^2]."""
    n = model.particle_count
    free = model.particle_inv_mass > 0.0
    diag = np.where(free, model.particle_mass / dt**2, 1.0)
    parts = [part(model, dt, free, diag) for part in MATRIX_PARTS.values()]
    # the diagonal after the first part's entries (the order scipy sums duplicates in)
    entries = [parts[0], (np.arange(n), np.arange(n), diag), *parts[1:]]
    rows, cols, values = (np.concatenate(x) for x in zip(*entries, strict=True))
    return sp.csc_matrix((values, (rows, cols)), shape=(n, n))


def build_projective(model, dt: float) -> Projective:
    """Factor the global matrix (:func:`system_matrix`) of ``model`` for step ``dt`` [s].

    The matrix is symmetric positive definite (mass on every free diagonal, springs and
    attachments adding Laplacian terms), so an LU factorisation without pivoting in a
    symmetric order is L D L^T: L from SuperLU, D its U's diagonal.
    """
    dt = float(dt)
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0 seconds, got {dt!r}")
    n = model.particle_count
    matrix = system_matrix(model, dt)
    order = dissection_order(matrix.tocsr(), model.particle_q)
    a = matrix[order][:, order].tocsc()
    lu = spla.splu(
        a,
        permc_spec="NATURAL",
        diag_pivot_thresh=0.0,
        options={"SymmetricMode": True},
    )
    d = lu.U.diagonal()
    if not np.array_equal(lu.perm_r, lu.perm_c) or not (np.all(np.isfinite(d)) and d.min() > 0):
        raise ValueError(
            "projective dynamics: the global matrix is not positive definite "
            "(a free particle without mass?)"
        )
    factor = lu.L
    # the strictly lower part with sorted rows (SuperLU's come unsorted), then its
    # supernodes: both compiled, as sp.tril and a CSC conversion took 0.8 s at 163,842
    indptr, indices, data = _core.plan_strict_lower(
        factor.indptr.astype(np.int64),
        factor.indices.astype(np.int64),
        np.ascontiguousarray(factor.data, dtype=np.float64),
    )
    perm = np.empty(n, dtype=np.int64)
    perm[lu.perm_r] = order
    col, row_ptr, rows, value_ptr, values = _core.plan_supernodes(indptr, indices, data)
    return Projective(
        n,
        dt,
        perm,
        1.0 / d,
        col,
        row_ptr,
        rows,
        value_ptr,
        values,
        len(indices),
    )


#: Nested dissection stops splitting a set of particles at this size.
DISSECTION_LEAF = 8


def dissection_order(a: sp.csr_matrix, points: np.ndarray) -> np.ndarray:
    """Nested-dissection order of the particles for a sparse (N, N) matrix ``a`` whose
    pattern is the springs', from their positions ``points`` (N, 3) [m].

    A set is cut at the median of its widest coordinate; the particles of the lower half
    joined to the upper half by a spring form the separator, ordered after both halves,
    which are ordered the same way first (George 1973). On the ball drop's 40,962-vertex
    ball it leaves 22% fewer entries in the factor than SuperLU's minimum degree (1.92 M
    against 2.46 M) and the solve took 9-10 ms instead of 10.4-10.7. Compiled (the
    core's ``plan_dissection_order``, a stack of segments of one buffer split in place,
    stably): 0.02 s at 40,962 particles, where a recursion over SciPy submatrices took
    1.3 s (6.0 s at 163,842), the same order.
    Returns ``order`` (N,): the particle at each position.
    """
    pattern = (a != 0).tocsr()
    pattern.sort_indices()
    return _core.plan_dissection_order(
        pattern.indptr.astype(np.int64),
        pattern.indices.astype(np.int64),
        np.ascontiguousarray(points, dtype=np.float64),
        DISSECTION_LEAF,
    )
