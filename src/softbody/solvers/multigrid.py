"""Algebraic multigrid preconditioner for the implicit solvers: the hierarchy's set-up
(the V-cycle itself is the core's, core/solvers/multigrid.hpp).

Backward Euler's system matrix is M - dt C - dt^2 K. Its stiff part is the spring network:
with k per spring the largest eigenvalue grows like k N / m, so Jacobi-preconditioned CG
needs about omega_max dt iterations (~300 on a 2,562-vertex ball at 1/60 s). This module
preconditions with the isotropic spring Laplacian instead,

    A = M + dt (L_c + D_c) + dt^2 (L_k + D_k)   (one scalar N x N matrix, times I_3),

where L_k, L_c are the graph Laplacians weighted by the springs' stiffness and damping and
D_k, D_c the attachments' (diagonal). Membrane triangles add their small-strain stiffness
and damping as Laplacians, W_t G_t^T G_t and beta W_t G_t^T G_t with W_t the mean of
the small-strain stiffness over in-plane deformations (``softbody.membrane.scalar_blocks``;
the largest, 2 (G_s + lam_s), needed 20-50% more iterations, a tenth of it more still),
so a membrane-only body coarsens along its triangles; the finest level's smoother holds
their true blocks, diagonal and between neighbours (``membrane_stencil``;
core/terms/membrane.hpp). A bounds every spring's true stiffness block from above
(axial k, transverse k max(0, 1 - L0/L) <= k), so A^-1 captures the stiff part and
CG is left with a spectrum of width about 1/strain, not omega_max dt.

A is constant for a given dt, so its hierarchy is built once per simulator: smoothed
aggregation (Vanek, Mandel & Brezina 1996) on the spring graph, prolongators P smoothed
once with the stiffness Laplacian (omega = 2/3, since rho(D^-1 L) <= 2), Galerkin coarse
matrices P^T A P kept as their mass, damping and stiffness parts so that a new dt only
recombines values. Coarsening stops at ``COARSE_SIZE`` unknowns (a dense Cholesky solve)
or when aggregation stalls (particles without springs; then Gauss-Seidel finishes).
One V-cycle with a forward Gauss-Seidel sweep down and a backward one up is a symmetric
positive-definite operator, as preconditioned CG requires.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from softbody.membrane import scalar_blocks

#: Unknowns at which coarsening stops and the level is solved densely.
COARSE_SIZE = 256
#: Coarsening that keeps more than this fraction of the unknowns has stalled.
STALL_RATIO = 0.85


class Multigrid(NamedTuple):
    """A V-cycle's arrays (L sparse levels and a coarsest one), flat for the core.

    Level l has ``level_size[l]`` unknowns; its matrix A_l is CSR in ``a_indptr`` /
    ``a_indices`` / ``a_data`` at offsets ``a_row_offset[l]`` / ``a_nz_offset[l]``, with
    the parts ``a_mass`` + dt ``a_damping`` + dt^2 ``a_stiffness``; P_l (level l to l + 1)
    likewise in ``p_*``. Vectors of level l live at rows ``vec_offset[l]`` of the
    scratch arrays. ``coarse_cholesky`` (n_L, n_L) is the Cholesky factor of the coarsest
    matrix when ``coarse_dense`` is 1.
    """

    level_count: int
    coarse_dense: int
    level_size: np.ndarray  # (L + 1,) int64
    vec_offset: np.ndarray  # (L + 2,) int64
    a_row_offset: np.ndarray  # (L + 1,) int64, into a_indptr
    a_nz_offset: np.ndarray  # (L + 1,) int64, into a_indices / a_data
    a_indptr: np.ndarray
    a_indices: np.ndarray
    a_data: np.ndarray  # values at the current dt
    a_mass: np.ndarray  # [kg]
    a_damping: np.ndarray  # [N s/m]
    a_stiffness: np.ndarray  # [N/m]
    a_diag: np.ndarray  # (sum n_l,) diagonal of each A_l at the current dt
    p_row_offset: np.ndarray  # (L,) int64
    p_nz_offset: np.ndarray  # (L,) int64
    p_indptr: np.ndarray
    p_indices: np.ndarray
    p_data: np.ndarray
    coarse_cholesky: np.ndarray  # (n_L, n_L)
    block: np.ndarray  # (N, 3, 3) scratch: finest-level diagonal blocks of the true matrix
    block_inv: np.ndarray  # (N, 3, 3) scratch: their inverses
    x: np.ndarray  # (sum n_l, 3) scratch: level solutions
    b: np.ndarray  # (sum n_l, 3) scratch: level right-hand sides
    r: np.ndarray  # (sum n_l, 3) scratch: level residuals
    # the finest level's blocks between particles: each coupling term's Stencil by name
    # (STENCILS), whose coefficients the core fills per step (core/terms/*.hpp)
    stencils: dict

    @property
    def sizes(self) -> list[int]:
        """Unknowns per level, finest first."""
        return [int(n) for n in self.level_size]


class Stencil(NamedTuple):
    """One term's entries in the finest level's smoother: each particle's neighbours as
    CSR sorted by the neighbour (so those to higher-numbered particles are a suffix, which
    the smoother's residual reads alone), and the term's map from its couplings to entries
    (core/terms/NAME.hpp: ``check_stencil`` says what it holds)."""

    ptr: np.ndarray  # (N + 1,) int64
    neighbor: np.ndarray  # (E,) int64
    map: np.ndarray  # int64, flat: the term's own


def spring_stencil(model) -> Stencil:
    """Each particle's springs as entries sorted by the particle at the other end; map:
    each entry's spring (2 S,)."""
    n = model.particle_count
    ends = model.spring_indices.reshape(-1).astype(np.int64)
    order = np.lexsort((ends[np.arange(ends.shape[0]) ^ 1], ends))
    ptr = np.zeros(n + 1, dtype=np.int64)
    ptr[1:] = np.cumsum(np.bincount(ends, minlength=n))
    # the other end: entry 2 s + e of the flattened pairs sits opposite 2 s + 1 - e
    return Stencil(ptr, ends[order ^ 1].astype(np.int64), (order // 2).astype(np.int64))


def membrane_stencil(model) -> Stencil:
    """Each particle's membrane neighbours (particles sharing a membrane triangle), sorted;
    map: the entry of every membrane triangle's ordered corner pair (a, b), (Tm, 3, 3)
    flattened, -1 where a = b (its diagonal block)."""
    n = model.particle_count
    tri = model.membrane_indices.reshape(-1, 3)
    i = np.repeat(tri, 3, axis=1).reshape(-1, 3, 3)  # i[t, a, b] = tri[t, a]
    j = np.repeat(tri[:, None, :], 3, axis=1)  # j[t, a, b] = tri[t, b]
    off = ~np.eye(3, dtype=bool)[None].repeat(len(tri), axis=0)
    keys = i[off] * n + j[off]
    unique, inverse = np.unique(keys, return_inverse=True)
    slot = np.full((len(tri), 3, 3), -1, dtype=np.int64)
    slot[off] = inverse
    ptr = np.zeros(n + 1, dtype=np.int64)
    ptr[1:] = np.cumsum(np.bincount(unique // n, minlength=n))
    return Stencil(ptr, (unique % n).astype(np.int64), slot.reshape(-1))


STENCILS = {
    "springs": spring_stencil,
    "membrane": membrane_stencil,
}
"""Each term that couples particles in the smoother (the core's terms with a
``stencil_width``, ``softbody._core.term_table``; a test holds the two sets equal): its
stencil's builder, ``builder(model) -> Stencil``, by name."""


def empty_multigrid() -> Multigrid:
    """A zero-level placeholder for simulators that do not use the preconditioner."""
    i0, f0 = np.zeros(1, dtype=np.int64), np.zeros(0)
    none = Stencil(np.zeros(1, dtype=np.int64), i0[:0], i0[:0])
    return Multigrid(
        0,
        0,
        np.zeros(1, dtype=np.int64),
        np.zeros(2, dtype=np.int64),
        i0,
        i0,
        i0,
        i0[:0],
        f0,
        f0,
        f0,
        f0,
        f0,
        i0,
        i0,
        i0,
        i0[:0],
        f0,
        np.zeros((0, 0)),
        np.zeros((0, 3, 3)),
        np.zeros((0, 3, 3)),
        np.zeros((0, 3)),
        np.zeros((0, 3)),
        np.zeros((0, 3)),
        dict.fromkeys(STENCILS, none),
    )


def _aggregate(indptr, indices, out):
    """Greedy aggregation of a graph (CSR, no self loops) into ``out`` (n,) aggregate ids;
    returns the aggregate count. Pass 1 takes a node and all its neighbours when none of
    them is taken; pass 2 joins the rest to a neighbouring aggregate; pass 3 groups what
    is left with its free neighbours. Plain Python on lists (planning, once per
    simulator: the whole hierarchy of the ball drop's ball builds in 0.04 s at 10,242
    particles, 0.15 s at 40,962)."""
    ptr, adj = indptr.tolist(), indices.tolist()
    n = len(ptr) - 1
    agg = [-1] * n
    count = 0
    for i in range(n):
        if agg[i] >= 0 or ptr[i + 1] == ptr[i]:
            continue
        row = adj[ptr[i] : ptr[i + 1]]
        if all(agg[j] < 0 for j in row):
            agg[i] = count
            for j in row:
                agg[j] = count
            count += 1
    first_pass = list(agg)
    for i in range(n):
        if agg[i] >= 0:
            continue
        for j in adj[ptr[i] : ptr[i + 1]]:
            if first_pass[j] >= 0:
                agg[i] = first_pass[j]
                break
    for i in range(n):
        if agg[i] >= 0:
            continue
        agg[i] = count
        for j in adj[ptr[i] : ptr[i + 1]]:
            if agg[j] < 0:
                agg[j] = count
        count += 1
    out[:] = agg
    return count


def _laplacian(n: int, i: np.ndarray, j: np.ndarray, weight: np.ndarray) -> sp.csr_matrix:
    off = sp.coo_matrix((np.r_[weight, weight], (np.r_[i, j], np.r_[j, i])), shape=(n, n))
    off = off.tocsr()
    return (sp.diags(np.asarray(off.sum(axis=1)).ravel()) - off).tocsr()


def _union(*matrices: sp.csr_matrix) -> list[sp.csr_matrix]:
    """The matrices on one common sparsity pattern (explicit zeros kept), sorted."""
    pattern = abs(matrices[0])
    for mat in matrices[1:]:
        pattern = pattern + abs(mat)
    pattern = pattern.tocsr()
    pattern.sort_indices()
    n = pattern.shape[1]
    rows = np.repeat(np.arange(pattern.shape[0], dtype=np.int64), np.diff(pattern.indptr))
    keys = rows * n + pattern.indices
    out = []
    for mat in matrices:
        coo = mat.tocoo()
        data = np.zeros(pattern.nnz)
        # exact: each entry lands on its slot of the (sorted) common pattern
        np.add.at(data, np.searchsorted(keys, coo.row.astype(np.int64) * n + coo.col), coo.data)
        out.append(
            sp.csr_matrix((data, pattern.indices.copy(), pattern.indptr.copy()), pattern.shape)
        )
    return out


def build_multigrid(model) -> Multigrid:
    """Smoothed-aggregation hierarchy of the model's spring Laplacian (module docstring).

    model : Model. The result's values are set for a step with :func:`set_multigrid_step`.
    """
    n = model.particle_count
    i, j = model.spring_indices[:, 0], model.spring_indices[:, 1]
    lap_k = _laplacian(n, i, j, model.spring_stiffness)
    lap_c = _laplacian(n, i, j, model.spring_damping)
    att_k, att_c = np.zeros(n), np.zeros(n)
    np.add.at(att_k, model.attachment_particle, model.attachment_stiffness)
    np.add.at(att_c, model.attachment_particle, model.attachment_damping)
    mass = sp.diags(model.particle_mass).tocsr()
    stiff = (lap_k + sp.diags(att_k)).tocsr()
    damp = (lap_c + sp.diags(att_c)).tocsr()
    if model.membrane_count:  # membranes as Laplacians of their small-strain stiffness
        rows, cols, k_m, c_m = scalar_blocks(model, mean=True)
        stiff = (stiff + sp.csr_matrix((k_m, (rows, cols)), shape=(n, n))).tocsr()
        damp = (damp + sp.csr_matrix((c_m, (rows, cols)), shape=(n, n))).tocsr()
    levels, prolongators = [], []
    while True:
        mass, damp, stiff = _union(mass, damp, stiff)
        levels.append((mass, damp, stiff))
        size = mass.shape[0]
        if size <= COARSE_SIZE:
            break
        graph = abs(stiff) + abs(damp)
        graph.setdiag(0.0)
        graph.eliminate_zeros()
        graph = graph.tocsr()
        agg = np.empty(size, dtype=np.int64)
        count = _aggregate(graph.indptr.astype(np.int64), graph.indices.astype(np.int64), agg)
        if count > STALL_RATIO * size:
            break
        tentative = sp.csr_matrix((np.ones(size), (np.arange(size), agg)), shape=(size, count))
        diag = stiff.diagonal()
        scale = np.divide(2.0 / 3.0, diag, out=np.zeros(size), where=diag > 0)
        p = (tentative - sp.diags(scale) @ (stiff @ tentative)).tocsr()
        p.eliminate_zeros()
        p.sort_indices()
        prolongators.append(p)
        pt = p.T.tocsr()
        mass, damp, stiff = (pt @ mat @ p for mat in (mass, damp, stiff))
    sizes = np.array([lv[0].shape[0] for lv in levels], dtype=np.int64)
    coarse_dense = int(sizes[-1] <= COARSE_SIZE)
    vec_offset = np.zeros(len(levels) + 1, dtype=np.int64)
    vec_offset[1:] = np.cumsum(sizes)
    a_row = np.zeros(len(levels), dtype=np.int64)
    a_nz = np.zeros(len(levels), dtype=np.int64)
    for lv in range(1, len(levels)):
        a_row[lv] = a_row[lv - 1] + sizes[lv - 1] + 1
        a_nz[lv] = a_nz[lv - 1] + levels[lv - 1][0].nnz
    p_row = np.zeros(max(len(prolongators), 1), dtype=np.int64)
    p_nz = np.zeros(max(len(prolongators), 1), dtype=np.int64)
    for lv in range(1, len(prolongators)):
        p_row[lv] = p_row[lv - 1] + sizes[lv - 1] + 1
        p_nz[lv] = p_nz[lv - 1] + prolongators[lv - 1].nnz

    def cat(arrays, dtype):
        return np.concatenate([np.asarray(a, dtype=dtype) for a in arrays] or [np.zeros(0, dtype)])

    total = int(vec_offset[-1])
    nz = int(sum(lv[0].nnz for lv in levels))
    mg = Multigrid(
        len(prolongators),
        coarse_dense,
        sizes,
        vec_offset,
        a_row,
        a_nz,
        cat([lv[0].indptr for lv in levels], np.int64),
        cat([lv[0].indices for lv in levels], np.int64),
        np.zeros(nz),
        cat([lv[0].data for lv in levels], np.float64),
        cat([lv[1].data for lv in levels], np.float64),
        cat([lv[2].data for lv in levels], np.float64),
        np.zeros(total),
        p_row,
        p_nz,
        cat([p.indptr for p in prolongators], np.int64),
        cat([p.indices for p in prolongators], np.int64),
        cat([p.data for p in prolongators], np.float64),
        np.zeros((int(sizes[-1]), int(sizes[-1])) if coarse_dense else (0, 0)),
        np.zeros((n, 3, 3)),
        np.zeros((n, 3, 3)),
        np.zeros((total, 3)),
        np.zeros((total, 3)),
        np.zeros((total, 3)),
        {name: build(model) for name, build in STENCILS.items()},
    )
    return mg


def set_multigrid_step(mg: Multigrid, dt: float) -> None:
    """Recombine the level matrices for step ``dt`` [s] in place (and refactor the
    coarsest level): A = mass + dt damping + dt^2 stiffness."""
    data = mg.a_data
    np.multiply(mg.a_damping, dt, out=data)
    data += dt * dt * mg.a_stiffness
    data += mg.a_mass
    _diagonals(mg)
    if mg.coarse_dense:
        last = mg.level_count
        n = int(mg.level_size[last])
        r0, z0 = mg.a_row_offset[last], mg.a_nz_offset[last]
        indptr = mg.a_indptr[r0 : r0 + n + 1]
        nnz = int(indptr[-1])
        dense = sp.csr_matrix(
            (mg.a_data[z0 : z0 + nnz], mg.a_indices[z0 : z0 + nnz], indptr), shape=(n, n)
        ).toarray()
        mg.coarse_cholesky[:] = np.linalg.cholesky(0.5 * (dense + dense.T))


def _diagonals(mg):
    """a_diag = the diagonal of each level's A at the current step (each row holds its
    diagonal entry at most once: the levels are canonical CSR)."""
    for lv in range(mg.level_count + 1):
        r0, z0, v0 = mg.a_row_offset[lv], mg.a_nz_offset[lv], mg.vec_offset[lv]
        n = int(mg.level_size[lv])
        indptr = mg.a_indptr[r0 : r0 + n + 1]
        entries = slice(z0 + indptr[0], z0 + indptr[-1])
        rows = np.repeat(np.arange(n), np.diff(indptr))
        on = mg.a_indices[entries] == rows
        mg.a_diag[v0 : v0 + n] = np.bincount(rows[on], weights=mg.a_data[entries][on], minlength=n)
