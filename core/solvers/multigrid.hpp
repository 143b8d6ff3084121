// The V-cycle of the implicit schemes' multigrid preconditioner (softbody.solvers.
// multigrid): Gauss-Seidel on the isotropic spring-Laplacian levels A_l = M + h C + h^2 K
// (three right-hand sides at once), restriction by P^T, prolongation by P, and a dense
// Cholesky solve (or Gauss-Seidel when coarsening stalled) on the coarsest level. Python
// builds the hierarchy and sets its values for the step; bindings/implicit.cpp checks its offsets and
// indices, so every read here is in bounds.
#pragma once

#include "model.hpp"

namespace softbody::SOFTBODY_KERNELS::multigrid {

/// One Gauss-Seidel sweep (forward or backward) on A_l x_l = b_l, in place.
inline void gauss_seidel(const MultigridView& mg, index lv, bool forward) {
    const index r0 = mg.a_row_offset[lv], z0 = mg.a_nz_offset[lv], v0 = mg.vec_offset[lv];
    const index n = mg.level_size[lv];
    double* x = mg.x;
    const double* b = mg.b;
    for (index step = 0; step < n; ++step) {
        const index i = forward ? step : n - 1 - step;
        double s0 = b[3 * (v0 + i)], s1 = b[3 * (v0 + i) + 1], s2 = b[3 * (v0 + i) + 2];
        for (index e = mg.a_indptr[r0 + i]; e < mg.a_indptr[r0 + i + 1]; ++e) {
            const index col = mg.a_indices[z0 + e];
            if (col != i) {
                const double a = mg.a_data[z0 + e];
                s0 -= a * x[3 * (v0 + col)];
                s1 -= a * x[3 * (v0 + col) + 1];
                s2 -= a * x[3 * (v0 + col) + 2];
            }
        }
        const double inv = 1.0 / mg.a_diag[v0 + i];
        x[3 * (v0 + i)] = s0 * inv;
        x[3 * (v0 + i) + 1] = s1 * inv;
        x[3 * (v0 + i) + 2] = s2 * inv;
    }
}

/// b_{l+1} = P_l^T res for res (n_l, 3).
inline void restrict_to(const MultigridView& mg, index lv, const double* res) {
    const index vc = mg.vec_offset[lv + 1];
    for (index k = 3 * vc; k < 3 * (vc + mg.level_size[lv + 1]); ++k) mg.b[k] = 0.0;
    const index pr0 = mg.p_row_offset[lv], pz0 = mg.p_nz_offset[lv];
    for (index i = 0; i < mg.level_size[lv]; ++i) {
        const double s0 = res[3 * i], s1 = res[3 * i + 1], s2 = res[3 * i + 2];
        for (index e = mg.p_indptr[pr0 + i]; e < mg.p_indptr[pr0 + i + 1]; ++e) {
            const index col = mg.p_indices[pz0 + e];
            const double p = mg.p_data[pz0 + e];
            mg.b[3 * (vc + col)] += p * s0;
            mg.b[3 * (vc + col) + 1] += p * s1;
            mg.b[3 * (vc + col) + 2] += p * s2;
        }
    }
}

/// x_l += P_l x_{l+1}.
inline void prolong(const MultigridView& mg, index lv) {
    const index v0 = mg.vec_offset[lv], vc = mg.vec_offset[lv + 1];
    const index pr0 = mg.p_row_offset[lv], pz0 = mg.p_nz_offset[lv];
    double* x = mg.x;
    for (index i = 0; i < mg.level_size[lv]; ++i)
        for (index e = mg.p_indptr[pr0 + i]; e < mg.p_indptr[pr0 + i + 1]; ++e) {
            const index col = mg.p_indices[pz0 + e];
            const double p = mg.p_data[pz0 + e];
            x[3 * (v0 + i)] += p * x[3 * (vc + col)];
            x[3 * (v0 + i) + 1] += p * x[3 * (vc + col) + 1];
            x[3 * (v0 + i) + 2] += p * x[3 * (vc + col) + 2];
        }
}

/// x_L = A_L^-1 b_L on the coarsest level: L L^T x = b by rows of the Cholesky factor (three
/// right-hand sides at once), or two symmetric Gauss-Seidel sweeps when coarsening stalled.
inline void coarse_solve(const MultigridView& mg) {
    const index last = mg.level_count;
    const index vl = mg.vec_offset[last], nl = mg.level_size[last];
    double* x = mg.x;
    if (mg.coarse_dense) {
        const double* ch = mg.coarse_cholesky;
        for (index i = 0; i < nl; ++i) {  // L y = b
            double s0 = mg.b[3 * (vl + i)], s1 = mg.b[3 * (vl + i) + 1], s2 = mg.b[3 * (vl + i) + 2];
            for (index j = 0; j < i; ++j) {
                const double lij = ch[nl * i + j];
                s0 -= lij * x[3 * (vl + j)];
                s1 -= lij * x[3 * (vl + j) + 1];
                s2 -= lij * x[3 * (vl + j) + 2];
            }
            const double inv = 1.0 / ch[nl * i + i];
            x[3 * (vl + i)] = s0 * inv;
            x[3 * (vl + i) + 1] = s1 * inv;
            x[3 * (vl + i) + 2] = s2 * inv;
        }
        for (index i = nl - 1; i >= 0; --i) {  // L^T x = y, by rows of L
            const double inv = 1.0 / ch[nl * i + i];
            const double x0 = x[3 * (vl + i)] * inv, x1 = x[3 * (vl + i) + 1] * inv,
                         x2 = x[3 * (vl + i) + 2] * inv;
            x[3 * (vl + i)] = x0;
            x[3 * (vl + i) + 1] = x1;
            x[3 * (vl + i) + 2] = x2;
            for (index j = 0; j < i; ++j) {
                const double lij = ch[nl * i + j];
                x[3 * (vl + j)] -= lij * x0;
                x[3 * (vl + j) + 1] -= lij * x1;
                x[3 * (vl + j) + 2] -= lij * x2;
            }
        }
    } else {
        for (index k = 3 * vl; k < 3 * (vl + nl); ++k) x[k] = 0.0;
        for (int sweep = 0; sweep < 2; ++sweep) {
            gauss_seidel(mg, last, true);
            gauss_seidel(mg, last, false);
        }
    }
}

/// V-cycle on levels first..L for A_first x = b_first (b set, x overwritten): a forward
/// sweep from 0 and the residual restricted on the way down, the coarse solve, then
/// prolongation and a backward sweep on the way up (a symmetric operator).
inline void cycle_from(const MultigridView& mg, index first) {
    for (index lv = first; lv < mg.level_count; ++lv) {
        const index r0 = mg.a_row_offset[lv], z0 = mg.a_nz_offset[lv], v0 = mg.vec_offset[lv];
        const index n = mg.level_size[lv];
        for (index k = 3 * v0; k < 3 * (v0 + n); ++k) mg.x[k] = 0.0;
        gauss_seidel(mg, lv, true);
        for (index i = 0; i < n; ++i) {  // r = b - A x
            double s0 = mg.b[3 * (v0 + i)], s1 = mg.b[3 * (v0 + i) + 1], s2 = mg.b[3 * (v0 + i) + 2];
            for (index e = mg.a_indptr[r0 + i]; e < mg.a_indptr[r0 + i + 1]; ++e) {
                const index col = mg.a_indices[z0 + e];
                const double a = mg.a_data[z0 + e];
                s0 -= a * mg.x[3 * (v0 + col)];
                s1 -= a * mg.x[3 * (v0 + col) + 1];
                s2 -= a * mg.x[3 * (v0 + col) + 2];
            }
            mg.r[3 * (v0 + i)] = s0;
            mg.r[3 * (v0 + i) + 1] = s1;
            mg.r[3 * (v0 + i) + 2] = s2;
        }
        restrict_to(mg, lv, mg.r + 3 * v0);
    }
    coarse_solve(mg);
    for (index lv = mg.level_count - 1; lv >= first; --lv) {
        prolong(mg, lv);
        gauss_seidel(mg, lv, false);
    }
}

/// z = V(r) for r, z (N, 3): one V-cycle for A_0 z = r from z = 0.
inline void apply(const MultigridView& mg, const double* r, double* z) {
    const index n3 = 3 * mg.level_size[0];
    for (index k = 0; k < n3; ++k) mg.b[k] = r[k];
    cycle_from(mg, 0);
    for (index k = 0; k < n3; ++k) z[k] = mg.x[k];
}

}  // namespace softbody::SOFTBODY_KERNELS::multigrid
