// What a physics term is to the solvers: one struct per term (its file's `Term`), derived
// from TermBase, whose static functions are the term's forms. A solver, the diagnostics and
// the stability estimate iterate the registered terms (terms/registry.hpp) and call a form
// on each; TermBase gives every form a default that does nothing, so a term defines only
// the forms it has, and an empty default costs nothing once inlined.
//
// The forms, each at a point `Eval` (model, control, time, positions, velocities and the
// gas state of this evaluation):
//
//   update      per-evaluation state the forces read, before any force (gas: volumes and
//               pressures); `lanes_ran` says the vertex-major pass already did its part
//   force       f (N, 3) [N] += the term's force; skipped for a kLane term when the
//               vertex-major pass ran (its lane form gave that force) and for a kProjected
//               term in projective dynamics (its projection stands for the force there)
//   energy      the term's energy [J], each body's share added to body (B,); kEnergy says
//               the term has one (dissipative and given forces have none)
//   linearization_size  how many doubles of scratch its prepare keeps for its products at
//               a point (Linearization::own, in the term's layout; 0: none)
//   prepare     the implicit solvers' linearisation at the step's start (Linearization)
//   jacobian_product   out (N, 3) += alpha_c C p + alpha_k K p (C = df/dv, K = df/dx), the
//               matrix-free product of backward Euler and BDF2, -K positive semi-definite
//   add_smoother_blocks  the term's share of each particle's 3 x 3 diagonal block of
//               M - h C - h^2 K (the multigrid smoother), and with kStencil its blocks
//               between particles into its stencil's coefficients (s.entries)
//   add_entries  (kStencil) the smoother's row sums: s += the term's entries first..last-1
//               of its stencil (a particle's, sorted by neighbour j) times x_j, their
//               blocks being those of -(M - h C - h^2 K)
//   check_stencil (kStencil) whether a stencil's map (the term's own, map_length entries)
//               fits the model: null, or what is wrong (the bindings check it once)
//   add_jacobi_diagonal  the term's share of each particle's Jacobi preconditioner, one
//               number per particle (N,) [kg] of M - h C - h^2 K (a mean of its diagonal block's
//               diagonal, or the axial part of it)
//   project     projective dynamics' local step: the term's part of the global step's
//               right-hand side at the iterate (a kProjected term's matrix part is in the
//               factor Python builds)
//   flow        a gas-flow term's molar flows into and out of the bodies' gas at e, added
//               to e.gas's flow_in, flow_in_t and flow_out (terms/flows.hpp), which every
//               scheme integrates into the gas state (solvers/gas_state.hpp)
//   add_row_sums  the stability estimate, first pass (kSharedRows terms): the term's
//               Gershgorin weights sqrt(w) by part added into s.root_sum (N, 4) at its
//               particles, the row sums R_i that every kSharedRows term's rows then share
//   bound       the stability estimate: the term's own Gershgorin bound by part at positions
//               q (TermBound), after every add_row_sums (kBound says it has one; s.rows
//               (N, 2) its scratch); kernels.cpp: stiffness_bounds calls it for every term,
//               softbody.stability adds them (Weyl), the kSharedRows ones by their largest
//   prepare_spectral  (kSpectral) the stability estimate's linearisation at l.q into its own
//               scratch (linearization_size doubles, l.own), after every `bound` form: the
//               estimate's state in BoundScratch (the gas at its largest scheduled value);
//               a term without kSpectral gets its `prepare` at e instead
//   spectral_product  (kSpectral) the stability estimate's split of the Jacobian: out
//               (N, 3) += the term's part `part` (StiffnessPart: damped, undamped or whole
//               stiffness, K = df/dx; or the damping, C = df/dv) times p at
//               prepare_spectral's linearisation. A term without kSpectral counts its whole
//               K (jacobian_product, alpha_k = 1) in every stiffness part and its C in the
//               damping part: never less than it has, so the estimate stays an upper bound
//   prepare_constraints  what XPBD's constraint pass needs for a substep h, once per run
//   constrain   XPBD's pass over the term's constraints (solvers/substep.hpp): positions
//               p.rows moved in place by each constraint's Delta lambda (kConstraint terms;
//               their force is left out of the substep's explicit forces)
//   active      whether the term acts at all in a call (the fused symplectic Euler pass
//               covers only kFused terms: a call with another active term takes the
//               general step)
//
// Forms the vertex-major pass fuses (lanes) stay in each term's file beside these
// (gravity::lane_force, springs::lane_pair, gas::lane_face, membrane::lane_triangle).
#pragma once

#include "model.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS {

/// A point at which a form is evaluated: time t [s], positions q and velocities qd (N, 3),
/// and the gas state (volumes, pressures, dV/dx) the forces of this evaluation share.
struct Eval {
    const Model& m;
    const Control& c;
    double t;
    const double* q;
    const double* qd;
    const BodyGas& gas;
};

