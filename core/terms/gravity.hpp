// Uniform gravity: f_i = m_i g. Energy -m_i g . x_i; no Jacobian (constant force).
//
// Forms: force, lane_force (the vertex-major pass), energies (per body). No Jacobian
// product, smoother block, projection or stiffness bound: a constant force, which every
// solver takes as it is (projective dynamics explicitly within its iteration).
#pragma once

#include "model.hpp"
#include "simd.hpp"
#include "terms/term.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::gravity {

/// f (N, 3) [N] += m_i g.
inline void force(const Model& m, double* f) {
    const double gx = m.gravity.acceleration[0], gy = m.gravity.acceleration[1], gz = m.gravity.acceleration[2];
    for (index i = 0; i < m.particles.count; ++i) {
        const double mass = m.particles.mass[i];
        f[3 * i] += mass * gx;
        f[3 * i + 1] += mass * gy;
        f[3 * i + 2] += mass * gz;
    }
}

/// Vertex-major: m g for kLanes particles from `first` [N] (initialises the lanes).
inline void lane_force(const Model& m, index first, vd& fx, vd& fy, vd& fz) {
    const vd mass = load_lanes(m.slots.mass + first);
    fx = mass * m.gravity.acceleration[0];
    fy = mass * m.gravity.acceleration[1];
    fz = mass * m.gravity.acceleration[2];
}

/// Potential energy -m_i g . x_i [J] of every particle at q (N, 3), each added to its
/// body's entry of body_energy (B,) (a free particle's counts in the total only); returns
/// the total [J]. Pinned particles count too: their weight is balanced, not absent.
inline double energies(const Model& m, const double* q, double* body_energy) {
    const double gx = m.gravity.acceleration[0], gy = m.gravity.acceleration[1], gz = m.gravity.acceleration[2];
    double total = 0.0;
    for (index i = 0; i < m.particles.count; ++i) {
        const double e =
            -m.particles.mass[i] * (q[3 * i] * gx + q[3 * i + 1] * gy + q[3 * i + 2] * gz);
        total += e;
        if (m.particles.body[i] >= 0) body_energy[m.particles.body[i]] += e;
    }
    return total;
}

/// The registered term (terms/registry.hpp).
struct Term : TermBase {
    static constexpr const char* kName = "gravity";
    static constexpr bool kLane = true, kFused = true, kEnergy = true;
    static void force(const Eval& e, double* f) { gravity::force(e.m, f); }
    static double energy(const Eval& e, double* body) { return energies(e.m, e.q, body); }
};

}  // namespace softbody::SOFTBODY_KERNELS::gravity
