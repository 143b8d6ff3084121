// The explicit schemes for y' = (qd, f(q, qd, t) / m) and their time loop: explicit Euler,
// midpoint (RK2, the paper's choice), classical RK4, symplectic Euler and velocity Verlet.
// Each step starts from the forces at the step's start (evaluated first so the loop can
// check the volumes) and the start state in q0, v0. Pinned particles have inverse mass 0.
#pragma once

#include "model.hpp"
#include "simd.hpp"
#include "solvers/common.hpp"
#include "solvers/forms.hpp"
#include "solvers/gas_state.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::explicit_solver {

/// q_out = q0 + h slope_q; v_out = v0 + h f / m (safe when slope_q is v_out).
inline void stage(const Model& m, const double* q0, const double* v0, double h,
                  const double* slope_q, const double* f, double* q_out, double* v_out) {
    for (index i = 0; i < m.particles.count; ++i) {
        const double w = h * m.particles.inv_mass[i];
        for (int k = 0; k < 3; ++k) {
            const index r = 3 * i + k;
            const double sq = slope_q[r];
            q_out[r] = q0[r] + h * sq;
            v_out[r] = v0[r] + w * f[r];
        }
    }
}

inline void accumulate(const Model& m, double weight, const double* vs, const double* f,
                       double* acc_q, double* acc_v) {
    for (index i = 0; i < m.particles.count; ++i) {
        const double wm = weight * m.particles.inv_mass[i];
        for (int k = 0; k < 3; ++k) {
            acc_q[3 * i + k] += weight * vs[3 * i + k];
            acc_v[3 * i + k] += wm * f[3 * i + k];
        }
    }
}

