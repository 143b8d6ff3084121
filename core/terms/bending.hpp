// Material bending of a surface: the discrete-shell energy (Grinspun, Hirani, Desbrun and
// Schroeder 2003, "Discrete Shells") on every interior edge ("hinge").
//
// A hinge is the edge (x0, x1) shared by the triangles (x0, x1, x2) and (x1, x0, x3), both
// wound as the surface. With e = x1 - x0, n1 = e x (x2 - x0), n2 = (x3 - x0) x e (the two
// faces' normals, of lengths twice their areas) its signed dihedral angle is
//     theta = atan2((n1 x n2) . e / |e|, n1 . n2),
// 0 where the two faces are flat, positive where the surface bends away from its normals
// (on a convex closed surface wound outward). Its energy is
//     E = k (theta - theta0)^2,   k = D |e0|^2 / (2 A0)   [N m],
// D the bending stiffness [N m] (E H^3 / (12 (1 - nu^2)) for a plate), |e0| the rest edge
// length and A0 the two triangles' rest areas summed; theta - theta0 is taken in
// [-pi, pi]. On a mesh of equilateral triangles (k = D / sqrt(3), Seung and Nelson 1988)
// bent to a cylinder of radius R this tends to the plate's D / (2 R^2) per unit area
// (docs/guide/bending.md: the factor, and how it depends on the mesh).
//
// The gradient of theta (Bridson, Marino and Fedkiw 2003; Tamstorf and Grinspun 2013):
//     g2 = -|e| n1 / |n1|^2,   g3 = -|e| n2 / |n2|^2,
//     g1 = -(s2 g2 + s3 g3),   g0 = -(g1 + g2 + g3)   (theta moves with no translation),
// s_k = (x_k - x0) . e / |e|^2. The force on corner a is f_a = -2 k (theta - theta0) g_a.
// A hinge whose edge or either face has no length or area has no angle: no force.
//
// Forms: force and energy (per body, by Bending::body); jacobian_product and
// add_smoother_blocks with the Gauss-Newton stiffness K = -2 k g g^T per hinge (g the
// 12-vector of the four gradients), the exact Hessian less its part 2 k (theta - theta0)
// d2theta/dx2, which is indefinite: -K is positive semi-definite, and exact where every
// hinge is at its rest angle; prepare stores the gradients at the linearisation's point
// (its linearisation, Linearization::own). add_bound_rows: the stability estimate's Gershgorin
// rows. No projection: the dihedral angle is not a quadratic constraint, and projective
// dynamics steps this force explicitly inside its iterations, as it does the gas. No
// damping.
#pragma once

#include <cmath>

#include "model.hpp"
#include "terms/term.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::bending {

/// One hinge at some positions: its angle theta [rad] and the gradients g (4,) [1/m] of
/// theta with respect to its four corners; live false where the angle is undefined.
struct Hinge {
    double theta = 0.0;
    V3 g[4];
    bool live = false;
};

/// The angle and its gradient of hinge h at q (N, 3); kAngle false leaves theta 0 (the
/// Jacobian needs the gradient only, and the atan2 is a good part of the cost).
template <bool kAngle = true>
inline Hinge hinge(const Model& m, const double* q, index h) {
    const index* c = m.bending.hinges + 4 * h;
    const V3 x0 = load(q, c[0]);
    const V3 e = load(q, c[1]) - x0, a = load(q, c[2]) - x0, b = load(q, c[3]) - x0;
    const V3 n1 = cross(e, a), n2 = cross(b, e);
    const double e2 = dot(e, e), a1 = dot(n1, n1), a2 = dot(n2, n2);
    Hinge out;
    if (!(e2 > 0.0 && a1 > 0.0 && a2 > 0.0)) return out;
    const double length = std::sqrt(e2), inv_length = 1.0 / length;
    if (kAngle) out.theta = std::atan2(dot(cross(n1, n2), e) * inv_length, dot(n1, n2));
    out.g[2] = (-length / a1) * n1;
    out.g[3] = (-length / a2) * n2;
    const double inv_e2 = inv_length * inv_length;
    const double s2 = dot(a, e) * inv_e2, s3 = dot(b, e) * inv_e2;
    out.g[1] = -(s2 * out.g[2] + s3 * out.g[3]);
    out.g[0] = -(out.g[1] + out.g[2] + out.g[3]);
    out.live = true;
    return out;
}

