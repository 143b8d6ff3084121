// The explicit schemes for y' = (qd, f(q, qd, t) / m) and their time loop: explicit Euler,
// midpoint (RK2, the paper's choice), classical RK4, symplectic Euler and velocity Verlet.
// Each step starts from the forces at the step's start (evaluated first so the loop can
// check the volumes) and the start state in q0, v0. Pinned particles have inverse mass 0.
#pragma once

#include "model.hpp"
#include "solvers/common.hpp"
#include "terms/attachments.hpp"
#include "terms/drag.hpp"
#include "terms/external.hpp"
#include "terms/gas.hpp"
#include "terms/gravity.hpp"
#include "terms/springs.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::explicit_solver {

/// All forces at time t [s] for q, qd (N, 3) into f (N, 3) [N]: the list of physics terms in
/// the paper's order. The gas's volumes, gradients and pressures are refreshed on the way.
inline void eval_forces(const Model& m, const Control& c, double t, const double* q,
                        const double* qd, const BodyGas& gas, double* f) {
    gravity::force(m, f);                   // weight m g (initialises the accumulator)
    springs::force(m, q, qd, f);            // damped Hooke springs: edges, bending, user
    attachments::force(m, c, q, qd, f);     // springs to anchor points
    external::force(m, c, f);               // per-step forces from Control
    external::grab_force(c, q, qd, f);      // a grabbed particle pulled to a target
    gas::evaluate(m, c, t, q, gas);         // volumes, dV/dx and the gas law's P(V, t)
    gas::force(m, gas, f);                  // (P - P_ambient) dV/dx
    drag::force(m, c, q, qd, f);            // air drag on faces (skipped when off)
}

/// q_out = q0 + h slope_q; v_out = v0 + h f / m (safe when slope_q is v_out).
inline void stage(const Model& m, const double* q0, const double* v0, double h,
                  const double* slope_q, const double* f, double* q_out, double* v_out) {
    for (index i = 0; i < m.particle_count; ++i) {
        const double w = h * m.particle_inv_mass[i];
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
    for (index i = 0; i < m.particle_count; ++i) {
        const double wm = weight * m.particle_inv_mass[i];
        for (int k = 0; k < 3; ++k) {
            acc_q[3 * i + k] += weight * vs[3 * i + k];
            acc_v[3 * i + k] += wm * f[3 * i + k];
        }
    }
}

/// One step of `scheme` from (w.q0, w.v0) with the start forces in w.f, into q, qd.
inline void step(const Model& m, const Control& c, int scheme, double t, double dt, double* q,
                 double* qd, const ExplicitBuffers& w) {
    const index n = m.particle_count;
    if (scheme == 0) {  // explicit Euler (first order)
        stage(m, w.q0, w.v0, dt, w.v0, w.f, q, qd);
    } else if (scheme == 1) {  // midpoint: slopes at the half step (second order)
        stage(m, w.q0, w.v0, 0.5 * dt, w.v0, w.f, w.qs, w.vs);
        eval_forces(m, c, t + 0.5 * dt, w.qs, w.vs, w.gas, w.f);
        stage(m, w.q0, w.v0, dt, w.vs, w.f, q, qd);
    } else if (scheme == 2) {  // classical RK4
        for (index k = 0; k < 3 * n; ++k) w.acc_q[k] = w.acc_v[k] = 0.0;
        accumulate(m, 1.0, w.v0, w.f, w.acc_q, w.acc_v);
        stage(m, w.q0, w.v0, 0.5 * dt, w.v0, w.f, w.qs, w.vs);
        eval_forces(m, c, t + 0.5 * dt, w.qs, w.vs, w.gas, w.f);
        accumulate(m, 2.0, w.vs, w.f, w.acc_q, w.acc_v);
        stage(m, w.q0, w.v0, 0.5 * dt, w.vs, w.f, w.qs, w.vs);
        eval_forces(m, c, t + 0.5 * dt, w.qs, w.vs, w.gas, w.f);
        accumulate(m, 2.0, w.vs, w.f, w.acc_q, w.acc_v);
        stage(m, w.q0, w.v0, dt, w.vs, w.f, w.qs, w.vs);
        eval_forces(m, c, t + dt, w.qs, w.vs, w.gas, w.f);
        accumulate(m, 1.0, w.vs, w.f, w.acc_q, w.acc_v);
        const double h = dt / 6.0;
        for (index k = 0; k < 3 * n; ++k) {
            q[k] = w.q0[k] + h * w.acc_q[k];
            qd[k] = w.v0[k] + h * w.acc_v[k];
        }
    } else if (scheme == 3) {  // symplectic Euler: v += dt a(q, v), then q += dt v_new
        for (index i = 0; i < n; ++i) {
            const double h = dt * m.particle_inv_mass[i];
            for (int k = 0; k < 3; ++k) {
                const index r = 3 * i + k;
                const double v = w.v0[r] + h * w.f[r];
                qd[r] = v;
                q[r] = w.q0[r] + dt * v;
            }
        }
    } else {  // velocity Verlet: half kick, drift, forces at the new positions, half kick
        for (index i = 0; i < n; ++i) {
            const double h = 0.5 * dt * m.particle_inv_mass[i];
            for (int k = 0; k < 3; ++k) {
                const index r = 3 * i + k;
                const double v = w.v0[r] + h * w.f[r];
                w.vs[r] = v;
                q[r] = w.q0[r] + dt * v;
            }
        }
        eval_forces(m, c, t + dt, q, w.vs, w.gas, w.f);
        for (index i = 0; i < n; ++i) {
            const double h = 0.5 * dt * m.particle_inv_mass[i];
            for (int k = 0; k < 3; ++k) qd[3 * i + k] = w.vs[3 * i + k] + h * w.f[3 * i + k];
        }
    }
}

/// Advance s.q, s.qd by p.steps steps of p.dt from p.t0. On a particle failure the state goes
/// back to the failing step's start; on a volume failure it is the state whose volume failed.
/// NEED_HASH (value: the entries needed) also leaves the state at the failing step's start.
inline RunResult simulate(const Model& m, const Control& c, const RunParams& p,
                          const StateView& s, const ExplicitBuffers& w) {
    const index n3 = 3 * m.particle_count;
    loop::begin_run(m, c, p, s, w.contact);
    for (index step_index = 0; step_index < p.steps; ++step_index) {
        const double t = p.t0 + static_cast<double>(step_index) * p.dt;
        loop::copy(s.q, w.q0, n3);
        loop::copy(s.qd, w.v0, n3);
        eval_forces(m, c, t, s.q, s.qd, w.gas, w.f);
        RunResult r = loop::check_volumes(m, w.gas.volume, p.ratio_min, p.ratio_max);
        if (r.status != OK) {
            r.steps_done = step_index;
            return r;
        }
        step(m, c, p.scheme, t, p.dt, s.q, s.qd, w);
        const index needed = loop::contacts(m, c, p, step_index, t + p.dt, s, w.q0, w.contact);
        if (needed > 0) {  // the hash is too small: undo the step, the caller grows it
            loop::copy(w.q0, s.q, n3);
            loop::copy(w.v0, s.qd, n3);
            return {NEED_HASH, step_index, -1, static_cast<double>(needed)};
        }
        r = loop::check_particles(m, s.q, s.qd, p.max_speed);
        if (r.status != OK) {
            loop::copy(w.q0, s.q, n3);
            loop::copy(w.v0, s.qd, n3);
            r.steps_done = step_index;
            return r;
        }
    }
    return {OK, p.steps, -1, 0.0};
}

}  // namespace softbody::SOFTBODY_KERNELS::explicit_solver