/// One step of `scheme` from (w.q0, w.v0) with the start forces in w.f, into q, qd. With
/// `flowing`, the gas state too, from its start (kN0, kT0) with the rates there (kDn, kDt),
/// by the same stages (solvers/gas_state.hpp), into s's amounts and kTheta.
inline void step(const Model& m, const Control& c, int scheme, double t, double dt, double* q,
                 double* qd, const ExplicitBuffers& w, bool flowing, const StateView& s) {
    using namespace gas_state;
    const index n = m.particles.count;
    const BodyGas& g = w.gas;
    double* n0 = slot(m, g, kN0);
    double* t0 = slot(m, g, kT0);
    double* ns = slot(m, g, kNs);
    double* ts = slot(m, g, kTs);
    double* dn = slot(m, g, kDn);
    double* dth = slot(m, g, kDt);
    double* theta = slot(m, g, kTheta);
    const BodyGas stage_gas = at(g, ns, ts);
    // the forces (and, flowing, the gas rates) at a stage whose gas state is ns, ts
    auto eval = [&](double time, const double* x, const double* v) {
        if (!flowing) {
            forms::eval_forces(m, c, time, x, v, g, w.lanes, w.f);
            return;
        }
        forms::eval_forces(m, c, time, x, v, stage_gas, w.lanes, w.f);
        rates(m, c, time, x, v, stage_gas, dn, dth);
    };
    if (scheme == Integrator::EULER) {  // explicit Euler (first order)
        stage(m, w.q0, w.v0, dt, w.v0, w.f, q, qd);
        if (flowing) advance(m, dt, n0, t0, dn, dth, s.gas_moles, theta);
    } else if (scheme == Integrator::MIDPOINT) {  // midpoint: slopes at the half step (second order)
        stage(m, w.q0, w.v0, 0.5 * dt, w.v0, w.f, w.qs, w.vs);
        if (flowing) advance(m, 0.5 * dt, n0, t0, dn, dth, ns, ts);
        eval(t + 0.5 * dt, w.qs, w.vs);
        stage(m, w.q0, w.v0, dt, w.vs, w.f, q, qd);
        if (flowing) advance(m, dt, n0, t0, dn, dth, s.gas_moles, theta);
    } else if (scheme == Integrator::RK4) {  // classical RK4
        double* an = slot(m, g, kAccN);
        double* at_ = slot(m, g, kAccT);
        const index bodies = m.bodies.count;
        auto gas_accumulate = [&](double weight) {
            if (!flowing) return;
            for (index b = 0; b < bodies; ++b) {
                an[b] += weight * dn[b];
                at_[b] += weight * dth[b];
            }
        };
        if (flowing) std::fill(an, an + bodies, 0.0), std::fill(at_, at_ + bodies, 0.0);
        for (index k = 0; k < 3 * n; ++k) w.acc_q[k] = w.acc_v[k] = 0.0;
        accumulate(m, 1.0, w.v0, w.f, w.acc_q, w.acc_v);
        gas_accumulate(1.0);
        stage(m, w.q0, w.v0, 0.5 * dt, w.v0, w.f, w.qs, w.vs);
        if (flowing) advance(m, 0.5 * dt, n0, t0, dn, dth, ns, ts);
        eval(t + 0.5 * dt, w.qs, w.vs);
        accumulate(m, 2.0, w.vs, w.f, w.acc_q, w.acc_v);
        gas_accumulate(2.0);
        stage(m, w.q0, w.v0, 0.5 * dt, w.vs, w.f, w.qs, w.vs);
        if (flowing) advance(m, 0.5 * dt, n0, t0, dn, dth, ns, ts);
        eval(t + 0.5 * dt, w.qs, w.vs);
        accumulate(m, 2.0, w.vs, w.f, w.acc_q, w.acc_v);
        gas_accumulate(2.0);
        stage(m, w.q0, w.v0, dt, w.vs, w.f, w.qs, w.vs);
        if (flowing) advance(m, dt, n0, t0, dn, dth, ns, ts);
        eval(t + dt, w.qs, w.vs);
        accumulate(m, 1.0, w.vs, w.f, w.acc_q, w.acc_v);
        gas_accumulate(1.0);
        const double h = dt / 6.0;
        for (index k = 0; k < 3 * n; ++k) {
            q[k] = w.q0[k] + h * w.acc_q[k];
            qd[k] = w.v0[k] + h * w.acc_v[k];
        }
        if (flowing) advance(m, h, n0, t0, an, at_, s.gas_moles, theta);
    } else if (scheme == Integrator::SYMPLECTIC_EULER) {  // symplectic Euler: v += dt a(q, v), then q += dt v_new
        for (index i = 0; i < n; ++i) {
            const double h = dt * m.particles.inv_mass[i];
            for (int k = 0; k < 3; ++k) {
                const index r = 3 * i + k;
                const double v = w.v0[r] + h * w.f[r];
                qd[r] = v;
                q[r] = w.q0[r] + dt * v;
            }
        }
        if (flowing) advance(m, dt, n0, t0, dn, dth, s.gas_moles, theta);
    } else {  // velocity Verlet: half kick, drift, forces at the new positions, half kick
        for (index i = 0; i < n; ++i) {
            const double h = 0.5 * dt * m.particles.inv_mass[i];
            for (int k = 0; k < 3; ++k) {
                const index r = 3 * i + k;
                const double v = w.v0[r] + h * w.f[r];
                w.vs[r] = v;
                q[r] = w.q0[r] + dt * v;
            }
        }
        // the gas by Heun: a predictor to the step's end, then the mean of the two rates
        double* an = slot(m, g, kAccN);
        double* at_ = slot(m, g, kAccT);
        if (flowing) {
            std::copy(dn, dn + m.bodies.count, an);
            std::copy(dth, dth + m.bodies.count, at_);
            advance(m, dt, n0, t0, dn, dth, ns, ts);
        }
        eval(t + dt, q, w.vs);
        for (index i = 0; i < n; ++i) {
            const double h = 0.5 * dt * m.particles.inv_mass[i];
            for (int k = 0; k < 3; ++k) qd[3 * i + k] = w.vs[3 * i + k] + h * w.f[3 * i + k];
        }
        if (flowing) {
            for (index b = 0; b < m.bodies.count; ++b) {
                an[b] = 0.5 * (an[b] + dn[b]);
                at_[b] = 0.5 * (at_[b] + dth[b]);
            }
            advance(m, dt, n0, t0, an, at_, s.gas_moles, theta);
        }
    }
}

/// Whether symplectic Euler can end its steps in one fused pass (symplectic_pass): every
/// term acting in the call is one that pass covers (kFused: the lane terms, the pressure and
/// Control's forces; kFusedInPass: the membranes when the vertex-major pass runs; another
/// would change the order of the sums), and bodies whose
/// particle ranges follow one another.
inline bool fused_symplectic(const Model& m, const Control& c, int scheme,
                             const LaneBuffers& lanes) {
    if (scheme != Integrator::SYMPLECTIC_EULER ||
        !forms::all_fused(m, c, lanes::use_vertex_pass(lanes)))
        return false;
    index end = 0;
    for (index b = 0; b < m.bodies.count; ++b) {
        if (m.bodies.particle_range[2 * b] < end) return false;
        end = m.bodies.particle_range[2 * b + 1];
    }
    return true;
}