/// theta - theta0 of hinge h taken in [-pi, pi] [rad]: both lie in [-pi, pi], so one
/// turn added or taken away suffices (softbody.reference.bending.excess alike).
inline double excess(const Model& m, index h, double theta) {
    constexpr double kPi = 3.141592653589793, kTwoPi = 6.283185307179586;
    const double d = theta - m.bending.rest_angle[h];
    return d > kPi ? d - kTwoPi : (d < -kPi ? d + kTwoPi : d);
}

/// Accumulate every hinge's bending force -dE/dx into f (N, 3) [N] at q (N, 3).
inline void force(const Model& m, const double* q, double* f) {
    for (index h = 0; h < m.bending.count; ++h) {
        const Hinge g = hinge(m, q, h);
        if (!g.live) continue;
        const double s = -2.0 * m.bending.stiffness[h] * excess(m, h, g.theta);
        const index* c = m.bending.hinges + 4 * h;
        for (int a = 0; a < 4; ++a) add_to(f, c[a], s * g.g[a]);
    }
}

/// Bending energy k (theta - theta0)^2 [J] of every hinge at q (N, 3), each added to its
/// body's entry of body_energy (B,); returns the total [J]. A hinge without an angle
/// (a degenerate face) counts theta = 0.
inline double energies(const Model& m, const double* q, double* body_energy) {
    double total = 0.0;
    for (index h = 0; h < m.bending.count; ++h) {
        const double d = excess(m, h, hinge(m, q, h).theta);
        const double e = m.bending.stiffness[h] * d * d;
        total += e;
        body_energy[m.bending.body[h]] += e;
    }
    return total;
}

/// Every hinge's gradient of theta at q (N, 3) into gradient (H, 4, 3) [1/m] (0 where the
/// angle is undefined): what jacobian_product and smoother_blocks read, once per step.
inline void gradients(const Model& m, const double* q, double* gradient) {
    for (index h = 0; h < m.bending.count; ++h) {
        const Hinge g = hinge<false>(m, q, h);
        for (int a = 0; a < 4; ++a) store(gradient, 4 * h + a, g.g[a]);
    }
}

/// Hinge h's gradients: from `gradient` (H, 4, 3) when given, else computed at q (N, 3).
inline Hinge stored_or_computed(const Model& m, const double* q, const double* gradient,
                                index h) {
    if (gradient == nullptr) return hinge<false>(m, q, h);
    Hinge g;
    for (int a = 0; a < 4; ++a) g.g[a] = load(gradient, 4 * h + a);
    g.live = true;  // a dead hinge's stored gradient is 0: it adds nothing
    return g;
}

/// out += alpha_k K p for p (N, 3), K = -2 k g g^T per hinge (Gauss-Newton) at q (N, 3),
/// g from `gradient` (H, 4, 3) (gradients) or, where null, computed at q.
inline void jacobian_product(const Model& m, const double* q, const double* gradient,
                             double alpha_k, const double* p, double* out) {
    if (alpha_k == 0.0) return;
    for (index h = 0; h < m.bending.count; ++h) {
        const Hinge g = stored_or_computed(m, q, gradient, h);
        if (!g.live) continue;
        const index* c = m.bending.hinges + 4 * h;
        double gp = 0.0;
        for (int a = 0; a < 4; ++a) gp += dot(g.g[a], load(p, c[a]));
        const double s = -2.0 * alpha_k * m.bending.stiffness[h] * gp;
        for (int a = 0; a < 4; ++a) add_to(out, c[a], s * g.g[a]);
    }
}

/// The hinges' share of the diagonal blocks (N, 3, 3) of M - h^2 K: h^2 2 k g_a g_a^T at
/// each corner a, at q (N, 3) (g from `gradient` as in jacobian_product); h [s].
inline void smoother_blocks(const Model& m, const double* q, const double* gradient, double h,
                            double* block) {
    for (index k = 0; k < m.bending.count; ++k) {
        const Hinge g = stored_or_computed(m, q, gradient, k);
        if (!g.live) continue;
        const double w = 2.0 * h * h * m.bending.stiffness[k];
        const index* c = m.bending.hinges + 4 * k;
        for (int a = 0; a < 4; ++a) {
            const V3 v = g.g[a];
            double* d = block + 9 * c[a];
            const double xy = w * v.x * v.y, xz = w * v.x * v.z, yz = w * v.y * v.z;
            d[0] += w * v.x * v.x, d[4] += w * v.y * v.y, d[8] += w * v.z * v.z;
            d[1] += xy, d[3] += xy;
            d[2] += xz, d[6] += xz;
            d[5] += yz, d[7] += yz;
        }
    }
}

