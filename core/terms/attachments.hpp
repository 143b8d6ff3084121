// Damped springs tying particles to anchor points (the paper's hanging ball). The anchors
// come from Control and do not move during a step. Force on particle i with
// u = (anchor - x_i) / L: [k (L - L0) - c v_i . u] u. Energy 1/2 k (L - L0)^2.
//
// Forms: force; energies (per body of the tied particle); jacobian_product;
// add_smoother_blocks; project (projective dynamics, through springs::projection);
// bound_weights, add_root_sums, row_bounds and damping_ratios (the stability estimate's
// Gershgorin bound: an attachment adds sqrt(w) to its particle's row sum R_i, shared with
// the springs, and its row sqrt(w) R_i / m_i).
#pragma once

#include <vector>

#include "model.hpp"
#include "terms/springs.hpp"
#include "terms/term.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::attachments {

/// Accumulate the attachment forces into f (N, 3) [N].
inline void force(const Model& m, const Control& c, const double* q, const double* qd,
                  double* f) {
    for (index a = 0; a < m.attachments.count; ++a) {
        const index i = m.attachments.particle[a];
        const V3 d = load(c.attachment_anchor, a) - load(q, i);
        const double length = std::sqrt(dot(d, d));
        if (length == 0.0) continue;
        const V3 u = (1.0 / length) * d;
        const double rel = -dot(load(qd, i), u);
        const double mag = m.attachments.stiffness[a] * (length - m.attachments.rest_length[a]) +
                           m.attachments.damping[a] * rel;
        add_to(f, i, mag * u);
    }
}

/// Projective dynamics: the attachments' part of the global step's right-hand side, added
/// to rhs (N, 3) [N] at the iterate x (N, 3) (x0 at the step's start; h [s] the step). An
/// attachment is a spring to a fixed anchor a: its energy k / 2 |d - p|^2 + c / (2 h)
/// |d - q|^2 in d = x_i - a (springs::projection) gives (k + c / h) a + k p + c / h q, the
/// matrix holding its (k + c / h) on i's diagonal. Pinned particles have none.
inline void project(const Model& m, const Control& c, double h, const double* x,
                    const double* x0, double* rhs) {
    const double inv_h = 1.0 / h;
    for (index a = 0; a < m.attachments.count; ++a) {
        const index i = m.attachments.particle[a];
        if (m.particles.inv_mass[i] == 0.0) continue;
        const V3 anchor = load(c.attachment_anchor, a);
        const double k = m.attachments.stiffness[a], c_h = m.attachments.damping[a] * inv_h;
        const V3 t = springs::projection(load(x, i) - anchor, load(x0, i) - anchor,
                                         m.attachments.rest_length[a], k, c_h);
        add_to(rhs, i, (k + c_h) * anchor + t);
    }
}

/// out += alpha_c C p + alpha_k K p: per attachment -(k_iso p_i + ((k - k_iso) u.p) u) with
/// k_iso = k max(0, 1 - L0/L), and -c (u.p) u for the damping.
inline void jacobian_product(const Model& m, const Control& c, const double* q, double alpha_c,
                             double alpha_k, const double* p, double* out) {
    for (index a = 0; a < m.attachments.count; ++a) {
        const index i = m.attachments.particle[a];
        const V3 d = load(c.attachment_anchor, a) - load(q, i);
        const double length = std::sqrt(dot(d, d));
        const double k = m.attachments.stiffness[a];
        double iso = k, ud = 0.0;
        V3 u{0.0, 0.0, 0.0};
        if (length != 0.0) {
            u = (1.0 / length) * d;
            iso = k * std::max(0.0, 1.0 - m.attachments.rest_length[a] / length);
            ud = dot(u, load(p, i));
        }
        const double axial = alpha_k * (k - iso) * ud + alpha_c * m.attachments.damping[a] * ud;
        const V3 pi = load(p, i);
        out[3 * i] -= alpha_k * iso * pi.x + axial * u.x;
        out[3 * i + 1] -= alpha_k * iso * pi.y + axial * u.y;
        out[3 * i + 2] -= alpha_k * iso * pi.z + axial * u.z;
    }
}