/// Symplectic Euler's step in one pass over the flat (N, 3) arrays, kLanes values at a time:
/// f + (P - P_ambient) dV/dx + Control.particle_f (the kFused terms forms::eval_forces adds
/// after the lane terms, in registry order), v = v0 + h f with h = dt / m (h3 (N, 3), per component),
/// x = x0 + dt v, the start state kept in q0, v0 (N, 3) and the new one written to q, qd.
/// `seen` gets the particle checks' filter of what was written.
inline void symplectic_pass(const Model& m, const Control& c, double dt, const double* h3,
                            const BodyGas& gas, const double* f, double* q, double* qd,
                            double* q0, double* v0, colliders::Seen& seen) {
    vi bad{};
    vd largest{};
    bool bad_tail = false;
    double most_tail = 0.0;
    const double* pf = c.particle_f;
    const double* g = gas.volume_gradient;
    // flat components [k0, k1), their body's pressure p (or none)
    auto run = [&](index k0, index k1, bool with_gas, double p) {
        index k = k0;
        const vd pv = splat(p), dtv = splat(dt);
        for (; k + kLanes <= k1; k += kLanes) {
            vd force = load_lanes(f + k);
            if (with_gas) force += pv * load_lanes(g + k);
            force += load_lanes(pf + k);
            const vd x0 = load_lanes(q + k), u0 = load_lanes(qd + k);
            const vd v = u0 + load_lanes(h3 + k) * force;
            const vd x = x0 + dtv * v;
            store_lanes(q0 + k, x0);
            store_lanes(v0 + k, u0);
            store_lanes(q + k, x);
            store_lanes(qd + k, v);
            bad |= (x - x != 0.0) | (v - v != 0.0);
            const vd a = v < 0.0 ? -v : v;
            largest = a > largest ? a : largest;
        }
        for (; k < k1; ++k) {
            double force = f[k];
            if (with_gas) force += p * g[k];
            force += pf[k];
            const double x0 = q[k], u0 = qd[k];
            const double v = u0 + h3[k] * force;
            const double x = x0 + dt * v;
            q0[k] = x0, v0[k] = u0, q[k] = x, qd[k] = v;
            bad_tail |= !(std::isfinite(x) && std::isfinite(v));
            most_tail = std::max(most_tail, std::fabs(v));
        }
    };
    index at = 0;  // particles between bodies feel no pressure
    for (index b = 0; b < m.bodies.count; ++b) {
        const index p0 = m.bodies.particle_range[2 * b], p1 = m.bodies.particle_range[2 * b + 1];
        run(3 * at, 3 * p0, false, 0.0);
        run(3 * p0, 3 * p1, true, gas.pressure[b] - m.gases.ambient_pressure[b]);
        at = p1;
    }
    run(3 * at, 3 * m.particles.count, false, 0.0);
    seen.bad |= bad_tail;
    seen.most = std::max(seen.most, most_tail);
    for (int l = 0; l < kLanes; ++l) {
        seen.bad |= bad[l] != 0;
        seen.most = std::max(seen.most, largest[l]);
    }
}

