// XPBD with small steps (Macklin et al., "XPBD: Position-Based Simulation of Compliant
// Constrained Dynamics", MIG 2016; "Small Steps in Physics Simulation", SCA 2019). Each
// step dt is cut into n substeps of h = dt / n; each substep:
//
//   f        the forces of every registered term without a constraint form (gravity, the
//            gas pressure with the exact volume and dV/dx at the substep's start, the air
//            on faces, bending, membranes, Control's forces): forms::eval_forces<kUnconstrained>
//   x*       = x + h v + h^2 f / m (pinned particles, 1 / m = 0, move with their velocity)
//   x        every kConstraint term's constrain form on x*, `iterations` passes (springs:
//            a distance constraint of compliance 1 / k with XPBD's damping, Gauss-Seidel
//            colour by colour; attachments), the multipliers zeroed first. The passes work
//            on rows of one 64-byte line per particle, the iterate beside the substep's
//            start (ConstraintPass), so that a spring's end is one load and one store, not
//            a gather and a scatter per coordinate (1.6x faster a pass, measured). Every
//            pass after the first is over-relaxed by `relaxation` (omega; 1: plain
//            Gauss-Seidel): each constraint's step omega times its own. The first stays
//            plain, so a lone constraint, which it solves exactly, is left exact (the
//            later steps are zero) and the substep's converged solution is the same; the
//            coupled network's slow modes, which a few plain passes leave soft, converge
//            faster (successive over-relaxation; omega 1.9 measured best on the ball drop)
//   v        = (x - x_prev) / h
//   gas      forward Euler over h with the flows' rates at the substep's start (first order)
//   contacts the step's contact stage (loop::contacts) with the substep's start positions
//            for the colliders' continuous detection, the colliders at the substep's end
//
// The explicit part is symplectic Euler on the unconstrained forces; with the constraint
// pass it is a first-order scheme: one pass from lambda = 0 is one Gauss-Seidel Newton
// iteration of the substep's implicit solve, whose position change differs from the
// springs' own forces k (L - L0) + c dL/dt applied explicitly by a factor
// 1 / (1 + (k h^2 + c h) w), so the stiffness is honoured as h -> 0 and the dynamics
// converge to the true ones (velocity Verlet's) as n grows, the error falling like h.
// The checks are the other schemes': volumes at each substep's start, particles at the
// step's end; a failure restores the step's start.
#pragma once

#include <algorithm>

#include "model.hpp"
#include "solvers/common.hpp"
#include "solvers/forms.hpp"
#include "solvers/gas_state.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::substep {

/// Back to the step's start (q0, v0; the gas too when it flows), the result saying the
/// step `step_index` failed.
inline RunResult undo(const Model& m, const StateView& s, const SubstepBuffers& w, bool flowing,
                      RunResult r, index step_index) {
    const index n3 = 3 * m.particles.count;
    loop::copy(w.q0, s.q, n3);
    loop::copy(w.v0, s.qd, n3);
    if (flowing) gas_state::restore_start(m, s, w.gas);
    r.steps_done = step_index;
    return r;
}

/// The constraint pass's view of the buffers for a substep of h.
inline ConstraintPass constraint_pass(const SubstepBuffers& w, double h, double relaxation) {
    ConstraintPass p;
    p.h = h;
    p.relaxation = relaxation;
    p.rows = w.rows;
    p.spring_order = w.spring_order;
    p.colour_ptr = w.colour_ptr;
    p.colours = w.colours;
    p.spring_lambda = w.spring_lambda;
    p.attachment_lambda = w.attachment_lambda;
    p.spring_coef = w.spring_coef;
    p.spring_ends = w.spring_ends;
    return p;
}

