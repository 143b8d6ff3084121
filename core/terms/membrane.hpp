// Constant-strain triangle membranes: thin sheets of a hyperelastic material in plane stress
// (rubber, fabric, film), one element per membrane triangle.
//
// Each triangle (x0, x1, x2) has the deformation gradient F = [x1 - x0, x2 - x0] Dm^-1
// (3 x 2; Dm the rest edge matrix in a 2D frame of the rest triangle, its inverse
// precomputed), the in-plane right Cauchy-Green tensor C = F^T F (2 x 2) and the energy
//     E_t = A0 H W(C)                                                           [J]
// with A0 the rest area, H the rest thickness and W an energy per unit rest volume [Pa]:
//     neo-Hookean (incompressible)     W = mu / 2 (I1 - 3)
//     Mooney-Rivlin (incompressible)   W = c10 (I1 - 3) + c01 (I2 - 3)
//     St Venant-Kirchhoff (plane stress)
//                                      W = E / (2 (1 - nu^2)) [(1 - nu) tr(G^2) + nu (tr G)^2]
// where I1 = tr C + 1 / det C, I2 = det C + tr C / det C (the thickness stretch is
// 1 / sqrt(det C)) and G = (C - I) / 2 the Green strain. (The StVK formula, per unit
// area with H in it, is this W times H.) The first Piola stress P = 2 F dW/dC gives the
// forces f_a = -A0 H P g_a, g_1, g_2 the rows of Dm^-1 and g_0 = -(g_1 + g_2) (so that
// F = sum_a x_a g_a^T).
//
// Damping (optional, per triangle): a Kelvin-Voigt viscous stress, Rayleigh-style: the
// material's small-strain plane-stress stiffness (shear modulus G_s, Lame constant lam_s:
// neo-Hookean G_s = mu, lam_s = 2 mu; Mooney-Rivlin mu = 2 (c10 + c01) likewise; StVK
// G_s = E / (2 (1 + nu)), lam_s = E nu / (1 - nu^2)) times a time beta [s] acting on the
// Green strain rate Gdot = sym(F^T Fdot):
//     S_v = beta (2 G_s Gdot + lam_s tr(Gdot) I),   P_v = F S_v.
// It is the force of the dissipation potential A0 H beta / 2 Gdot : C0 : Gdot (C0 the
// small-strain tangent), so it dissipates at every state, is linear in the velocities, and
// leaves rigid motion (Gdot = 0) undamped; near rest it is beta times the elastic stiffness.
//
// Linearisation: with vec(F) (6,) = [F col 0; F col 1], the Hessian of E_t in x is
// G_t^T H_F G_t with H_F = A0 H d2W/dF2 (6 x 6) and G_t the constant map x_t -> vec(F).
// The implicit solvers' K uses H_F with its negative eigenvalues clamped to 0 (a 6 x 6
// Jacobi eigensolve per triangle, skipped where a Cholesky factorisation shows H_F
// positive definite, as in a stretched sheet), so -K = G^T H_F+ G is positive
// semi-definite; the damping C = -G^T D_F G, D_F = A0 H beta L^T C0 L (L: Fdot -> Gdot),
// is so already.
//
// Forms: force and energy (edge-major, per triangle), the lane form (lane_triangle: the
// vertex-major pass computes each triangle at its three corners, fused with the ring of
// neighbour rows it walks, so that no force is scattered; with it a model with membranes
// keeps the fused symplectic pass), prepare + jacobian_product (the 6 x 6 blocks per triangle
// stored in its linearisation (Linearization::own), or computed on the fly where that is null),
// add_smoother_blocks (the triangle's 3 x 3 blocks of M - h C - h^2 K: its corners'
// diagonal blocks, and the blocks between corners as the smoother's membrane entries;
// the coarse levels see the membrane as a Laplacian: softbody.solvers.multigrid), project
// (projective dynamics: a quasi-Newton splitting, the factor holding w A0 H G^T G per
// triangle with w = 3 x 2 (G_s + lam_s) (1 + beta / h), the right-hand side w A0 H G^T G x +
// f(x) at the iterate, so a fixed point is backward Euler with the true material), and
// the stable step's Gershgorin rows (bound_rows).
#pragma once

#include <algorithm>
#include <cmath>

#include "model.hpp"
#include "simd.hpp"
#include "terms/term.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::membrane {

/// Entries of a symmetric 6 x 6 block stored as its upper triangle, row by row.
constexpr int kSym6 = 21;
/// Per triangle in its linearisation (Linearization::own): the clamped stiffness H_F+ then D_F.
constexpr int kBlock = 2 * kSym6;
static_assert(kBlock == kMembraneBlock, "model.hpp's kMembraneBlock");

/// A symmetric 2 x 2 matrix [[a, b], [b, c]].
struct S2 {
    double a, b, c;
};
inline S2 operator+(S2 x, S2 y) { return {x.a + y.a, x.b + y.b, x.c + y.c}; }
inline S2 operator*(double s, S2 x) { return {s * x.a, s * x.b, s * x.c}; }
inline double trace(S2 x) { return x.a + x.c; }
inline double det(S2 x) { return x.a * x.c - x.b * x.b; }
inline S2 adj(S2 x) { return {x.c, -x.b, x.a}; }  // det(x) x^-1, linear in x
inline S2 identity2() { return {1.0, 0.0, 1.0}; }

/// One triangle's kinematics: its corners, F's columns and the gradient vectors g_a (2,).
struct Element {
    index v[3];
    V3 f0, f1;       // F = [f0 f1]
    double g[3][2];  // F = sum_a x_a g_a^T
};

