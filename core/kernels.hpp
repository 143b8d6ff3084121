// The entry points of the step kernels, one table per instruction set (kernels.cpp is
// compiled once per set; dispatch.cpp chooses a table for the CPU at run time).
#pragma once

#include <limits>
#include <string>
#include <vector>

#include "model.hpp"

namespace softbody {

/// Each registered term's energy at a state [J] (softbody.diagnostics.energies), in
/// registry order: its total over the model and each body's share (a free particle's
/// weight, a user's spring or an attachment of a free particle counts in the total only).
/// Terms without an energy (TermTraits::energy) give 0.
struct TermEnergies {
    double total[kMaxTerms] = {};
    double* body = nullptr;  // (terms, B): term k's shares at body + k B
};

/// The stability estimate's Gershgorin pieces (softbody.stability.stiffest_mode): every
/// registered term's own (its `bound` form, TermBound: by part, damped, transverse,
/// whole [1/s^2] and damping [1/s]; zero for a term without one), in registry order, and
/// the range of c / k [s] over them all.
struct StiffnessBounds {
    TermBound terms[kMaxTerms];
    // c / k [s]; +inf and -inf where no term has a damped part with k > 0
    double ratio_min = std::numeric_limits<double>::infinity();
    double ratio_max = -std::numeric_limits<double>::infinity();
    bool pure_dampers = false;  // some term has a damper with c > 0 and k = 0
};

struct KernelTable {
    const char* name;  // "scalar", "avx2", "avx512"
    int term_count;            // the registered terms (terms/registry.hpp)
    const TermTraits* terms;   // (term_count,) their names and traits, in registry order
    /// Advance a state by an explicit scheme (RunParams.scheme 0-4).
    RunResult (*simulate_explicit)(const Model&, const Control&, const RunParams&,
                                   const StateView&, const ExplicitBuffers&);
    /// Advance a state by backward Euler or BDF2; mg is the multigrid hierarchy, or null
    /// for the Jacobi preconditioner.
    RunResult (*simulate_implicit)(const Model&, const Control&, const RunParams&,
                                   const ImplicitParams&, const StateView&,
                                   const ImplicitBuffers&, const MultigridView* mg);
    /// z = P^-1 r for r, z (N, 3): the implicit solve's preconditioner for step h with its
    /// blocks at w.q0 at time t (w.gas refreshed there); mg null: Jacobi. With contacts
    /// (not null), the thickness contacts' pairs near at w.q0 (as a step from rest of h
    /// takes them, gathered in those buffers) in it too.
    void (*apply_preconditioner)(const Model&, const Control&, double t, double h,
                                 const ImplicitBuffers& w, const MultigridView* mg,
                                 const double* r, double* z, const ContactBuffers* contacts);
    /// z = V(r) for r, z (N, 3): one V-cycle of the Laplacian hierarchy from z = 0.
    void (*apply_multigrid)(const MultigridView& mg, const double* r, double* z);
    /// Advance a state by projective dynamics (p.iterations per step) on factor `a`,
    /// built for p.dt.
    RunResult (*simulate_projective)(const Model&, const Control&, const RunParams&,
                                     const StateView&, const Factor& a,
                                     const ProjectiveBuffers&);
    /// Advance a state by XPBD with small steps (p.substeps per step, p.iterations
    /// constraint passes each; solvers/substep.hpp).
    RunResult (*simulate_substep)(const Model&, const Control&, const RunParams&,
                                  const StateView&, const SubstepBuffers&);
    /// out = A^-1 b for b, out (N, 3): projective dynamics' two triangular solves on the
    /// factor a; x (N, 3) scratch.
    void (*projective_solve)(const Factor& a, const double* b, double* x, double* out);
    /// All forces f (N, 3) [N] at time t for q, qd (N, 3); refreshes gas.
    void (*eval_forces)(const Model&, const Control&, double t, const double* q,
                        const double* qd, const BodyGas& gas, const LaneBuffers& lanes,
                        double* f);
    /// Volumes (and, with gas.volume_gradient set, dV/dx) and pressures at time t.
    void (*eval_gas)(const Model&, const Control&, double t, const double* q,
                     const BodyGas& gas);
    /// Volumes alone into gas.volume (B,) (bounds into gas.lo/hi); reads only the model's
    /// topology, volume methods and Monte Carlo samples.
    void (*eval_volumes)(const Model&, const double* q, const BodyGas& gas);
    /// out = alpha_m M p + alpha_c C p + alpha_k K p for p (N, 3) at the linearisation l
    /// (C = df/dv, K = df/dx), every registered term's product but those with their bit
    /// (registry position) set in `skip`.
    void (*apply_jacobians)(const Model&, const Control&, const Linearization& l,
                            const double* p, double alpha_m, double alpha_c, double alpha_k,
                            unsigned skip, double* out);
    /// One pass of the soft-soft contacts (the model's mode) on q, qd (N, 3) in place;
    /// returns the hash entries the surface contacts needed (0 if they fit, or none).
    index (*soft_contacts)(const Model&, double* q, double* qd, const ContactBuffers& w);
    /// Every registered term's energy at q and time t (TermEnergies), each body's gas at
    /// its volume by its own method (into gas.volume, with gas.lo/hi as scratch).
    void (*eval_energies)(const Model&, const Control&, double t, const double* q,
                          const BodyGas& gas, TermEnergies& out);
    /// The molar flows [mol/s] into and out of each body's gas (gas.flow_in, flow_in_t,
    /// flow_out) at time t, positions q, amounts moles (B,) [mol], temperatures (B,) [K]
    /// and vent latches (V,), by the flow terms' laws without the step limiter.
    void (*eval_flows)(const Model&, const Control&, double t, const double* q,
                       const double* moles, const double* temperature, const double* vent_open,
                       const BodyGas& gas);
    /// Bit k set: registered term k acts in a call with model m and control c.
    unsigned (*active_terms)(const Model& m, const Control& c);
    /// Every registered term's linearisation at l.q and time t (its prepare form, into
    /// l.scratch), after the terms' state there (gas: volumes, pressures and, where
    /// gas.volume_gradient is set, dV/dx).
    void (*prepare)(const Model&, const Control&, double t, const BodyGas& gas,
                    const Linearization& l);
    /// The stability estimate's linearisation at l.q (forms::prepare_spectral): each term's
    /// from the estimate's state w (stiffness_bounds' at l.q), the terms' state at l.q and
    /// time 0 into gas first.
    void (*prepare_spectral)(const Model&, const Control&, const BodyGas& gas,
                             const BoundScratch& w, const Linearization& l);
    /// out (N, 3) = the part `part` of K p (C p for the damping part) at the estimate's
    /// linearisation l, for p (N, 3): every registered term's split (forms::spectral_product).
    void (*spectral_product)(const Model&, const Control&, const Linearization& l,
                             StiffnessPart part, const double* p, double* out);
    /// How many doubles of scratch registered term `term` keeps for its linearisation in a
    /// model (Linearization::scratch; 0: none).
    index (*linearization_size)(int term, const Model& m);
    /// Whether a smoother stencil fits registered term `term` (a kStencil term) of model
    /// m: its map (map_length entries, s.map) checked by the term (ptr and neighbor are
    /// checked by the caller); null when it fits, else what is wrong.
    const char* (*check_stencil)(int term, const Model& m, const Stencil& s, index map_length);
    /// The stability estimate's Gershgorin pieces at q, attachments at c's anchors
    /// (w: scratch, and the gas's state at the estimate, BoundScratch).
    StiffnessBounds (*stiffness_bounds)(const Model&, const Control&, const double* q,
                                        const BoundScratch& w);
    /// The thickness contacts' candidate pairs at q (N, 3), gathered as the pair list's
    /// build gathers them (collision/thick.hpp): every vertex-triangle and edge-edge pair
    /// nearer than `radius` [m] (adjacent ones, and a body's own without self-contact, left
    /// out) into w.pairs' rows; returns their count, -1 for a crossing at q (w.crossing), or
    /// below -1 when a buffer could not grow to them. With q_end (N, 3; else null): the
    /// candidates of a step from q to q_end as the stage's swept gather finds them (its
    /// boxes grown by `radius` [m], as the stage's by the margin); with q_later (N, 3; else
    /// null) too, that gather made with slack [m] (Stage::slack), then a later pass's from
    /// its rows to q_later (reuse_swept, the same T).
    index (*contact_pairs)(const Model&, double* q, double radius, double* q_end,
                           const ContactBuffers& w, double* q_later, double slack);
    /// The thickness contacts' stage (collision/thick.hpp contacts()) on q (N, 3) in place
    /// from the step's start q0 (N, 3), velocities qd (N, 3), keeping its pair list in w
    /// between calls (for tests of the list); contacts()'s value.
    index (*contact_stage)(const Model&, const double* q0, double* q, double* qd,
                           const ContactBuffers& w);
};

namespace isa_scalar {
const KernelTable& kernel_table();
}
namespace isa_avx2 {
const KernelTable& kernel_table();
}
namespace isa_avx512 {
const KernelTable& kernel_table();
}

/// The table in use (chosen at first use: SOFTBODY_SIMD, else the best the CPU runs).
const KernelTable& kernels();
/// The instruction sets this build has and this CPU runs, best last.
std::vector<std::string> available_simd();
/// Use the named set ("scalar", "avx2", "avx512", or "auto"); false if unavailable.
bool select_simd(const std::string& name);

}  // namespace softbody
