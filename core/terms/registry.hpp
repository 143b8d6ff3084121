// The registered physics terms, one line each, in the order every solver sums them: their
// forces into the accumulator, their Jacobian products, smoother blocks, projections and
// energies. The order is part of the results (floating-point sums), so a run repeats bit
// for bit; a new term goes where its sums should fall (usually last). Solvers, kernels.cpp
// and the bindings iterate this list and never name a term (terms/term.hpp: the forms).
#pragma once

#include "terms/attachments.hpp"
#include "terms/bending.hpp"
#include "terms/drag.hpp"
#include "terms/external.hpp"
#include "terms/flows.hpp"
#include "terms/gas.hpp"
#include "terms/gravity.hpp"
#include "terms/membrane.hpp"
#include "terms/springs.hpp"
#include "terms/term.hpp"

namespace softbody::SOFTBODY_KERNELS {

template <class... T>
struct TermList {
    static constexpr int count = sizeof...(T);
    /// f(Term{}, position) for every term, in order.
    template <class F>
    static void each(F&& f) {
        int position = 0;
        (f(T{}, position++), ...);
    }
};

using Terms = TermList<
    gravity::Term,      // weight m g
    springs::Term,      // damped Hooke springs: edges, bending, user springs
    gas::Term,          // the gas law's pressure on the faces
    attachments::Term,  // springs to anchor points Control moves
    external::Term,     // per-particle forces from Control
    external::GrabTerm, // a grabbed particle pulled to a target
    drag::Term,         // air drag on faces
    bending::Term,      // discrete-shell bending on interior edges
    membrane::Term,     // triangle membranes: hyperelastic sheets
    flows::VentTerm,    // gas out of (or into) a body through vents
    flows::OrificeTerm, // gas between two bodies
    flows::InflatorTerm,// gas delivered by inflators
    flows::LeakTerm>;   // gas through the fabric

/// Each term's traits (terms/term.hpp) in registry order (softbody._core.term_table).
inline const TermTraits* term_traits() {
    static TermTraits traits[Terms::count];
    Terms::each([](auto term, int k) {
        using T = decltype(term);
        traits[k] = {T::kName,   T::kLane,     T::kProjected, T::kFused,
                     T::kEnergy, T::kExternal, T::kFlow,      T::kBound,
                     T::kSharedRows, T::kVolumeMode, T::kStencil ? T::kStencilWidth : 0};
    });
    return traits;
}

}  // namespace softbody::SOFTBODY_KERNELS