inline Element element(const Model& m, const double* q, index t) {
    Element e;
    for (int a = 0; a < 3; ++a) e.v[a] = m.membranes.indices[3 * t + a];
    const double* bm = m.membranes.rest_inverse + 4 * t;  // row-major Dm^-1
    e.g[1][0] = bm[0], e.g[1][1] = bm[1];
    e.g[2][0] = bm[2], e.g[2][1] = bm[3];
    e.g[0][0] = -(bm[0] + bm[2]), e.g[0][1] = -(bm[1] + bm[3]);
    const V3 x0 = load(q, e.v[0]);
    const V3 d1 = load(q, e.v[1]) - x0, d2 = load(q, e.v[2]) - x0;
    e.f0 = bm[0] * d1 + bm[2] * d2;
    e.f1 = bm[1] * d1 + bm[3] * d2;
    return e;
}

/// Triangle t's corners and gradient vectors without F (what the matrix-free product needs).
inline Element corners(const Model& m, index t) {
    Element e;
    for (int a = 0; a < 3; ++a) e.v[a] = m.membranes.indices[3 * t + a];
    const double* bm = m.membranes.rest_inverse + 4 * t;  // row-major Dm^-1
    e.g[1][0] = bm[0], e.g[1][1] = bm[1];
    e.g[2][0] = bm[2], e.g[2][1] = bm[3];
    e.g[0][0] = -(bm[0] + bm[2]), e.g[0][1] = -(bm[1] + bm[3]);
    e.f0 = e.f1 = {0.0, 0.0, 0.0};
    return e;
}

/// Fdot's columns for velocities qd (N, 3) (the same map as F).
inline void rate(const Element& e, const double* qd, V3& r0, V3& r1) {
    r0 = {0.0, 0.0, 0.0};
    r1 = {0.0, 0.0, 0.0};
    for (int a = 0; a < 3; ++a) {
        const V3 v = load(qd, e.v[a]);
        r0 = r0 + e.g[a][0] * v;
        r1 = r1 + e.g[a][1] * v;
    }
}

inline S2 gram(V3 f0, V3 f1) { return {dot(f0, f0), dot(f0, f1), dot(f1, f1)}; }

/// The small-strain plane-stress moduli (G_s, lam_s) [Pa] of triangle t's material.
inline void small_strain(const Model& m, index t, double& shear, double& lame) {
    const double p0 = m.membranes.params[2 * t], p1 = m.membranes.params[2 * t + 1];
    switch (m.membranes.material[t]) {
        case MembraneMaterial::NEO_HOOKEAN:
            shear = p0, lame = 2.0 * p0;
            break;
        case MembraneMaterial::MOONEY_RIVLIN:
            shear = 2.0 * (p0 + p1), lame = 4.0 * (p0 + p1);
            break;
        default:  // StVK: E, nu
            shear = p0 / (2.0 * (1.0 + p1)), lame = p0 * p1 / (1.0 - p1 * p1);
            break;
    }
}

/// W(C) [Pa] of triangle t's material at C; det C <= 0 (a collapsed triangle) gives +inf
/// for the incompressible materials.
inline double density(const Model& m, index t, S2 cg) {
    const double p0 = m.membranes.params[2 * t], p1 = m.membranes.params[2 * t + 1];
    const double tr = trace(cg), j = det(cg);
    switch (m.membranes.material[t]) {
        case MembraneMaterial::NEO_HOOKEAN:
            if (!(j > 0.0)) return INFINITY;
            return 0.5 * p0 * (tr + 1.0 / j - 3.0);
        case MembraneMaterial::MOONEY_RIVLIN:
            if (!(j > 0.0)) return INFINITY;
            return p0 * (tr + 1.0 / j - 3.0) + p1 * (j + tr / j - 3.0);
        default: {
            const S2 g = 0.5 * (cg + (-1.0) * identity2());
            const double k = p0 / (2.0 * (1.0 - p1 * p1));
            const double tr_g = trace(g);
            const double tr_g2 = g.a * g.a + 2.0 * g.b * g.b + g.c * g.c;
            return k * ((1.0 - p1) * tr_g2 + p1 * tr_g * tr_g);
        }
    }
}

/// dW/dC (symmetric 2 x 2) [Pa] of triangle t's material at C.
inline S2 stress(const Model& m, index t, S2 cg) {
    const double p0 = m.membranes.params[2 * t], p1 = m.membranes.params[2 * t + 1];
    const double tr = trace(cg), j = det(cg);
    const S2 ad = adj(cg), id = identity2();
    switch (m.membranes.material[t]) {
        case MembraneMaterial::NEO_HOOKEAN:  // mu / 2 (I - C^-1 / J)
            return 0.5 * p0 * (id + (-1.0 / (j * j)) * ad);
        case MembraneMaterial::MOONEY_RIVLIN:  // + c01 (J C^-1 + I / J - tr C C^-1 / J)
            return p0 * (id + (-1.0 / (j * j)) * ad) +
                   p1 * (ad + (1.0 / j) * id + (-tr / (j * j)) * ad);
        default: {
            const S2 g = 0.5 * (cg + (-1.0) * id);
            const double k = p0 / (2.0 * (1.0 - p1 * p1));
            return k * ((1.0 - p1) * g + (p1 * trace(g)) * id);
        }
    }
}