/// out -= the stability estimate's part `part` of every attachment's stiffness (or
/// damping) block times p_i at q, anchors from c: with u = d / L the unit vector to the
/// anchor and t = k |1 - L0/L| (u = 0 and t = k where L = 0), the axial k u u^T (damped,
/// its damper c u u^T the damping part), the transverse t (I - u u^T) (undamped), their
/// sum (whole).
inline void spectral_product(const Model& m, const Control& c, const double* q,
                             StiffnessPart part, const double* p, double* out) {
    for (index a = 0; a < m.attachments.count; ++a) {
        const index i = m.attachments.particle[a];
        const V3 d = load(c.attachment_anchor, a) - load(q, i);
        const double length = std::sqrt(dot(d, d));
        const double k = m.attachments.stiffness[a];
        V3 u{0.0, 0.0, 0.0};
        double t = k * 1.0;
        if (length > 0.0) {
            u = {d.x / length, d.y / length, d.z / length};
            t = k * std::abs(1.0 - m.attachments.rest_length[a] / length);
        }
        double axial = 0.0, side = 0.0;  // the block axial u u^T + side (I - u u^T)
        if (part == StiffnessPart::kDamped || part == StiffnessPart::kWhole) axial = k;
        if (part == StiffnessPart::kUndamped || part == StiffnessPart::kWhole) side = t;
        if (part == StiffnessPart::kDamping) axial = m.attachments.damping[a];
        const V3 pi = load(p, i);
        const double up = dot(u, pi);
        add_to(out, i, -(side * pi + ((axial - side) * up) * u));
    }
}

/// The attachments' share of the implicit system's diagonal blocks (N, 3, 3) at q for step
/// h [s]: per attachment h^2 (k_iso I + (k - k_iso) u u^T) + h c u u^T, added to its particle's.
inline void add_smoother_blocks(const Model& m, const Control& c, double h, const double* q,
                                double* block) {
    for (index a = 0; a < m.attachments.count; ++a) {
        const index i = m.attachments.particle[a];
        const V3 dv = load(c.attachment_anchor, a) - load(q, i);
        const double d[3] = {dv.x, dv.y, dv.z};
        const double length = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        const double k = m.attachments.stiffness[a];
        const double iso =
            length == 0.0 ? k : k * std::max(0.0, 1.0 - m.attachments.rest_length[a] / length);
        const double alpha = h * m.attachments.damping[a] + h * h * (k - iso);
        double* b = block + 9 * i;
        for (int r = 0; r < 3; ++r) {
            for (int col = 0; col < 3; ++col)
                if (length > 0.0) b[3 * r + col] += alpha * d[r] * d[col] / (length * length);
            b[4 * r] += h * h * iso;
        }
    }
}

/// Elastic energy 1/2 k (L - L0)^2 [J] of every attachment at q (N, 3) with the anchors of
/// c, each added to its particle's body's entry of body_energy (B,) (a free particle's
/// counts in the total only); returns the total [J].
inline double energies(const Model& m, const Control& c, const double* q, double* body_energy) {
    double total = 0.0;
    for (index a = 0; a < m.attachments.count; ++a) {
        const index i = m.attachments.particle[a];
        const V3 d = load(c.attachment_anchor, a) - load(q, i);
        const double stretch = std::sqrt(dot(d, d)) - m.attachments.rest_length[a];
        const double e = 0.5 * m.attachments.stiffness[a] * stretch * stretch;
        total += e;
        if (m.particles.body[i] >= 0) body_energy[m.particles.body[i]] += e;
    }
    return total;
}

/// Stiffness bound: the norms of each attachment's block by part (springs::BoundPart: k,
/// k |1 - L0/L|, k max(1, |1 - L0/L|), c) into w (A, kBoundParts), at q with c's anchors.
/// An attachment is a spring whose other end does not move.
inline void bound_weights(const Model& m, const Control& c, const double* q, double* w) {
    using namespace springs;
    for (index a = 0; a < m.attachments.count; ++a) {
        const V3 d = load(c.attachment_anchor, a) - load(q, m.attachments.particle[a]);
        const double k = m.attachments.stiffness[a];
        const double stretch = stretch_factor(std::sqrt(dot(d, d)), m.attachments.rest_length[a]);
        double* wa = w + kBoundParts * a;
        wa[kDamped] = k;
        wa[kTransverse] = k * stretch;
        wa[kWhole] = k * std::max(1.0, stretch);
        wa[kDamping] = m.attachments.damping[a];
    }
}

/// The attachments' share of the Gershgorin row sums R_i (springs::add_root_sums): sqrt(w)
/// added into root_sum (N, kBoundParts) at the tied particle.
inline void add_root_sums(const Model& m, const double* w, double* root_sum) {
    using springs::kBoundParts;
    for (index a = 0; a < m.attachments.count; ++a) {
        double* ri = root_sum + kBoundParts * m.attachments.particle[a];
        for (int part = 0; part < kBoundParts; ++part)
            ri[part] += std::sqrt(w[kBoundParts * a + part]);
    }
}

/// The attachments' Gershgorin rows, max over attachments of sqrt(w) R_i / m_i [1/s^2]
/// (damping part: [1/s]), into bound (kBoundParts,) where larger.
inline void row_bounds(const Model& m, const double* w, const double* root_sum, double* bound) {
    using springs::kBoundParts;
    for (index a = 0; a < m.attachments.count; ++a) {
        const index i = m.attachments.particle[a];
        for (int part = 0; part < kBoundParts; ++part) {
            const double row = std::sqrt(w[kBoundParts * a + part]) *
                               root_sum[kBoundParts * i + part] * m.particles.inv_mass[i];
            bound[part] = std::max(bound[part], row);
        }
    }
}

