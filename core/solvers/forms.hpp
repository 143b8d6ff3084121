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

/// l with the scratch of the term at registry position k as its own.
inline Linearization own(const Linearization& l, int k) {
    Linearization o = l;
    o.own = l.scratch != nullptr ? l.scratch[k] : nullptr;
    return o;
}

/// Every term's linearisation at e (l.q the point, e.gas the gas state there), into its
/// own scratch.
inline void prepare(const Eval& e, const Linearization& l) {
    Terms::each([&](auto term, int k) { decltype(term)::prepare(e, own(l, k)); });
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
            decltype(term)::jacobian_product(m, c, own(l, k), alpha_c, alpha_k, p, out);
    });
}

/// The stability estimate's linearisation at l.q: every kSpectral term's prepare_spectral
/// (from the estimate's state w, after the bound forms), every other term's prepare at e
/// (its state at l.q), each into its own scratch.
inline void prepare_spectral(const Eval& e, const BoundScratch& w, const Linearization& l) {
    Terms::each([&](auto term, int k) {
        using T = decltype(term);
        if constexpr (T::kSpectral)
            T::prepare_spectral(e, w, own(l, k));
        else
            T::prepare(e, own(l, k));
    });
}

/// out (N, 3) = the part `part` of K p (or C p, StiffnessPart::kDamping) for p (N, 3) at the
/// estimate's linearisation l, summed over the terms in registry order: each kSpectral
/// term's split, each other term's whole K (its C for the damping part).
inline void spectral_product(const Model& m, const Control& c, const Linearization& l,
                             StiffnessPart part, const double* p, double* out) {
    std::fill(out, out + 3 * m.particles.count, 0.0);
    const bool damping = part == StiffnessPart::kDamping;
    Terms::each([&](auto term, int k) {
        using T = decltype(term);
        if constexpr (T::kSpectral)
            T::spectral_product(m, c, own(l, k), part, p, out);
        else
            T::jacobian_product(m, c, own(l, k), damping ? 1.0 : 0.0, damping ? 0.0 : 1.0, p,
                                out);
    });
}

/// The smoother's blocks of M - h C - h^2 K for step h [s]: its diagonal blocks into block
/// (N, 3, 3), m I then each term's share, and each kStencil term's blocks between
/// particles into its stencil (stencils: by registry position).
inline void smoother_blocks(const Model& m, const Control& c, const Linearization& l, double h,
                            double* block, const Stencil* stencils) {
    for (index i = 0; i < m.particles.count; ++i) {
        double* d = block + 9 * i;
        for (int k = 0; k < 9; ++k) d[k] = 0.0;
        d[0] = d[4] = d[8] = m.particles.mass[i];
    }
    Terms::each([&](auto term, int k) {
        using T = decltype(term);
        SmootherBlocks s;
        s.h = h;
        s.block = block;
        if (T::kStencil) s.entries = stencils[k];
        T::add_smoother_blocks(m, c, own(l, k), s);
    });
}

/// Which of particle i's smoother entries add_entries sums: those to particles j < i, to
/// j > i (entries are sorted by j; none is i's own), or all.
enum class Span { kEarlier, kLater, kAll };

/// s += every kStencil term's entries of particle i (the span's) times x_j, in registry
/// order (stencils: by registry position).
template <Span kSpan>
inline void add_entries(const Stencil* stencils, const double* x, index i, V3& s) {
    Terms::each([&](auto term, int k) {
        using T = decltype(term);
        if constexpr (T::kStencil) {
            const Stencil& st = stencils[k];
            index first = st.ptr[i], last = st.ptr[i + 1];
            if (kSpan != Span::kAll) {
                index e = first;
                while (e < last && st.neighbor[e] < i) ++e;
                if (kSpan == Span::kEarlier)
                    last = e;
                else
                    first = e;
            }
            T::add_entries(st, x, first, last, s);
        }
    });
}

/// The Jacobi preconditioner's diagonal diag (N,) [kg] of M - h C - h^2 K at the
/// linearisation l: m, then each term's share.
inline void jacobi_diagonal(const Model& m, const Control& c, const Linearization& l, double h,
                            double* diag) {
    for (index i = 0; i < m.particles.count; ++i) diag[i] = m.particles.mass[i];
    Terms::each([&](auto term, int k) {
        decltype(term)::add_jacobi_diagonal(m, c, own(l, k), h, diag);
    });
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