/// The derivative of dW/dC along dC at C (symmetric 2 x 2) [Pa].
inline S2 stress_derivative(const Model& m, index t, S2 cg, S2 dc) {
    const double p0 = m.membranes.params[2 * t], p1 = m.membranes.params[2 * t + 1];
    const double tr = trace(cg), j = det(cg);
    const S2 ad = adj(cg), dad = adj(dc), id = identity2();
    const double dj = cg.c * dc.a + cg.a * dc.c - 2.0 * cg.b * dc.b;  // dJ
    // d(adj / J^2) = adj(dC) / J^2 - 2 dJ adj / J^3
    const S2 d_inv = (1.0 / (j * j)) * dad + (-2.0 * dj / (j * j * j)) * ad;
    switch (m.membranes.material[t]) {
        case MembraneMaterial::NEO_HOOKEAN:
            return (-0.5 * p0) * d_inv;
        case MembraneMaterial::MOONEY_RIVLIN:
            return (-p0) * d_inv +
                   p1 * (dad + (-dj / (j * j)) * id + (-trace(dc) / (j * j)) * ad +
                         (-tr) * d_inv);
        default: {
            const double k = p0 / (2.0 * (1.0 - p1 * p1));
            return k * ((0.5 * (1.0 - p1)) * dc + (0.5 * p1 * trace(dc)) * id);
        }
    }
}

/// dC for the unit change of F's entry (row r, column c): dF^T F + F^T dF.
inline S2 unit_dc(V3 f0, V3 f1, int r, int c) {
    const double fr0 = (&f0.x)[r], fr1 = (&f1.x)[r];
    return c == 0 ? S2{2.0 * fr0, fr1, 0.0} : S2{0.0, fr0, 2.0 * fr1};
}

/// P = 2 F S for a symmetric S: its columns.
inline void times_f(V3 f0, V3 f1, S2 s, V3& p0, V3& p1) {
    p0 = (2.0 * s.a) * f0 + (2.0 * s.b) * f1;
    p1 = (2.0 * s.b) * f0 + (2.0 * s.c) * f1;
}

/// The viscous stress S_v / 2 (so that P_v = 2 F (S_v / 2)) for Gdot = dc / 2.
inline S2 viscous_half(double beta, double shear, double lame, S2 dc) {
    const S2 gdot = 0.5 * dc;
    return (0.5 * beta) * ((2.0 * shear) * gdot + (lame * trace(gdot)) * identity2());
}

/// Index of entry (i, j) of a symmetric 6 x 6 block stored by upper rows.
inline int sym_index(int i, int j) {
    if (i > j) std::swap(i, j);
    return i * 6 - i * (i - 1) / 2 + (j - i);
}

/// The symmetric eigen decomposition of a (6 x 6, row-major, overwritten by its
/// eigenvalues on the diagonal) into vectors v (columns), by cyclic Jacobi rotations.
inline void eigen6(double a[36], double v[36]) {
    for (int i = 0; i < 36; ++i) v[i] = (i % 7 == 0) ? 1.0 : 0.0;
    for (int sweep = 0; sweep < 30; ++sweep) {
        double off = 0.0, diag = 0.0;
        for (int i = 0; i < 6; ++i) {
            diag += a[7 * i] * a[7 * i];
            for (int j = i + 1; j < 6; ++j) off += a[6 * i + j] * a[6 * i + j];
        }
        if (!(off > 1e-30 * diag)) break;  // converged (or not finite)
        for (int p = 0; p < 6; ++p)
            for (int r = p + 1; r < 6; ++r) {
                const double apr = a[6 * p + r];
                if (apr == 0.0) continue;
                const double theta = (a[6 * r + r] - a[6 * p + p]) / (2.0 * apr);
                const double tt = (theta >= 0.0 ? 1.0 : -1.0) /
                                  (std::abs(theta) + std::sqrt(theta * theta + 1.0));
                const double c = 1.0 / std::sqrt(tt * tt + 1.0), s = tt * c;
                for (int k = 0; k < 6; ++k) {  // columns p, r
                    const double akp = a[6 * k + p], akr = a[6 * k + r];
                    a[6 * k + p] = c * akp - s * akr;
                    a[6 * k + r] = s * akp + c * akr;
                }
                for (int k = 0; k < 6; ++k) {  // rows p, r
                    const double apk = a[6 * p + k], ark = a[6 * r + k];
                    a[6 * p + k] = c * apk - s * ark;
                    a[6 * r + k] = s * apk + c * ark;
                }
                for (int k = 0; k < 6; ++k) {
                    const double vkp = v[6 * k + p], vkr = v[6 * k + r];
                    v[6 * k + p] = c * vkp - s * vkr;
                    v[6 * k + r] = s * vkp + c * vkr;
                }
            }
    }
}

/// Triangle t's d2W/dF2 times A0 H (6 x 6 row-major, vec(F) = [col 0; col 1]) into hf,
/// and with `damping` its D_F into hd.
inline void f_hessians(const Model& m, index t, const Element& e, double hf[36], double* hd) {
    const S2 cg = gram(e.f0, e.f1);
    const S2 s = stress(m, t, cg);
    const double scale = m.membranes.rest_area[t] * m.membranes.thickness[t];
    double shear = 0.0, lame = 0.0;
    const double beta = m.membranes.damping[t];
    if (hd != nullptr) small_strain(m, t, shear, lame);
    for (int c = 0; c < 2; ++c)
        for (int r = 0; r < 3; ++r) {
            const int col = 3 * c + r;
            const S2 dc = unit_dc(e.f0, e.f1, r, c);
            V3 d0, d1;  // dP = 2 dF S + 2 F dS
            times_f(e.f0, e.f1, stress_derivative(m, t, cg, dc), d0, d1);
            const double sr[2] = {c == 0 ? s.a : s.b, c == 0 ? s.b : s.c};  // row c of S
            (&d0.x)[r] += 2.0 * sr[0];
            (&d1.x)[r] += 2.0 * sr[1];
            for (int k = 0; k < 3; ++k) {
                hf[6 * k + col] = scale * (&d0.x)[k];
                hf[6 * (3 + k) + col] = scale * (&d1.x)[k];
            }
            if (hd != nullptr) {
                V3 v0, v1;
                times_f(e.f0, e.f1, viscous_half(beta, shear, lame, dc), v0, v1);
                for (int k = 0; k < 3; ++k) {
                    hd[6 * k + col] = scale * (&v0.x)[k];
                    hd[6 * (3 + k) + col] = scale * (&v1.x)[k];
                }
            }
        }
    for (int i = 0; i < 6; ++i)  // symmetric up to round-off: make it exactly so
        for (int j = i + 1; j < 6; ++j) {
            const double avg = 0.5 * (hf[6 * i + j] + hf[6 * j + i]);
            hf[6 * i + j] = hf[6 * j + i] = avg;
            if (hd != nullptr) {
                const double d = 0.5 * (hd[6 * i + j] + hd[6 * j + i]);
                hd[6 * i + j] = hd[6 * j + i] = d;
            }
        }
}

