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
//   prepare     the implicit solvers' linearisation at the step's start (Linearization)
//   jacobian_product   out (N, 3) += alpha_c C p + alpha_k K p (C = df/dv, K = df/dx), the
//               matrix-free product of backward Euler and BDF2, -K positive semi-definite
//   add_smoother_blocks  the term's share of each particle's 3 x 3 diagonal block of
//               M - h C - h^2 K (the multigrid smoother)
//   project     projective dynamics' local step: the term's part of the global step's
//               right-hand side at the iterate (a kProjected term's matrix part is in the
//               factor Python builds)
//   flow        a gas-flow term's molar flows into and out of the bodies' gas at e, added
//               to e.gas's flow_in, flow_in_t and flow_out (terms/flows.hpp), which every
//               scheme integrates into the gas state (solvers/gas_state.hpp)
//   bound       the stability estimate: the term's own Gershgorin bound by part at positions
//               q (TermBound), added to the springs' (kBound says it has one; rows (N, 2)
//               scratch). Springs, attachments and the gas, whose rows and rank-one part
//               combine, are composed in kernels.cpp: stiffness_bounds
//   prepare_constraints  what XPBD's constraint pass needs for a substep h, once per run
//   constrain   XPBD's pass over the term's constraints (solvers/substep.hpp): positions
//               p.x moved in place by each constraint's Delta lambda (kConstraint terms;
//               their force is left out of the substep's explicit forces)
//   active      whether the term acts at all in a call (the fused symplectic Euler pass
//               covers only kFused terms: a call with another active term takes the
//               general step)
//
// Forms the vertex-major pass fuses (lanes) stay in each term's file beside these
// (gravity::lane_force, springs::lane_pair, gas::lane_face, membrane::lane_triangle); the
// stability estimate's Gershgorin pieces too (kernels.cpp composes them).
#pragma once

#include "model.hpp"

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
/// x (N, 3) moved in place, the substep's start x_start (N, 3) (the damping's reference),
/// the springs in colour order (spring_order (S,), colour c holding entries
/// [colour_ptr[c], colour_ptr[c + 1]), no two springs of a colour sharing a particle) and
/// each constraint's multiplier lambda [N s^2], zeroed at the substep's start (the springs'
/// per entry of spring_order). spring_ends (2, S): each entry's two particles;
/// spring_coef (6, S), per entry: what prepare_constraints computes once for h
/// (springs::constraint_coefficients).
struct ConstraintPass {
    double h = 0.0;
    double* x = nullptr;
    const double* x_start = nullptr;
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
    static constexpr bool kFlow = false;  // it moves gas (its `flow` form), no force
    static constexpr bool kBound = false;  // it has a `bound` form
    // XPBD (solvers/substep.hpp) solves it by its `constrain` form, no force there
    static constexpr bool kConstraint = false;
    static bool active(const Model&, const Control&) { return true; }
    static void update(const Eval&, bool /*lanes_ran*/) {}
    static void force(const Eval&, double* /*f*/) {}
    static double energy(const Eval&, double* /*body*/) { return 0.0; }
    static void prepare(const Eval&, const Linearization&) {}
    static void jacobian_product(const Model&, const Control&, const Linearization&,
                                 double /*alpha_c*/, double /*alpha_k*/, const double* /*p*/,
                                 double* /*out*/) {}
    static void add_smoother_blocks(const Model&, const Control&, const Linearization&,
                                    const SmootherBlocks&) {}
    static void project(const Model&, const Control&, double /*h*/, const double* /*x*/,
                        const double* /*x0*/, double* /*rhs*/) {}
    static void flow(const Eval&) {}
    static void bound(const Model&, const Control&, const double* /*q*/, double* /*rows*/,
                      TermBound&) {}
    static void prepare_constraints(const Model&, const Control&, const ConstraintPass&) {}
    static void constrain(const Model&, const Control&, const ConstraintPass&) {}
};

}  // namespace softbody::SOFTBODY_KERNELS
