// Forces given from outside each call through Control: per-particle forces, and a damped
// grab spring pulling one particle toward a target (interactive use).
//
// Forms: force (Control.particle_f: given, with no energy, Jacobian or bound); grab_force,
// grab_energy (1/2 k |target - x_g|^2, which softbody.diagnostics leaves out: the hand
// does work), grab_jacobian_product and add_grab_block (the implicit solvers). The grab
// is no part of the stability estimate, which describes the model, not the interaction.
#pragma once

#include "model.hpp"
#include "terms/term.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::external {

/// f += Control.particle_f (N, 3) [N].
inline void force(const Model& m, const Control& c, double* f) {
    const index n = 3 * m.particles.count;
    for (index k = 0; k < n; ++k) f[k] += c.particle_f[k];
}

/// f_g += k (target - x_g) - c v_g for the grabbed particle g (none when g < 0).
inline void grab_force(const Control& c, const double* q, const double* qd, double* f) {
    const index g = c.grab_particle;
    if (g < 0) return;
    for (int k = 0; k < 3; ++k)
        f[3 * g + k] +=
            c.grab_stiffness * (c.grab_target[k] - q[3 * g + k]) - c.grab_damping * qd[3 * g + k];
}

/// out += alpha_c C p + alpha_k K p of the grab spring: -(alpha_k k + alpha_c c) p_g.
inline void grab_jacobian_product(const Control& c, double alpha_c, double alpha_k,
                                  const double* p, double* out) {
    const index g = c.grab_particle;
    if (g < 0) return;
    for (int k = 0; k < 3; ++k)
        out[3 * g + k] -= (alpha_k * c.grab_stiffness + alpha_c * c.grab_damping) * p[3 * g + k];
}

/// The grab spring's share of the implicit system's diagonal blocks (N, 3, 3) for step
/// h [s]: (h^2 k + h c) I on the grabbed particle.
inline void add_grab_block(const Control& c, double h, double* block) {
    const index g = c.grab_particle;
    if (g < 0) return;
    for (int r = 0; r < 3; ++r) block[9 * g + 4 * r] += h * h * c.grab_stiffness + h * c.grab_damping;
}

/// Elastic energy 1/2 k |target - x_g|^2 [J] of the grab spring at q (0 when nothing is
/// grabbed). softbody.diagnostics.energies leaves it out: the user's hand does work on the
/// body, and Control.particle_f, given from outside each call, has no energy at all.
inline double grab_energy(const Control& c, const double* q) {
    const index g = c.grab_particle;
    if (g < 0) return 0.0;
    double e = 0.0;
    for (int k = 0; k < 3; ++k) {
        const double d = c.grab_target[k] - q[3 * g + k];
        e += d * d;
    }
    return 0.5 * c.grab_stiffness * e;
}

/// The registered terms (terms/registry.hpp): Control's per-particle forces, and the grab
/// spring (its energy is reported, and softbody.diagnostics leaves it out of the total).
struct Term : TermBase {
    static constexpr const char* kName = "external";
    static constexpr bool kFused = true;
    static void force(const Eval& e, double* f) { external::force(e.m, e.c, f); }
};

struct GrabTerm : TermBase {
    static constexpr const char* kName = "grab";
    static constexpr bool kEnergy = true, kExternal = true, kFromOutside = true;
    static bool active(const Model&, const Control& c) { return c.grab_particle >= 0; }
    static void force(const Eval& e, double* f) { grab_force(e.c, e.q, e.qd, f); }
    /// The grab spring's energy [J], added to the grabbed particle's body.
    static double energy(const Eval& e, double* body) {
        const double energy = grab_energy(e.c, e.q);
        if (e.c.grab_particle >= 0 && e.m.particles.body[e.c.grab_particle] >= 0)
            body[e.m.particles.body[e.c.grab_particle]] += energy;
        return energy;
    }
    static void jacobian_product(const Model&, const Control& c, const Linearization&,
                                 double alpha_c, double alpha_k, const double* p, double* out) {
        grab_jacobian_product(c, alpha_c, alpha_k, p, out);
    }
    static void add_smoother_blocks(const Model&, const Control& c, const Linearization&,
                                    const SmootherBlocks& s) {
        add_grab_block(c, s.h, s.block);
    }
};

}  // namespace softbody::SOFTBODY_KERNELS::external