/// Whether a symmetric 6 x 6 (row-major) is positive definite: its Cholesky factorisation
/// runs with positive pivots (about 70 flops, against thousands for the eigensolve).
inline bool positive_definite(const double h[36]) {
    double l[36];
    for (int j = 0; j < 6; ++j) {
        double d = h[7 * j];
        for (int k = 0; k < j; ++k) d -= l[6 * j + k] * l[6 * j + k];
        if (!(d > 0.0)) return false;
        const double root = std::sqrt(d);
        l[7 * j] = root;
        for (int i = j + 1; i < 6; ++i) {
            double s = h[6 * i + j];
            for (int k = 0; k < j; ++k) s -= l[6 * i + k] * l[6 * j + k];
            l[6 * i + j] = s / root;
        }
    }
    return true;
}

inline void pack(const double h[36], double* out);

/// hf (6 x 6) with its negative eigenvalues set to 0, packed into out (kSym6,): hf itself
/// where it is positive definite (a stretched triangle), else by the eigensolve.
inline void clamp_pack(double hf[36], double* out) {
    if (positive_definite(hf)) {
        pack(hf, out);
        return;
    }
    double v[36];
    eigen6(hf, v);
    double lam[6];
    for (int k = 0; k < 6; ++k) lam[k] = std::max(0.0, hf[7 * k]);
    for (int i = 0; i < 6; ++i)
        for (int j = i; j < 6; ++j) {
            double s = 0.0;
            for (int k = 0; k < 6; ++k) s += v[6 * i + k] * lam[k] * v[6 * j + k];
            out[sym_index(i, j)] = s;
        }
}

inline void pack(const double h[36], double* out) {
    for (int i = 0; i < 6; ++i)
        for (int j = i; j < 6; ++j) out[sym_index(i, j)] = h[6 * i + j];
}

/// Triangle t's blocks at q (kBlock,): the clamped stiffness H_F+, then D_F.
inline void blocks(const Model& m, const double* q, index t, double* out) {
    const Element e = element(m, q, t);
    double hf[36], hd[36];
    f_hessians(m, t, e, hf, hd);
    clamp_pack(hf, out);
    pack(hd, out + kSym6);
}

/// Every triangle's blocks at q into h (Tm, kBlock).
inline void prepare(const Model& m, const double* q, double* h) {
    for (index t = 0; t < m.membranes.count; ++t) blocks(m, q, t, h + kBlock * t);
}

/// Every membrane triangle's elastic and viscous force, added to f (N, 3) [N].
inline void force(const Model& m, const double* q, const double* qd, double* f) {
    for (index t = 0; t < m.membranes.count; ++t) {
        const Element e = element(m, q, t);
        const S2 cg = gram(e.f0, e.f1);
        S2 s = stress(m, t, cg);
        const double beta = m.membranes.damping[t];
        if (beta > 0.0) {
            V3 r0, r1;
            rate(e, qd, r0, r1);
            double shear, lame;
            small_strain(m, t, shear, lame);
            // dC/dt = Fdot^T F + F^T Fdot
            const S2 dc = {2.0 * dot(r0, e.f0), dot(r0, e.f1) + dot(e.f0, r1), 2.0 * dot(r1, e.f1)};
            s = s + viscous_half(beta, shear, lame, dc);
        }
        V3 p0, p1;
        times_f(e.f0, e.f1, s, p0, p1);
        const double scale = -m.membranes.rest_area[t] * m.membranes.thickness[t];
        for (int a = 0; a < 3; ++a)
            add_to(f, e.v[a], scale * (e.g[a][0] * p0 + e.g[a][1] * p1));
    }
}

/// Elastic energy A0 H W(C) [J] of every membrane triangle at q, each added to its body's
/// entry of body_energy (B,); returns the total [J].
inline double energies(const Model& m, const double* q, double* body_energy) {
    double total = 0.0;
    for (index t = 0; t < m.membranes.count; ++t) {
        const Element e = element(m, q, t);
        const double w = m.membranes.rest_area[t] * m.membranes.thickness[t] *
                         density(m, t, gram(e.f0, e.f1));
        total += w;
        if (m.membranes.body[t] >= 0) body_energy[m.membranes.body[t]] += w;
    }
    return total;
}

/// y (6,) = B x (6,) for a symmetric block packed by upper rows.
inline void sym_apply(const double* b, const double x[6], double y[6]) {
    for (int i = 0; i < 6; ++i) {
        double s = 0.0;
        for (int j = 0; j < 6; ++j) s += b[sym_index(i, j)] * x[j];
        y[i] = s;
    }
}

/// out -= G^T B G p for a triangle's gradient vectors, B a packed block times `scale`.
inline void apply_block(const Element& e, const double* b, double scale, const double* p,
                        double* out) {
    double x[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0}, y[6];
    for (int a = 0; a < 3; ++a) {
        const V3 pa = load(p, e.v[a]);
        for (int k = 0; k < 3; ++k) {
            x[k] += e.g[a][0] * (&pa.x)[k];
            x[3 + k] += e.g[a][1] * (&pa.x)[k];
        }
    }
    sym_apply(b, x, y);
    for (int a = 0; a < 3; ++a) {
        const V3 w = {e.g[a][0] * y[0] + e.g[a][1] * y[3], e.g[a][0] * y[1] + e.g[a][1] * y[4],
                      e.g[a][0] * y[2] + e.g[a][1] * y[5]};
        add_to(out, e.v[a], -scale * w);
    }
}