/// One substep of h from time t (the explicit forces already in w.f, the constraints'
/// constants prepared for h): the prediction (into the pass's rows, beside the substep's
/// start), the constraint passes, the positions and the velocities from the rows.
inline void substep(const Model& m, const Control& c, double h, index iterations, double relaxation,
                    const StateView& s, const SubstepBuffers& w) {
    const index n = m.particles.count;
    const double h2 = h * h;
    for (index i = 0; i < n; ++i) {
        const V3 x = load(s.q, i);
        double* row = w.rows + kRow * i;
        store(w.q_prev, i, x);
        store(row, 0, x + h * load(s.qd, i) + (h2 * m.particles.inv_mass[i]) * load(w.f, i));
        store(row, 1, x);
    }
    std::fill(w.spring_lambda, w.spring_lambda + m.springs.count, 0.0);
    std::fill(w.attachment_lambda, w.attachment_lambda + m.attachments.count, 0.0);
    ConstraintPass p = constraint_pass(w, h, 1.0);
    for (index it = 0; it < iterations; ++it) {
        p.relaxation = it == 0 ? 1.0 : relaxation;
        forms::constrain(m, c, p);
    }
    const double inv_h = 1.0 / h;
    for (index i = 0; i < n; ++i) {
        const double* row = w.rows + kRow * i;
        const V3 x = load(row, 0);
        store(s.q, i, x);
        store(s.qd, i, inv_h * (x - load(row, 1)));
    }
}

/// The steps of simulate, inside loop::run (the run's start and the gas state's begin and
/// finish around them).
inline RunResult run_steps(const Model& m, const Control& c, const RunParams& p,
                           const StateView& s, const SubstepBuffers& w) {
    const index n3 = 3 * m.particles.count;
    const index substeps = p.substeps;
    const double h = p.dt / static_cast<double>(substeps);
    RunParams sub = p;  // the contacts' clock: the colliders' poses at each substep's end
    sub.steps = p.steps * substeps;
    sub.dt = h;
    const bool flowing = gas_state::flowing(m, c);
    forms::prepare_constraints(m, c, constraint_pass(w, h, p.relaxation));
    double* dn = gas_state::slot(m, w.gas, gas_state::kDn);
    double* dth = gas_state::slot(m, w.gas, gas_state::kDt);
    double* theta = gas_state::slot(m, w.gas, gas_state::kTheta);
    for (index step_index = 0; step_index < p.steps; ++step_index) {
        if (stop_requested(p, step_index)) return {STOPPED, step_index, -1, 0.0};
        const double t = p.time_at(step_index);
        loop::copy(s.q, w.q0, n3);
        loop::copy(s.qd, w.v0, n3);
        if (flowing) gas_state::save_start(m, s, w.gas);
        for (index k = 0; k < substeps; ++k) {
            const double ts = t + static_cast<double>(k) * h;
            forms::eval_forces<forms::Which::kUnconstrained>(m, c, ts, s.q, s.qd, w.gas, w.lanes,
                                                            w.f);
            RunResult r = loop::check_volumes(m, w.gas.volume, p.ratio_min, p.ratio_max);
            if (r.status != OK) {
                if (k == 0) {  // the state whose volume failed: the step's start
                    r.steps_done = step_index;
                    return r;
                }
                return undo(m, s, w, flowing, r, step_index);
            }
            if (flowing) {
                gas_state::latch(m, c, ts, s.q, w.gas, s.vent_open);
                gas_state::rates(m, c, ts, s.q, s.qd, w.gas, dn, dth);
            }
            substep(m, c, h, p.iterations, p.relaxation, s, w);
            if (flowing) gas_state::advance(m, h, s.gas_moles, theta, dn, dth, s.gas_moles, theta);
            const index needed =
                loop::contacts(m, c, sub, step_index * substeps + k, ts + h, s, w.q_prev, w.contact);
            if (needed != 0)
                return undo(m, s, w, flowing, loop::contact_failure(needed, step_index, w.contact),
                            step_index);
        }
        RunResult r = loop::check_particles(m, s.q, s.qd, p.max_speed);
        if (r.status != OK) {
            loop::copy(w.q0, s.q, n3);
            loop::copy(w.v0, s.qd, n3);
            r.steps_done = step_index;
        }
        if (flowing) r = gas_state::end_step(m, s, w.gas, r, step_index, w.q0, w.v0);
        if (r.status != OK) return r;
    }
    return {OK, p.steps, -1, 0.0};
}

/// Advance s.q, s.qd (and the gas state) by p.steps steps of p.dt from p.time_at(0), each of
/// p.substeps substeps with p.iterations constraint passes. On a failure the state goes
/// back to the failing step's start (a volume that fails at a step's start: that state).
inline RunResult simulate(const Model& m, const Control& c, const RunParams& p,
                          const StateView& s, const SubstepBuffers& w) {
    return loop::run(m, c, p, s, w.contact, w.gas, [&] { return run_steps(m, c, p, s, w); });
}

}  // namespace softbody::SOFTBODY_KERNELS::substep
