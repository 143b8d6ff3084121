// The registered terms' forms summed over the registry (terms/registry.hpp), in its order:
// what every solver, the diagnostics and the stability estimate call. Nothing here names a
// term: a new term is one line in the registry and its own file.
#pragma once

#include <algorithm>

#include "model.hpp"
#include "solvers/lanes.hpp"
#include "terms/registry.hpp"

namespace softbody::SOFTBODY_KERNELS::forms {

/// Which terms' forces eval_forces sums.
enum class Which {
    kAll,        // every term (explicit and implicit schemes)
    kBody,       // the lane terms only (kLane: what the fused symplectic pass starts from)
    kUnprojected, // all but the kProjected terms (projective dynamics: their projections
                  // stand for them in its global step)
    kUnconstrained // all but the kConstraint terms (XPBD: their constraint pass stands for
                   // them; solvers/substep.hpp)
};

/// Forces at time t [s] for q, qd (N, 3) into f (N, 3) [N], the gas state into gas. With
/// SIMD lanes (or threads) the lane terms' forces, dV/dx and the exact volumes come from
/// the vertex-major pass (its springs and membranes left out for kUnprojected, its springs
/// for kUnconstrained); on the scalar path every
/// term's edge-major force, each spring and face once (half the arithmetic, which pays
/// without lanes). Then every term's update (the gas: the other volumes, the pressures),
/// then the remaining forces in registry order. The same terms either way; the sums run in
/// another order, so the paths agree to round-off.
template <Which kWhich = Which::kAll>
inline void eval_forces(const Model& m, const Control& c, double t, const double* q,
                        const double* qd, const BodyGas& gas, const LaneBuffers& lanes,
                        double* f) {
    const bool pass = lanes::use_vertex_pass(lanes);
    if (pass)
        lanes::vertex_pass<kWhich != Which::kUnprojected && kWhich != Which::kUnconstrained,
                           kWhich != Which::kUnprojected>(m, q, qd, gas, lanes, f);
    else
        std::fill(f, f + 3 * m.particles.count, 0.0);
    const Eval e{m, c, t, q, qd, gas};
    Terms::each([&](auto term, int) { decltype(term)::update(e, pass); });
    Terms::each([&](auto term, int) {
        using T = decltype(term);
        if (pass && T::kLane) return;                              // the pass gave it
        if (kWhich == Which::kBody && !T::kLane) return;           // the fused pass adds it
        if (kWhich == Which::kUnprojected && T::kProjected) return;  // in the global step
        if (kWhich == Which::kUnconstrained && T::kConstraint) return;  // XPBD's constraints
        T::force(e, f);
    });
}

/// Every term's per-evaluation state at e (the gas: volumes, dV/dx where e.gas asks, and
/// pressures), with no force.
inline void update(const Eval& e) {
    Terms::each([&](auto term, int) { decltype(term)::update(e, false); });
}

/// Whether every term that acts in this call with a force is one the fused symplectic
/// pass covers (the flows move gas, which that pass's loop steps itself); `pass`: the
/// vertex-major pass runs (kFusedInPass terms count then).
inline bool all_fused(const Model& m, const Control& c, bool pass) {
    bool fused = true;
    Terms::each([&](auto term, int) {
        using T = decltype(term);
        if (!T::kFused && !(pass && T::kFusedInPass) && !T::kFlow && T::active(m, c))
            fused = false;
    });
    return fused;
}

/// Every term's linearisation at e (l.q the point, e.gas the gas state there).
inline void prepare(const Eval& e, const Linearization& l) {
    Terms::each([&](auto term, int) { decltype(term)::prepare(e, l); });
}

/// out (N, 3) = alpha_m M p + alpha_c C p + alpha_k K p for p (N, 3) at the linearisation l
/// (C = df/dv, K = df/dx); terms whose bit is set in `skip` are left out.
inline void apply_jacobians(const Model& m, const Control& c, const Linearization& l,
                            double alpha_m, double alpha_c, double alpha_k, const double* p,
                            double* out, unsigned skip = 0) {
    for (index i = 0; i < m.particles.count; ++i) {
        const double w = alpha_m * m.particles.mass[i];
        for (int k = 0; k < 3; ++k) out[3 * i + k] = w * p[3 * i + k];
    }
    Terms::each([&](auto term, int k) {
        if (!(skip & (1u << k)))
            decltype(term)::jacobian_product(m, c, l, alpha_c, alpha_k, p, out);
    });
}

/// The smoother's diagonal blocks of M - h C - h^2 K: m I, then each term's share.
inline void smoother_blocks(const Model& m, const Control& c, const Linearization& l,
                            const SmootherBlocks& s) {
    for (index i = 0; i < m.particles.count; ++i) {
        double* d = s.block + 9 * i;
        for (int k = 0; k < 9; ++k) d[k] = 0.0;
        d[0] = d[4] = d[8] = m.particles.mass[i];
    }
    Terms::each([&](auto term, int) { decltype(term)::add_smoother_blocks(m, c, l, s); });
}

/// Projective dynamics' local step: every projected term's part of the right-hand side
/// rhs (N, 3) at the iterate x, its start x0 (N, 3), step h [s].
inline void project(const Model& m, const Control& c, double h, const double* x,
                    const double* x0, double* rhs) {
    Terms::each([&](auto term, int) { decltype(term)::project(m, c, h, x, x0, rhs); });
}

/// XPBD's set-up for a substep p.h: every kConstraint term's prepare_constraints form.
inline void prepare_constraints(const Model& m, const Control& c, const ConstraintPass& p) {
    Terms::each([&](auto term, int) {
        using T = decltype(term);
        if (T::kConstraint) T::prepare_constraints(m, c, p);
    });
}

/// XPBD's constraint pass: every kConstraint term's constrain form, in registry order.
inline void constrain(const Model& m, const Control& c, const ConstraintPass& p) {
    Terms::each([&](auto term, int) {
        using T = decltype(term);
        if (T::kConstraint) T::constrain(m, c, p);
    });
}

/// Every term's energy at e: total[k] [J] for term k, and its bodies' shares in
/// body + k B (B,) (zeroed first). Terms without an energy give 0.
inline void energies(const Eval& e, double* total, double* body) {
    const index bodies = e.m.bodies.count;
    std::fill(body, body + Terms::count * bodies, 0.0);
    Terms::each([&](auto term, int k) {
        total[k] = decltype(term)::energy(e, body + k * bodies);
    });
}

}  // namespace softbody::SOFTBODY_KERNELS::forms