/// out (N, 3) += alpha_c C p + alpha_k K p, K = -G^T H_F+ G and C = -G^T D_F G per
/// triangle, from the blocks h (Tm, kBlock) of prepare, or (h null) computed at q.
inline void jacobian_product(const Model& m, const double* q, const double* h, double alpha_c,
                             double alpha_k, const double* p, double* out) {
    double local[kBlock];
    for (index t = 0; t < m.membranes.count; ++t) {
        const Element e = corners(m, t);  // F is in the blocks
        const double* b = h != nullptr ? h + kBlock * t : local;
        if (h == nullptr) blocks(m, q, t, local);
        double mix[kSym6];
        for (int k = 0; k < kSym6; ++k) mix[k] = alpha_k * b[k] + alpha_c * b[kSym6 + k];
        apply_block(e, mix, 1.0, p, out);
    }
}

/// The membrane's share of the smoother's matrix M - h C - h^2 K: per triangle and corner
/// pair (a, b) the block sum over columns c, d of g_a,c g_b,d (h D_F + h^2 H_F+)[(., c),
/// (., d)], added to block (N, 3, 3) where a = b, and (negated, as the smoother's entries
/// hold -A_ij) to coef (E, 3, 3) at slot[t, a, b] otherwise (coef zeroed first; slot null:
/// the diagonal blocks only).
inline void smoother_blocks(const Model& m, double h, const double* q, const double* hb,
                            double* block, const index* slot, index entries, double* coef) {
    double local[kBlock];
    if (slot != nullptr) std::fill(coef, coef + 9 * entries, 0.0);
    for (index t = 0; t < m.membranes.count; ++t) {
        const Element e = element(m, q, t);
        const double* b = hb != nullptr ? hb + kBlock * t : local;
        if (hb == nullptr) blocks(m, q, t, local);
        double mix[36];  // h^2 H_F+ + h D_F, unpacked
        for (int i = 0; i < 6; ++i)
            for (int j = i; j < 6; ++j) {
                const int k = sym_index(i, j);
                mix[6 * i + j] = mix[6 * j + i] = h * h * b[k] + h * b[kSym6 + k];
            }
        double rows[3][3][6];  // rows[a][i][.] = sum_c g_a,c mix[3 c + i][.]
        for (int a = 0; a < 3; ++a)
            for (int i = 0; i < 3; ++i)
                for (int k = 0; k < 6; ++k)
                    rows[a][i][k] = e.g[a][0] * mix[6 * i + k] + e.g[a][1] * mix[6 * (3 + i) + k];
        for (int a = 0; a < 3; ++a)
            for (int c = 0; c < 3; ++c) {
                double* d;
                double sign = 1.0;
                if (a == c) {
                    d = block + 9 * e.v[a];
                } else if (slot != nullptr) {
                    d = coef + 9 * slot[9 * t + 3 * a + c];
                    sign = -1.0;
                } else {
                    continue;
                }
                for (int i = 0; i < 3; ++i)
                    for (int j = 0; j < 3; ++j)
                        d[3 * i + j] += sign * (rows[a][i][j] * e.g[c][0] +
                                                rows[a][i][3 + j] * e.g[c][1]);
            }
    }
}

/// The diagonal of the membrane's part of M - h C - h^2 K per particle, averaged over its
/// three directions (the Jacobi preconditioner's scalar), added to diag (N,).
inline void add_jacobi_diagonal(const Model& m, double h, const double* q, const double* hb,
                                double* diag) {
    double local[kBlock];
    for (index t = 0; t < m.membranes.count; ++t) {
        const Element e = element(m, q, t);
        const double* b = hb != nullptr ? hb + kBlock * t : local;
        if (hb == nullptr) blocks(m, q, t, local);
        for (int a = 0; a < 3; ++a) {
            double s = 0.0;
            for (int i = 0; i < 3; ++i)
                for (int bc = 0; bc < 2; ++bc)
                    for (int cc = 0; cc < 2; ++cc) {
                        const int k = sym_index(3 * bc + i, 3 * cc + i);
                        s += e.g[a][bc] * e.g[a][cc] * (h * h * b[k] + h * b[kSym6 + k]);
                    }
            diag[e.v[a]] += s / 3.0;
        }
    }
}

/// How many times the small-strain stiffness projective dynamics' matrix holds
/// (softbody.membrane.PROJECTIVE_MARGIN): the splitting contracts while the sheet's
/// tangent stays below the matrix's weight, and a stretched sheet stiffens (StVK's tangent
/// grows like (3 l^2 - 1) / 2 at stretch l, and tension adds geometric stiffness). With 1
/// a StVK balloon at stretch 1.8 and a neo-Hookean one at 2.5 diverged; with 3 both
/// settle, and at 6 the iterations converged visibly slower.
constexpr double kProjectiveMargin = 3.0;

/// Projective dynamics' weight of triangle t for step h [s]: A0 H w (1 + beta / h),
/// w = kProjectiveMargin 2 (G_s + lam_s), 2 (G_s + lam_s) the small-strain stiffness's
/// largest eigenvalue in F [Pa].
inline double projective_weight(const Model& m, index t, double h) {
    double shear, lame;
    small_strain(m, t, shear, lame);
    return m.membranes.rest_area[t] * m.membranes.thickness[t] * kProjectiveMargin * 2.0 *
           (shear + lame) * (1.0 + m.membranes.damping[t] / h);
}

