// Damped springs tying particles to anchor points (the paper's hanging ball). The anchors
// come from Control and do not move during a step. Force on particle i with
// u = (anchor - x_i) / L: [k (L - L0) - c v_i . u] u.
#pragma once

#include "model.hpp"
#include "terms/springs.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::attachments {

/// Accumulate the attachment forces into f (N, 3) [N].
inline void force(const Model& m, const Control& c, const double* q, const double* qd,
                  double* f) {
    for (index a = 0; a < m.attachment_count; ++a) {
        const index i = m.attachment_particle[a];
        const V3 d = load(c.attachment_anchor, a) - load(q, i);
        const double length = std::sqrt(dot(d, d));
        if (length == 0.0) continue;
        const V3 u = (1.0 / length) * d;
        const double rel = -dot(load(qd, i), u);
        const double mag = m.attachment_stiffness[a] * (length - m.attachment_rest_length[a]) +
                           m.attachment_damping[a] * rel;
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
    for (index a = 0; a < m.attachment_count; ++a) {
        const index i = m.attachment_particle[a];
        if (m.particle_inv_mass[i] == 0.0) continue;
        const V3 anchor = load(c.attachment_anchor, a);
        const double k = m.attachment_stiffness[a], c_h = m.attachment_damping[a] * inv_h;
        const V3 t = springs::projection(load(x, i) - anchor, load(x0, i) - anchor,
                                         m.attachment_rest_length[a], k, c_h);
        add_to(rhs, i, (k + c_h) * anchor + t);
    }
}

/// out += alpha_c C p + alpha_k K p: per attachment -(k_iso p_i + ((k - k_iso) u.p) u) with
/// k_iso = k max(0, 1 - L0/L), and -c (u.p) u for the damping.
inline void jacobian_product(const Model& m, const Control& c, const double* q, double alpha_c,
                             double alpha_k, const double* p, double* out) {
    for (index a = 0; a < m.attachment_count; ++a) {
        const index i = m.attachment_particle[a];
        const V3 d = load(c.attachment_anchor, a) - load(q, i);
        const double length = std::sqrt(dot(d, d));
        const double k = m.attachment_stiffness[a];
        double iso = k, ud = 0.0;
        V3 u{0.0, 0.0, 0.0};
        if (length != 0.0) {
            u = (1.0 / length) * d;
            iso = k * std::max(0.0, 1.0 - m.attachment_rest_length[a] / length);
            ud = dot(u, load(p, i));
        }
        const double axial = alpha_k * (k - iso) * ud + alpha_c * m.attachment_damping[a] * ud;
        const V3 pi = load(p, i);
        out[3 * i] -= alpha_k * iso * pi.x + axial * u.x;
        out[3 * i + 1] -= alpha_k * iso * pi.y + axial * u.y;
        out[3 * i + 2] -= alpha_k * iso * pi.z + axial * u.z;
    }
}

/// The attachments' share of the implicit system's diagonal blocks (N, 3, 3) at q for step
/// h [s]: per attachment h^2 (k_iso I + (k - k_iso) u u^T) + h c u u^T, added to its particle's.
inline void add_smoother_blocks(const Model& m, const Control& c, double h, const double* q,
                                double* block) {
    for (index a = 0; a < m.attachment_count; ++a) {
        const index i = m.attachment_particle[a];
        const V3 dv = load(c.attachment_anchor, a) - load(q, i);
        const double d[3] = {dv.x, dv.y, dv.z};
        const double length = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        const double k = m.attachment_stiffness[a];
        const double iso =
            length == 0.0 ? k : k * std::max(0.0, 1.0 - m.attachment_rest_length[a] / length);
        const double alpha = h * m.attachment_damping[a] + h * h * (k - iso);
        double* b = block + 9 * i;
        for (int r = 0; r < 3; ++r) {
            for (int col = 0; col < 3; ++col)
                if (length > 0.0) b[3 * r + col] += alpha * d[r] * d[col] / (length * length);
            b[4 * r] += h * h * iso;
        }
    }
}

}  // namespace softbody::SOFTBODY_KERNELS::attachments