/// c / k [s] of the attachments with k > 0 folded into [lo, hi]; pure_damper set by one
/// with c > 0 and k = 0.
inline void damping_ratios(const Model& m, double& lo, double& hi, bool& pure_damper) {
    for (index a = 0; a < m.attachments.count; ++a) {
        const double k = m.attachments.stiffness[a], c = m.attachments.damping[a];
        if (k > 0.0) {
            lo = std::min(lo, c / k);
            hi = std::max(hi, c / k);
        } else if (k == 0.0 && c > 0.0) {
            pure_damper = true;
        }
    }
}

/// XPBD's pass over the attachments (ConstraintPass): each a distance constraint
/// |x_i - anchor| - L0 (springs::xpbd_delta) moving its particle alone; the anchor is
/// Control's, fixed over the call. Pinned particles have none.
inline void constrain(const Model& m, const Control& c, const ConstraintPass& p) {
    const double* inv = m.particles.inv_mass;
    for (index a = 0; a < m.attachments.count; ++a) {
        const index i = m.attachments.particle[a];
        if (inv[i] == 0.0) continue;
        double* row = p.rows + kRow * i;  // the iterate, then the substep's start
        const V3 d = load(row, 0) - load(c.attachment_anchor, a);
        const double length = std::sqrt(dot(d, d));
        if (length == 0.0) continue;
        const V3 u = (1.0 / length) * d;
        const V3 e = load(row, 0) - load(row, 1);
        const double dl = p.relaxation * springs::xpbd_delta(
            length - m.attachments.rest_length[a], p.attachment_lambda[a], dot(u, e),
            m.attachments.stiffness[a], m.attachments.damping[a], p.h, inv[i]);
        p.attachment_lambda[a] += dl;
        add_to(row, 0, (inv[i] * dl) * u);
    }
}

/// The registered term (terms/registry.hpp): its forms for the solvers.
struct Term : TermBase {
    static constexpr const char* kName = "attachments";
    static constexpr bool kProjected = true, kEnergy = true, kConstraint = true;
    static constexpr bool kBound = true, kSharedRows = true, kFromOutside = true;
    static constexpr bool kSpectral = true;
    static bool active(const Model& m, const Control&) { return m.attachments.count > 0; }
    /// The stability estimate: R_i at the tied particles (shared with the springs' rows),
    /// then the attachments' rows against them and their c / k; anchors from c.
    static void add_row_sums(const Model& m, const Control& c, const double* q,
                             const BoundScratch& s) {
        std::vector<double> w(static_cast<size_t>(springs::kBoundParts * m.attachments.count));
        bound_weights(m, c, q, w.data());
        add_root_sums(m, w.data(), s.root_sum);
    }
    static void bound(const Model& m, const Control& c, const double* q, const BoundScratch& s,
                      TermBound& out) {
        std::vector<double> w(static_cast<size_t>(springs::kBoundParts * m.attachments.count));
        bound_weights(m, c, q, w.data());
        row_bounds(m, w.data(), s.root_sum, out.parts);
        damping_ratios(m, out.ratio_min, out.ratio_max, out.pure_dampers);
    }
    static void constrain(const Model& m, const Control& c, const ConstraintPass& p) {
        attachments::constrain(m, c, p);
    }
    static void force(const Eval& e, double* f) { attachments::force(e.m, e.c, e.q, e.qd, f); }
    static double energy(const Eval& e, double* body) { return energies(e.m, e.c, e.q, body); }
    static void jacobian_product(const Model& m, const Control& c, const Linearization& l,
                                 double alpha_c, double alpha_k, const double* p, double* out) {
        attachments::jacobian_product(m, c, l.q, alpha_c, alpha_k, p, out);
    }
    /// The estimate's split, computed at l.q as the product goes (no linearisation).
    static void spectral_product(const Model& m, const Control& c, const Linearization& l,
                                 StiffnessPart part, const double* p, double* out) {
        attachments::spectral_product(m, c, l.q, part, p, out);
    }
    static void add_smoother_blocks(const Model& m, const Control& c, const Linearization& l,
                                    const SmootherBlocks& s) {
        attachments::add_smoother_blocks(m, c, s.h, l.q, s.block);
    }
    static void project(const Model& m, const Control& c, double h, const double* x,
                        const double* x0, double* rhs) {
        attachments::project(m, c, h, x, x0, rhs);
    }
};

}  // namespace softbody::SOFTBODY_KERNELS::attachments