/// Projective dynamics: the membrane's part of the global step's right-hand side, added to
/// rhs (N, 3) [N]: per triangle W G^T G x (W = projective_weight; the matrix part the
/// factor holds, over free particles only: a pinned corner's column is no unknown) plus
/// the membrane's force at the iterate x with the velocities (x - x0) / h.
inline void project(const Model& m, double h, const double* x, const double* x0, double* rhs) {
    const double* inv_mass = m.particles.inv_mass;
    const double inv_h = 1.0 / h;
    for (index t = 0; t < m.membranes.count; ++t) {
        const Element e = element(m, x, t);
        const double w = projective_weight(m, t, h);
        V3 sum = {0.0, 0.0, 0.0}, s1 = {0.0, 0.0, 0.0};  // G x over free corners
        V3 xs[3];
        for (int a = 0; a < 3; ++a) {
            xs[a] = inv_mass[e.v[a]] > 0.0 ? load(x, e.v[a]) : V3{0.0, 0.0, 0.0};
            sum = sum + e.g[a][0] * xs[a];
            s1 = s1 + e.g[a][1] * xs[a];
        }
        for (int a = 0; a < 3; ++a)
            if (inv_mass[e.v[a]] > 0.0) add_to(rhs, e.v[a], w * (e.g[a][0] * sum + e.g[a][1] * s1));
        // the force at the iterate: elastic, and viscous with v = (x - x0) / h
        const S2 cg = gram(e.f0, e.f1);
        S2 s = stress(m, t, cg);
        const double beta = m.membranes.damping[t];
        if (beta > 0.0) {
            V3 r0 = {0.0, 0.0, 0.0}, r1 = {0.0, 0.0, 0.0};
            for (int a = 0; a < 3; ++a) {
                const V3 v = inv_h * (load(x, e.v[a]) - load(x0, e.v[a]));
                r0 = r0 + e.g[a][0] * v;
                r1 = r1 + e.g[a][1] * v;
            }
            double shear, lame;
            small_strain(m, t, shear, lame);
            const S2 dc = {2.0 * dot(r0, e.f0), dot(r0, e.f1) + dot(e.f0, r1), 2.0 * dot(r1, e.f1)};
            s = s + viscous_half(beta, shear, lame, dc);
        }
        V3 p0, p1;
        times_f(e.f0, e.f1, s, p0, p1);
        const double scale = -m.membranes.rest_area[t] * m.membranes.thickness[t];
        for (int a = 0; a < 3; ++a)
            if (inv_mass[e.v[a]] > 0.0)
                add_to(rhs, e.v[a], scale * (e.g[a][0] * p0 + e.g[a][1] * p1));
    }
}

/// Stiffness bound (softbody.stability): Gershgorin by 3 x 3 blocks on M^-1/2 K M^-1/2.
/// Triangle t's block (a, b) of K has norm at most |H_F| |g_a| |g_b| (|H_F| the spectral
/// radius of its exact F-Hessian at q, so the bound holds at the current stretch, not only
/// near rest), so row i is at most sum over its triangles of |H_F| |g_a| / sqrt(m_i)
/// sum_b |g_b| / sqrt(m_b) (pinned particles, 1 / m = 0, add none). Into bound
/// (springs::BoundPart order: the elastic stiffness counts as damped and whole, since its
/// damping is beta times it near rest; nothing transverse; the damping D_F alike) the
/// largest rows [1/s^2] ([1/s] for damping); row (N, 2) scratch.
inline void bound_rows(const Model& m, const double* q, double* row, double* bound) {
    const double* inv = m.particles.inv_mass;
    std::fill(row, row + 2 * m.particles.count, 0.0);
    for (index t = 0; t < m.membranes.count; ++t) {
        const Element e = element(m, q, t);
        double hf[36], hd[36], v[36];
        f_hessians(m, t, e, hf, hd);
        eigen6(hf, v);
        eigen6(hd, v);
        double rf = 0.0, rd = 0.0;
        for (int k = 0; k < 6; ++k) {
            rf = std::max(rf, std::abs(hf[7 * k]));
            rd = std::max(rd, std::abs(hd[7 * k]));
        }
        if (!std::isfinite(rf)) rf = INFINITY;
        double len[3], across = 0.0;
        for (int a = 0; a < 3; ++a) {
            len[a] = std::hypot(e.g[a][0], e.g[a][1]);
            across += len[a] * std::sqrt(inv[e.v[a]]);
        }
        for (int a = 0; a < 3; ++a) {
            const double r = len[a] * std::sqrt(inv[e.v[a]]) * across;
            row[2 * e.v[a]] += rf * r;
            row[2 * e.v[a] + 1] += rd * r;
        }
    }
    for (index i = 0; i < m.particles.count; ++i) {
        bound[0] = std::max(bound[0], row[2 * i]);  // damped
        bound[2] = std::max(bound[2], row[2 * i]);  // whole
        bound[3] = std::max(bound[3], row[2 * i + 1]);  // damping
    }
}

/// The damping per stiffness beta [s] of every membrane triangle folded into [lo, hi].
inline void damping_ratios(const Model& m, double& lo, double& hi) {
    for (index t = 0; t < m.membranes.count; ++t) {
        lo = std::min(lo, m.membranes.damping[t]);
        hi = std::max(hi, m.membranes.damping[t]);
    }
}

/// Ring slot s's geometry at lane lane0 (Slots::ring_membrane), for lane_triangle.
inline const double* ring_geometry(const Model& m, index s, int lane0) {
    return m.slots.ring_membrane + kMembraneGeometry * kGroup * s + lane0;
}