/// Symplectic Euler's steps with the end of each fused (fused_symplectic): the lane terms'
/// forces and the gas state (forms::eval_forces<kBody>), the volume check, one pass for the rest of the forces, the kick, the drift
/// and the copies of the start state, then the contacts, and the particle checks, filtered
/// by what the pass and the colliders wrote when no soft contact moved particles between
/// them. The same arithmetic as step() and end_step(): the same results.
inline RunResult simulate_symplectic_fused(const Model& m, const Control& c, const RunParams& p,
                                           const StateView& s, const ExplicitBuffers& w) {
    const index n = m.particles.count;
    double* h3 = w.acc_q;  // dt / m per component (RK4's sums are free)
    for (index i = 0; i < n; ++i) {
        const double h = p.dt * m.particles.inv_mass[i];
        for (int k = 0; k < 3; ++k) h3[3 * i + k] = h;
    }
    const bool flowing = gas_state::flowing(m, c);
    for (index step_index = 0; step_index < p.steps; ++step_index) {
        if (stop_requested(p, step_index)) return {STOPPED, step_index, -1, 0.0};
        const double t = p.time_at(step_index);
        forms::eval_forces<forms::Which::kBody>(m, c, t, s.q, s.qd, w.gas, w.lanes, w.f);
        RunResult r = loop::check_volumes(m, w.gas.volume, p.ratio_min, p.ratio_max);
        if (r.status != OK) {
            r.steps_done = step_index;
            return r;
        }
        // the gas by forward Euler, symplectic Euler's own order, from the rates here
        if (flowing) gas_state::forward_euler(m, c, t, p.dt, s.q, s.qd, s, w.gas);
        colliders::Seen seen;
        symplectic_pass(m, c, p.dt, h3, w.gas, w.f, s.q, s.qd, w.q0, w.v0, seen);
        const index needed = loop::contacts(m, c, p, step_index, t + p.dt, s, w.q0, w.contact, &seen);
        if (needed != 0)
            r = loop::contact_failure(needed, step_index, w.contact);
        else if (m.soft_contacts.mode != SoftContactMode::NONE)  // soft contacts moved particles unseen
            r = loop::check_particles(m, s.q, s.qd, p.max_speed);
        else
            r = loop::check_seen(m, s.q, s.qd, p.max_speed, seen.bad, seen.most);
        if (r.status != OK) {
            loop::copy(w.q0, s.q, 3 * n);
            loop::copy(w.v0, s.qd, 3 * n);
            r.steps_done = step_index;
        }
        if (flowing) r = gas_state::end_step(m, s, w.gas, r, step_index, w.q0, w.v0);
        if (r.status != OK) return r;
    }
    return {OK, p.steps, -1, 0.0};
}

/// The steps of simulate, inside loop::run (the run's start and the gas state's begin and
/// finish around them).
inline RunResult run_steps(const Model& m, const Control& c, const RunParams& p,
                           const StateView& s, const ExplicitBuffers& w) {
    const index n3 = 3 * m.particles.count;
    if (fused_symplectic(m, c, p.scheme, w.lanes)) return simulate_symplectic_fused(m, c, p, s, w);
    const bool flowing = gas_state::flowing(m, c);
    for (index step_index = 0; step_index < p.steps; ++step_index) {
        if (stop_requested(p, step_index)) return {STOPPED, step_index, -1, 0.0};
        const double t = p.time_at(step_index);
        loop::copy(s.q, w.q0, n3);
        loop::copy(s.qd, w.v0, n3);
        if (flowing) gas_state::save_start(m, s, w.gas);
        forms::eval_forces(m, c, t, s.q, s.qd, w.gas, w.lanes, w.f);
        RunResult r = loop::check_volumes(m, w.gas.volume, p.ratio_min, p.ratio_max);
        if (r.status != OK) {
            r.steps_done = step_index;
            return r;
        }
        if (flowing) {
            gas_state::latch(m, c, t, s.q, w.gas, s.vent_open);
            gas_state::rates(m, c, t, s.q, s.qd, w.gas, gas_state::slot(m, w.gas, gas_state::kDn),
                             gas_state::slot(m, w.gas, gas_state::kDt));
        }
        step(m, c, p.scheme, t, p.dt, s.q, s.qd, w, flowing, s);
        // contacts and particle checks; a failure (or a hash too small) undoes the step
        r = loop::end_step(m, c, p, step_index, t, s, w.q0, w.v0, w.contact);
        if (flowing) r = gas_state::end_step(m, s, w.gas, r, step_index, w.q0, w.v0);
        if (r.status != OK) return r;
    }
    return {OK, p.steps, -1, 0.0};
}

/// Advance s.q, s.qd (and the gas state) by p.steps steps of p.dt from p.time_at(0). On a particle
/// failure the state goes back to the failing step's start; on a volume failure it is the
/// state whose volume failed. NEED_HASH (value: the entries needed) also leaves the state
/// at the failing step's start.
inline RunResult simulate(const Model& m, const Control& c, const RunParams& p,
                          const StateView& s, const ExplicitBuffers& w) {
    return loop::run(m, c, p, s, w.contact, w.gas, [&] { return run_steps(m, c, p, s, w); });
}

}  // namespace softbody::SOFTBODY_KERNELS::explicit_solver