/// The factor on the Gauss-Newton stiffness 2 k g g^T that the stability estimate takes
/// for the whole Hessian 2 k (g g^T + (theta - theta0) d2theta/dx2): 1 + 2 |theta -
/// theta0|, a margin for the second part, which grows with the angle's excess and, on
/// well-shaped triangles, is of the size of the first (d2theta/dx2 ~ |g|^2). Not a proof:
/// tests/test_bending.py checks the rows against the whole Hessian's largest eigenvalue
/// on bent, perturbed and folded surfaces.
inline double bound_factor(double excess_angle) { return 1.0 + 2.0 * std::abs(excess_angle); }

/// Stiffness bound: Gershgorin on M^-1/2 K M^-1/2 for K the hinges' stiffness, block by
/// block: a hinge adds to the row of each free corner a the norms of its blocks,
/// w |g_a| / sqrt(m_a) sum_b |g_b| / sqrt(m_b), w = 2 k bound_factor; added into rows (N,)
/// [1/s^2]. Pinned corners (1 / m = 0) add none.
inline void add_bound_rows(const Model& m, const double* q, double* rows) {
    const double* inv = m.particles.inv_mass;
    for (index h = 0; h < m.bending.count; ++h) {
        const Hinge g = hinge(m, q, h);
        if (!g.live) continue;
        const index* c = m.bending.hinges + 4 * h;
        const double w =
            2.0 * m.bending.stiffness[h] * bound_factor(excess(m, h, g.theta));
        double scaled[4], sum = 0.0;
        for (int a = 0; a < 4; ++a) {
            scaled[a] = std::sqrt(dot(g.g[a], g.g[a]) * inv[c[a]]);
            sum += scaled[a];
        }
        for (int a = 0; a < 4; ++a) rows[c[a]] += w * scaled[a] * sum;
    }
}

/// The registered term (terms/registry.hpp): its forms for the solvers. prepare stores the
/// gradients at the linearisation's point where the solver gives room for them
/// (its linearisation, l.own: (H, 4, 3)); the products compute them at l.q where it does not.
struct Term : TermBase {
    static constexpr const char* kName = "bending";
    static constexpr bool kEnergy = true, kBound = true, kSpectral = true;
    /// The stability estimate: its rows are undamped stiffness (parts undamped and whole).
    static void bound(const Model& m, const Control&, const double* q, const BoundScratch& s,
                      TermBound& out) {
        double* rows = s.rows;
        std::fill(rows, rows + m.particles.count, 0.0);
        add_bound_rows(m, q, rows);
        for (index i = 0; i < m.particles.count; ++i) {
            out.parts[1] = std::max(out.parts[1], rows[i]);
            out.parts[2] = std::max(out.parts[2], rows[i]);
        }
    }
    static bool active(const Model& m, const Control&) { return m.bending.count > 0; }
    static void force(const Eval& e, double* f) { bending::force(e.m, e.q, f); }
    static double energy(const Eval& e, double* body) { return energies(e.m, e.q, body); }
    /// Linearisation: each hinge's d theta / dx (H, 4, 3) [1/m].
    static index linearization_size(const Model& m) { return 12 * m.bending.count; }
    static void prepare(const Eval& e, const Linearization& l) {
        if (l.own != nullptr) gradients(e.m, l.q, l.own);
    }
    static void jacobian_product(const Model& m, const Control&, const Linearization& l,
                                 double, double alpha_k, const double* p, double* out) {
        bending::jacobian_product(m, l.q, l.own, alpha_k, p, out);
    }
    /// The stability estimate: the gradients at l.q, as prepare; its Gauss-Newton stiffness
    /// is undamped (the undamped and whole parts).
    static void prepare_spectral(const Eval& e, const BoundScratch&, const Linearization& l) {
        prepare(e, l);
    }
    static void spectral_product(const Model& m, const Control& c, const Linearization& l,
                                 StiffnessPart part, const double* p, double* out) {
        if (part == StiffnessPart::kUndamped || part == StiffnessPart::kWhole)
            jacobian_product(m, c, l, 0.0, 1.0, p, out);
    }
    static void add_smoother_blocks(const Model& m, const Control&, const Linearization& l,
                                    const SmootherBlocks& s) {
        smoother_blocks(m, l.q, l.own, s.h, s.block);
    }
};

}  // namespace softbody::SOFTBODY_KERNELS::bending