/// The lane form (the vertex-major pass, solvers/lanes.hpp): triangle (i, a, b) seen from
/// its corner i, kLanes particles i at once, its force on i added to fx, fy, fz [N]. Rows
/// of i, a, b (positions and velocities), with a - i and b - i given (the pass has them);
/// `geometry` at the slot's lane 0 in a (slots, 3, 8) table (Slots::ring_membrane: u, w, v,
/// 8 apart), `row` its (kLanes,) coefficient rows in Slots::membrane_rows. In the rest
/// frame whose x axis runs from i to a, a's gradient vector is (u, w) and b's (0, v), so
/// F = [u (a - i), w (a - i) + v (b - i)], i's is -(u, w + v) and the rest area
/// A0 = 1 / (2 u |v|); the stress S (the
/// materials' dW/dC and the viscous stress in one form, with -2 H folded in: plan/lanes.cpp,
/// membrane_row) gives f_i = A0 F S g_i, the edge-major force's corner term. Each triangle
/// is computed at its three corners (3 x the arithmetic of `force`, without its scatter).
SOFTBODY_ALWAYS_INLINE void lane_triangle(const Model& m, const double* geometry, const index* row,
                          const Rows& self, const Rows& a, vd ax, vd ay, vd az, const Rows& b,
                          vd bx, vd by, vd bz, vd& fx, vd& fy, vd& fz) {
    const vd u = load_lanes(geometry), w = load_lanes(geometry + kGroup);
    const vd v = load_lanes(geometry + 2 * kGroup);
    // the rest area A0 = 1 / (2 u |v|) (the table's third of a cache line less to read);
    // 0 in a lane without a triangle (u = 0)
    const vi has = u != 0.0;
    const vd uv = u * v;
    const vd area = select(has, 0.5 / (has ? (uv < 0.0 ? -uv : uv) : splat(1.0)));
    // the coefficients: one row for every lane (a body of one material), else a transpose
    // (a lane without a triangle has no area: any row gives it no force)
    vd m1, m2, s1, s2, d1, d2;
    bool same = true;
    if (!m.slots.membrane_one_row)
        for (int l = 1; l < kLanes; ++l) same = same && row[l] == row[0];
    if (same) {
        const double* r = m.slots.membrane_rows + 8 * (m.slots.membrane_one_row ? 1 : row[0]);
        m1 = splat(r[0]), m2 = splat(r[1]), s1 = splat(r[2]), s2 = splat(r[3]);
        d1 = splat(r[4]), d2 = splat(r[5]);
    } else {
        const Rows r = load_rows(m.slots.membrane_rows, row);
        m1 = r.x, m2 = r.y, s1 = r.z, s2 = r.vx, d1 = r.vy, d2 = r.vz;
    }
    // F = [f0 f1] and C = F^T F = [[ca, cb], [cb, cc]] (dot products by fused multiply-adds)
    auto dot3 = [](vd x0, vd y0, vd z0, vd x1, vd y1, vd z1) {
        return fmadd(x0, x1, fmadd(y0, y1, z0 * z1));
    };
    const vd f0x = u * ax, f0y = u * ay, f0z = u * az;
    const vd f1x = fmadd(w, ax, v * bx), f1y = fmadd(w, ay, v * by), f1z = fmadd(w, az, v * bz);
    const vd ca = dot3(f0x, f0y, f0z, f0x, f0y, f0z);
    const vd cb = dot3(f0x, f0y, f0z, f1x, f1y, f1z);
    const vd cc = dot3(f1x, f1y, f1z, f1x, f1y, f1z);
    const vd tr = ca + cc, j = fmadd(ca, cc, -(cb * cb));
    // 1 / J where the material is incompressible and there is a triangle (J <= 0 then gives
    // what `force` gives), else of 1, so that no lane multiplies an infinity by a zero
    const vi incompressible = ((m1 != 0.0) | (m2 != 0.0)) & has;
    const vd inv_j = 1.0 / (incompressible ? j : splat(1.0)), inv_j2 = inv_j * inv_j;
    // S = alpha I + beta adj C + s1 C (+ the viscous stress)
    const vd alpha = fmadd(m2, inv_j, m1) - s1 + s2 * (tr - 2.0);
    const vd beta = m2 - fmadd(m2, tr, m1) * inv_j2;
    vd sa = fmadd(beta, cc, fmadd(s1, ca, alpha)), sb = (s1 - beta) * cb;
    vd sc = fmadd(beta, ca, fmadd(s1, cc, alpha));
    if (m.slots.membrane_damped) {  // dC/dt = Fdot^T F + F^T Fdot
        const vd vax = a.vx - self.vx, vay = a.vy - self.vy, vaz = a.vz - self.vz;
        const vd vbx = b.vx - self.vx, vby = b.vy - self.vy, vbz = b.vz - self.vz;
        const vd r0x = u * vax, r0y = u * vay, r0z = u * vaz;
        const vd r1x = fmadd(w, vax, v * vbx), r1y = fmadd(w, vay, v * vby);
        const vd r1z = fmadd(w, vaz, v * vbz);
        const vd da = 2.0 * dot3(r0x, r0y, r0z, f0x, f0y, f0z);
        const vd db = dot3(r0x, r0y, r0z, f1x, f1y, f1z) + dot3(f0x, f0y, f0z, r1x, r1y, r1z);
        const vd dc = 2.0 * dot3(r1x, r1y, r1z, f1x, f1y, f1z);
        const vd dtr = d2 * (da + dc);
        sa = fmadd(d1, da, sa + dtr), sb = fmadd(d1, db, sb), sc = fmadd(d1, dc, sc + dtr);
    }
    // f_i = A0 F S g_i with g_i = -(u, w + v)
    const vd gi0 = -area * u, gi1 = -area * (w + v);
    const vd k0 = fmadd(gi0, sa, gi1 * sb), k1 = fmadd(gi0, sb, gi1 * sc);  // S g_i
    fx += fmadd(k0, f0x, k1 * f1x);
    fy += fmadd(k0, f0y, k1 * f1y);
    fz += fmadd(k0, f0z, k1 * f1z);
}

