// Aerodynamic drag on the faces of bodies (quadratic, per face, in a uniform wind).
//
// Face t with corners i, j, k, area A_t, unit normal n_t (the winding's) and velocity
// v_t = (v_i + v_j + v_k) / 3 moves through air of density rho [kg/m^3] at velocity
// v_rel = v_t - wind [m/s] relative to it and feels
//     F_t = -1/2 rho C_d A_t (v_rel . n_t) |v_rel . n_t| n_t,
// the dynamic pressure 1/2 rho (v_rel . n)^2 on the face's projected area, against its
// normal motion whichever side faces the flow: the front of a body is pushed, its back is
// pulled (suction), pi R^2 / 2 each on a sphere of radius R, so a sphere's drag is
// 1/2 rho C_d |v|^2 pi R^2, the usual definition on the frontal area (tests/test_drag.py
// derives it). F_t is shared equally by the three corners. C_d [1] is per body.
//
// Forms: face_force, force, power. No Jacobian, projection or stiffness bound: every
// solver takes drag explicitly, and the stability estimate leaves it out (its damping
// bound, below). Drag is dissipative: it has no energy (power, for diagnostics, instead).
// The power it delivers is
//     P = sum_i F_i . v_i = sum_t F_t . v_t
//       = -sum_t 1/2 rho C_d A_t |v_rel . n_t|^3 + sum_t F_t . wind,
// never positive in still air (the wind can do work on a body).
//
// Damping bound for the stable step. Along the face normal dF_t/dv_t = -rho C_d A_t
// |v_rel . n_t| n_t n_t^T (the derivative of s |s| / 2 is |s|), and v_t and the force shares
// are thirds, so the block between corners a and b of face t is
//     dF_a/dv_b = -1/9 rho C_d A_t |v_rel . n_t| n_t n_t^T.
// Its Gershgorin row sum bounds the damping rate that drag adds to particle i:
//     gamma_i <= sum_{t at i} 1/3 rho C_d A_t |v_rel| / m_i   [1/s],
// about rho C_d A_surface |v_rel| / m for a body of uniform particles (each face touches
// three of them). Explicit Euler and midpoint stay stable for dt < 2 / gamma; a balloon of
// 5 g and radius 0.2 m with C_d = 0.5 at its terminal 1.6 m/s has gamma ~ 1e2 1/s, far
// below its spring modes, which is why the stability estimate leaves drag out.
#pragma once

#include "model.hpp"
#include "terms/term.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::drag {

/// Whether the term acts: air of density > 0 and some body with C_d > 0.
inline bool active(const Model& m) {
    if (!(m.drag.air_density > 0.0)) return false;
    for (index b = 0; b < m.bodies.count; ++b)
        if (m.drag.coefficient[b] > 0.0) return true;
    return false;
}

/// F_t [N] of triangle t at q, qd (N, 3) in the wind [m/s]; half_rho_cd = 1/2 rho C_d
/// [kg/m^3]. With a = A_t n_t (half the edges' cross product) and s = v_rel . a = A_t v_n,
/// F_t = -1/2 rho C_d A_t v_n |v_n| n_t = -1/2 rho C_d s |s| a / |a|^2: no square root.
/// A degenerate face (zero area) has no normal and feels nothing.
inline V3 face_force(const Model& m, index t, const double* q, const double* qd, V3 wind,
                     double half_rho_cd) {
    const index i = m.triangles.indices[3 * t], j = m.triangles.indices[3 * t + 1],
                k = m.triangles.indices[3 * t + 2];
    const V3 xi = load(q, i);
    const V3 a = 0.5 * cross(load(q, j) - xi, load(q, k) - xi);  // A_t n_t [m^2]
    const double a2 = dot(a, a);
    if (a2 == 0.0) return {0.0, 0.0, 0.0};
    const V3 v_rel = (1.0 / 3.0) * (load(qd, i) + load(qd, j) + load(qd, k)) - wind;
    const double s = dot(v_rel, a);  // [m^3/s]
    return (-half_rho_cd * s * std::abs(s) / a2) * a;
}

/// f (N, 3) [N] += each face's drag, a third on each corner, for bodies with C_d > 0.
/// Nothing at all when the model has no drag (active() false).
inline void force(const Model& m, const Control& c, const double* q, const double* qd,
                  double* f) {
    if (!active(m)) return;
    const V3 wind{c.wind[0], c.wind[1], c.wind[2]};
    for (index b = 0; b < m.bodies.count; ++b) {
        const double cd = m.drag.coefficient[b];
        if (cd == 0.0) continue;
        const double half_rho_cd = 0.5 * m.drag.air_density * cd;
        for (index t = m.bodies.tri_range[2 * b]; t < m.bodies.tri_range[2 * b + 1]; ++t) {
            const V3 share = (1.0 / 3.0) * face_force(m, t, q, qd, wind, half_rho_cd);
            for (int corner = 0; corner < 3; ++corner)
                add_to(f, m.triangles.indices[3 * t + corner], share);
        }
    }
}

/// The power [W] drag delivers to the particles, sum_t F_t . v_t (<= 0 in still air): for
/// diagnostics, since drag has no energy to track.
inline double power(const Model& m, const Control& c, const double* q, const double* qd) {
    if (!active(m)) return 0.0;
    const V3 wind{c.wind[0], c.wind[1], c.wind[2]};
    double total = 0.0;
    for (index b = 0; b < m.bodies.count; ++b) {
        const double cd = m.drag.coefficient[b];
        if (cd == 0.0) continue;
        const double half_rho_cd = 0.5 * m.drag.air_density * cd;
        for (index t = m.bodies.tri_range[2 * b]; t < m.bodies.tri_range[2 * b + 1]; ++t) {
            const index i = m.triangles.indices[3 * t], j = m.triangles.indices[3 * t + 1],
                        k = m.triangles.indices[3 * t + 2];
            const V3 v = (1.0 / 3.0) * (load(qd, i) + load(qd, j) + load(qd, k));
            total += dot(face_force(m, t, q, qd, wind, half_rho_cd), v);
        }
    }
    return total;
}

/// The registered term (terms/registry.hpp): a force every solver takes explicitly.
struct Term : TermBase {
    static constexpr const char* kName = "drag";
    static constexpr bool kFromOutside = true;  // the air
    static bool active(const Model& m, const Control&) { return drag::active(m); }
    static void force(const Eval& e, double* f) { drag::force(e.m, e.c, e.q, e.qd, f); }
};

}  // namespace softbody::SOFTBODY_KERNELS::drag