/// XPBD's constraint pass within one substep of h [s] (solvers/substep.hpp): the iterate
/// and the substep's start (the damping's reference) packed per particle in rows
/// (N, kRow): x, y, z of the iterate, moved in place, then x, y, z at the substep's start
/// and two doubles of padding (one 64-byte line per particle, so that a spring's end is one
/// load: simd.hpp's load_rows reads the two triples as its positions and velocities). The
/// springs in colour order (spring_order (S,), colour c holding entries [colour_ptr[c],
/// colour_ptr[c + 1]), no two springs of a colour sharing a particle) and each
/// constraint's multiplier lambda [N s^2], zeroed at the substep's start (the springs' per
/// entry of spring_order). spring_ends (2, S): each entry's two particles; spring_coef
/// (6, S), per entry: what prepare_constraints computes once for h
/// (springs::constraint_coefficients).
struct ConstraintPass {
    double h = 0.0;
    double relaxation = 1.0;  // each constraint's step (Delta lambda) times this (SOR)
    double* rows = nullptr;               // (N, kRow) iterate, substep's start, padding
    const index* spring_order = nullptr;  // (S,)
    const index* colour_ptr = nullptr;    // (colours + 1,)
    index colours = 0;
    double* spring_lambda = nullptr;      // (S,)
    double* attachment_lambda = nullptr;  // (A,)
    const index* spring_ends = nullptr;   // (2, S)
    double* spring_coef = nullptr;        // (6, S)
};

/// Every form's default: none. A term's struct derives from this and hides what it has.
struct TermBase {
    static constexpr bool kLane = false;       // the vertex-major pass gives its force
    static constexpr bool kProjected = false;  // projective dynamics: a projection, no force
    // the fused symplectic pass (solvers/explicit.hpp, symplectic_pass) sums its force: only
    // the lane terms and the terms that pass adds (the pressure, Control's forces) may say so
    static constexpr bool kFused = false;
    // the same, but only when the vertex-major pass ran (a kLane term whose edge-major force
    // sums after the pressure's: the general step keeps that order without the pass)
    static constexpr bool kFusedInPass = false;
    static constexpr bool kEnergy = false;     // it has an energy
    // its energy is work done from outside the model (the grab spring: the user's hand),
    // which softbody.diagnostics leaves out of the model's total
    static constexpr bool kExternal = false;
    // its force comes from outside the body it acts on (an anchor, the user's hand, the
    // air), so it may turn a free body: the implicit step's keep_own_torque leaves its
    // torque in (a body's own forces exert none)
    static constexpr bool kFromOutside = false;
    static constexpr bool kFlow = false;  // it moves gas (its `flow` form), no force
    static constexpr bool kBound = false;  // it has a `bound` form
    // its Gershgorin rows are a particle's rows shared with the other kSharedRows terms (a
    // spring's and an attachment's at one particle): it has `add_row_sums`, and the
    // estimate bounds their sum by the largest of their `bound`s
    static constexpr bool kSharedRows = false;
    // its bound holds a body's volume mode (TermBound::mode: the gas's P'(V) g g^T), which
    // softbody.stability reports apart (omega_gas, omega_pressure)
    static constexpr bool kVolumeMode = false;
    // it couples particles in the multigrid smoother (blocks between them): a Stencil of
    // kStencilWidth numbers per entry, filled by add_smoother_blocks, read by add_entries
    static constexpr bool kStencil = false;
    static constexpr int kStencilWidth = 0;
    // XPBD (solvers/substep.hpp) solves it by its `constrain` form, no force there
    static constexpr bool kConstraint = false;
    // it splits its Jacobian for the stability estimate itself (prepare_spectral and
    // spectral_product); else its whole K counts in every stiffness part
    static constexpr bool kSpectral = false;
    static bool active(const Model&, const Control&) { return true; }
    static void update(const Eval&, bool /*lanes_ran*/) {}
    static void force(const Eval&, double* /*f*/) {}
    static double energy(const Eval&, double* /*body*/) { return 0.0; }
    static index linearization_size(const Model&) { return 0; }
    static void prepare(const Eval&, const Linearization&) {}
    static void jacobian_product(const Model&, const Control&, const Linearization&,
                                 double /*alpha_c*/, double /*alpha_k*/, const double* /*p*/,
                                 double* /*out*/) {}
    static void add_smoother_blocks(const Model&, const Control&, const Linearization&,
                                    const SmootherBlocks&) {}
    static void add_entries(const Stencil&, const double* /*x*/, index /*first*/,
                            index /*last*/, V3& /*s*/) {}
    static const char* check_stencil(const Model&, const Stencil&, index /*map_length*/) {
        return "has no stencil";
    }
    static void add_jacobi_diagonal(const Model&, const Control&, const Linearization&,
                                    double /*h*/, double* /*diag*/) {}
    static void project(const Model&, const Control&, double /*h*/, const double* /*x*/,
                        const double* /*x0*/, double* /*rhs*/) {}
    static void flow(const Eval&) {}
    static void add_row_sums(const Model&, const Control&, const double* /*q*/,
                             const BoundScratch&) {}
    static void bound(const Model&, const Control&, const double* /*q*/, const BoundScratch&,
                      TermBound&) {}
    static void prepare_spectral(const Eval&, const BoundScratch&, const Linearization&) {}
    static void spectral_product(const Model&, const Control&, const Linearization&,
                                 StiffnessPart, const double* /*p*/, double* /*out*/) {}
    static void prepare_constraints(const Model&, const Control&, const ConstraintPass&) {}
    static void constrain(const Model&, const Control&, const ConstraintPass&) {}
};

}  // namespace softbody::SOFTBODY_KERNELS