/// The lane form's triangles off the rings (Slots::membrane_*: a second layer, triangles
/// whose faces make no fan of the particle's), for particles [kGroup g + lane0, + kLanes),
/// their force added to fx, fy, fz [N]; rows (8 G, 8) the packed state.
inline void lane_force(const Model& m, const double* rows, index g, int lane0, const Rows& self,
                       vd& fx, vd& fy, vd& fz) {
    for (index s = m.slots.membrane_start[g]; s < m.slots.membrane_start[g + 1]; ++s) {
        const index e = kGroup * s + lane0;
        const Rows a = load_rows(rows, m.slots.membrane_next + e);
        const Rows b = load_rows(rows, m.slots.membrane_last + e);
        lane_triangle(m, m.slots.membrane_geometry + kMembraneGeometry * kGroup * s + lane0,
                      m.slots.membrane_row + e, self, a, a.x - self.x, a.y - self.y,
                      a.z - self.z, b, b.x - self.x, b.y - self.y, b.z - self.z, fx, fy, fz);
    }
}

/// The registered term (terms/registry.hpp).
struct Term : TermBase {
    static constexpr const char* kName = "membrane";
    static constexpr bool kProjected = true, kEnergy = true, kBound = true, kSpectral = true;
    // the vertex-major pass gives its force (lane_triangle), and then the fused symplectic
    // pass covers it; without the pass its edge-major force keeps its place in the sums
    static constexpr bool kLane = true, kFusedInPass = true;
    // smoother entries: -A_ij (3 x 3, row-major) between corners (smoother_blocks)
    static constexpr bool kStencil = true;
    static constexpr int kStencilWidth = 9;
    /// s += sum over entries of their block times x_j.
    static void add_entries(const Stencil& st, const double* x, index first, index last,
                            V3& s) {
        for (index e = first; e < last; ++e) {
            const index j = st.neighbor[e];
            const double* c = st.coef + 9 * e;
            const double xj0 = x[3 * j], xj1 = x[3 * j + 1], xj2 = x[3 * j + 2];
            s.x += c[0] * xj0 + c[1] * xj1 + c[2] * xj2;
            s.y += c[3] * xj0 + c[4] * xj1 + c[5] * xj2;
            s.z += c[6] * xj0 + c[7] * xj1 + c[8] * xj2;
        }
    }
    /// The map: each triangle's corner pair's entry (Tm, 3, 3), -1 exactly on a = b.
    static const char* check_stencil(const Model& m, const Stencil& st, index map_length) {
        if (map_length != 9 * m.membranes.count) return "map must have shape (Tm, 3, 3)";
        for (index t = 0; t < m.membranes.count; ++t)
            for (int a = 0; a < 3; ++a)
                for (int b = 0; b < 3; ++b) {
                    const index e = st.map[9 * t + 3 * a + b];
                    if (e >= st.count || e < -1) return "map holds an entry out of range";
                    if ((e < 0) != (a == b)) return "map must be -1 exactly on each diagonal";
                }
        return nullptr;
    }
    /// The stability estimate: bound_rows by part, and beta into the c / k range.
    static void bound(const Model& m, const Control&, const double* q, const BoundScratch& s,
                      TermBound& out) {
        bound_rows(m, q, s.rows, out.parts);
        damping_ratios(m, out.ratio_min, out.ratio_max);
    }
    static bool active(const Model& m, const Control&) { return m.membranes.count > 0; }
    static void force(const Eval& e, double* f) { membrane::force(e.m, e.q, e.qd, f); }
    static double energy(const Eval& e, double* body) { return energies(e.m, e.q, body); }
    /// Linearisation: each triangle's clamped blocks (Tm, kBlock) (membrane::prepare).
    static index linearization_size(const Model& m) { return kBlock * m.membranes.count; }
    static void prepare(const Eval& e, const Linearization& l) {
        if (l.own != nullptr) membrane::prepare(e.m, l.q, l.own);
    }
    static void jacobian_product(const Model& m, const Control&, const Linearization& l,
                                 double alpha_c, double alpha_k, const double* p, double* out) {
        membrane::jacobian_product(m, l.q, l.own, alpha_c, alpha_k, p, out);
    }
    /// The stability estimate: the clamped blocks at l.q, as prepare. Its stiffness is
    /// damped (its damping is beta times it near rest): the damped and whole parts, its
    /// damping the damping part.
    static void prepare_spectral(const Eval& e, const BoundScratch&, const Linearization& l) {
        prepare(e, l);
    }
    static void spectral_product(const Model& m, const Control& c, const Linearization& l,
                                 StiffnessPart part, const double* p, double* out) {
        if (part == StiffnessPart::kUndamped) return;
        const bool damping = part == StiffnessPart::kDamping;
        jacobian_product(m, c, l, damping ? 1.0 : 0.0, damping ? 0.0 : 1.0, p, out);
    }
    static void add_smoother_blocks(const Model& m, const Control&, const Linearization& l,
                                    const SmootherBlocks& s) {
        smoother_blocks(m, s.h, l.q, l.own, s.block, s.entries.map,
                        s.entries.count, s.entries.coef);
    }
    /// Jacobi: the mean of each corner's diagonal block's diagonal.
    static void add_jacobi_diagonal(const Model& m, const Control&, const Linearization& l,
                                    double h, double* diag) {
        membrane::add_jacobi_diagonal(m, h, l.q, l.own, diag);
    }
    static void project(const Model& m, const Control&, double h, const double* x,
                        const double* x0, double* rhs) {
        membrane::project(m, h, x, x0, rhs);
    }
};

}  // namespace softbody::SOFTBODY_KERNELS::membrane
