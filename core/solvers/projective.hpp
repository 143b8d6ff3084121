// Projective dynamics: backward Euler by local-global iterations on a prefactored matrix
// (Liu et al. 2013, Bouaziz et al. 2014; softbody.solvers.factor has the derivation).
// Backward Euler, x1 = x0 + h v1 with M (v1 - v0) = h f(x1, v1), is the minimum of
//
//     1 / (2 h^2) |x - y|_M^2 + sum_s [k_s / 2 |d_s - p_s|^2 + c_s / (2 h) |d_s - q_s|^2] - ...
//
// with y = x0 + h v0 and each spring's (and attachment's) projections p_s, q_s
// (springs::projection). Each iteration fixes the projections at the iterate (the local
// step, terms/springs.hpp and terms/attachments.hpp) and solves
//
//     (M / h^2 + sum_s (k_s + c_s / h) A_s^T A_s) x = M y / h^2 + sum_s A_s^T (k_s p_s + c_s / h q_s) + f
//
// (the global step) by two triangular solves on the factor Python built for h. f is every
// other force at the iterate, explicit within the iteration: every registered term that is
// not projected (terms/term.hpp, kProjected). Python's softbody.solvers.projective builds the
// factor and caches one per step size.
//
// Thickness contacts in the iterations (namespace contacts below). The pairs nearer than
// 2 h at the step's start (collision/thick_system.hpp, each_near: the stage's list) become
// constraints d_p(x) = n_p . sum_k c_pk x_k >= r = 1.5 h (the top of the implicit solvers'
// band; n_p and the gap's coefficients c_p fixed at x0, so d_p = J_p x is linear), pushed
// by forces J^T lambda, lambda >= 0, in f at every iterate. Converged, the iterations solve
// backward Euler with those constraints held (lambda_p > 0 only where d_p = r). The factor
// is fixed, so a contact's stiffness cannot enter the matrix. Weighed:
//   (a) A penalty k_p (r - d_p)_+ explicit in f. The iteration x' = A^-1 (b - K J x + ...)
//       contracts while rho(K J A^-1 J^T) < 1; A >= M / h^2 (the springs add PSD terms), so
//       rho <= rho(h^2 K J M^-1 J^T) <= max_p h^2 k_p R_p (Gershgorin on the pairs' rows:
//       R_p = sum_i |c_pi| S_i / m_i over the pair's free particles, S_i = sum of |c_qi|
//       over the pairs q at particle i), so k_p = 1 / (h^2 R_p) is the stiffest the bound
//       allows (a lone pair: m_c / h^2, a quarter of the implicit solvers' 4 m_c / h^2; a
//       particle in several pairs shares it). Measured on the ball resting on a held cloth
//       (tests/test_projective_contact.py, 1/60 s, 2 iterations, 2-4 s after the drop):
//       too soft to carry the ball (the weight rests on a few vertices): the stage's mean
//       largest correction per step 1.6e-2 m against 2.1e-2 m with the stage alone, the
//       kinetic energy at rest 2.0e-2 J against 3.7e-2 J. Accumulating k_p (r - d_p) into
//       lambda from iteration to iteration (Uzawa) gave the same (1.6e-2 m); carrying
//       lambda on to the next step (a warm start) made it an integral controller on a
//       mass: the ball bounced (0.24 J at 1/300 s) and a run at 1/60 s crossed.
//   (b) A constant contact weight W = w M / h^2 on the factor's diagonal, the target the
//       iterate where no pair is near: a free particle's iteration becomes
//       x' = (A + W)^-1 (b + W x), converging to the same point, but from y it takes only
//       1 / (1 + w) of its forces' motion per iteration: with w = 4 (the implicit solvers'
//       stiffness) two iterations give a falling particle 1 - 0.8^2 = 36 % of its
//       acceleration. Derived, not built (it would change every thickness model's
//       dynamics out of contact).
//   (c) Chosen: after each global solve one dual step (dual_step): delta_p =
//       max(k_p e_p, -lambda_p) with e_p = r - d_p(x) and k_p from (a) (a diagonal scaling),
//       its motion dx = A^-1 J^T delta by one more solve with the factor, and the exact
//       line search alpha = delta . e / delta . J dx on the dual quadratic (capped where a
//       multiplier would reach 0), lambda += alpha delta, x += alpha dx. Each step lowers
//       the dual (at the iterate's projections), with no stiffness bound: the springs that
//       A holds and the mass bound ignores show in alpha (median 20-35, up to 500, on the
//       resting ball: the bound in (a) is that conservative). Projecting positions after
//       each iteration (as Chebyshev-accelerated PD and PBD do) would be undone by the
//       next global solve, which rebuilds x from the projections, not from the iterate:
//       only the last projection would count, which is what the stage does. Measured on
//       the same run: the stage's correction 1.1e-5 m against 2.1e-2 m, the kinetic
//       energy at rest 6.5e-4 J against 3.7e-2 J, the spread of the ball's contact force
//       0.17 N against 0.70 N (weight 4.905 N), 0.09 s of CPU against 0.25 s (the stage no
//       longer rebuilds its list every step).
// The multipliers start at 0 each step (no warm start: (a)). J^T delta sums to 0 over
// each pair (sum_k c_pk = 0) and 1^T A = 1^T M / h^2, so momentum is what it is without
// contacts, kept to round-off. Pinned particles take no share (their rows of J^T delta
// are 0). Friction stays the stage's (pairs nearer than h): pairs held at 1.5 h feel
// none, as in the implicit solvers' band. The stage after the step still runs (the
// no-crossing guarantee is its, unchanged). Without thickness contacts there is no pair
// and the arithmetic is as before.
#pragma once

#include <algorithm>
#include <limits>
#include <vector>

#include "collision/thick_system.hpp"
#include "model.hpp"
#include "solvers/common.hpp"
#include "solvers/forms.hpp"
#include "solvers/gas_state.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::projective {

/// Rows of a supernode taken together in the solves below its triangle: their sums are
/// independent, so interleaving them keeps several additions in flight, each row summed in
/// its own order (the results do not change).
constexpr index kSolveRows = 4;

/// out = A^-1 b for b (N, 3) with the factor a (two triangular solves on the three columns
/// at once); x (N, 3) is scratch in factor order; out may be b.
inline void solve(const Factor& a, const double* b, double* x, double* out) {
    const index n = a.size;
    for (index r = 0; r < n; ++r) store(x, r, load(b, a.perm[r]));
    const index* rows = a.node_row;
    const double* values = a.node_value;
    for (index s = 0; s < a.node_count; ++s) {  // L z = b, node by node: each row a dot product
        const index c0 = a.node_col[s], width = a.node_col[s + 1] - c0;
        const index r0 = a.node_row_ptr[s], height = a.node_row_ptr[s + 1] - r0;
        const double* block = values + a.node_value_ptr[s];
        for (index p = 1; p < width; ++p) {  // the triangle: row c0 + p reads rows c0.. c0 + p - 1
            const double* row = block + p * width;
            double a0 = 0.0, a1 = 0.0, a2 = 0.0;
            for (index jj = 0; jj < p; ++jj) {
                const double v = row[jj];
                a0 += v * x[3 * (c0 + jj)];
                a1 += v * x[3 * (c0 + jj) + 1];
                a2 += v * x[3 * (c0 + jj) + 2];
            }
            add_to(x, c0 + p, -V3{a0, a1, a2});
        }
        // the rows below read only the node's columns (done) and write rows past them
        index p = width;
        for (; p + kSolveRows <= height; p += kSolveRows) {
            double acc[kSolveRows][3] = {};
            const double* row = block + p * width;
            for (index jj = 0; jj < width; ++jj) {
                const V3 xj = load(x, c0 + jj);
                for (index k = 0; k < kSolveRows; ++k) {
                    const double v = row[k * width + jj];
                    acc[k][0] += v * xj.x;
                    acc[k][1] += v * xj.y;
                    acc[k][2] += v * xj.z;
                }
            }
            for (index k = 0; k < kSolveRows; ++k)
                add_to(x, rows[r0 + p + k], -V3{acc[k][0], acc[k][1], acc[k][2]});
        }
        for (; p < height; ++p) {
            const double* row = block + p * width;
            double a0 = 0.0, a1 = 0.0, a2 = 0.0;
            for (index jj = 0; jj < width; ++jj) {
                const double v = row[jj];
                a0 += v * x[3 * (c0 + jj)];
                a1 += v * x[3 * (c0 + jj) + 1];
                a2 += v * x[3 * (c0 + jj) + 2];
            }
            add_to(x, rows[r0 + p], -V3{a0, a1, a2});
        }
    }
    for (index j = 0; j < n; ++j) store(x, j, a.inv_diag[j] * load(x, j));  // D^-1
    for (index s = a.node_count - 1; s >= 0; --s) {  // D L^T x = z: rows below, then the block
        const index c0 = a.node_col[s], width = a.node_col[s + 1] - c0;
        const index r0 = a.node_row_ptr[s], height = a.node_row_ptr[s + 1] - r0;
        const double* block = values + a.node_value_ptr[s];
        // rows below, last first, kSolveRows at a time: each column entry takes their
        // products in the same order, with one load and store of it per group
        index p = height - 1;
        for (; p - kSolveRows + 1 >= width; p -= kSolveRows) {
            V3 xr[kSolveRows];
            for (index k = 0; k < kSolveRows; ++k) xr[k] = load(x, rows[r0 + p - k]);
            for (index jj = 0; jj < width; ++jj) {
                V3 xj = load(x, c0 + jj);
                for (index k = 0; k < kSolveRows; ++k)
                    xj = xj - block[(p - k) * width + jj] * xr[k];
                store(x, c0 + jj, xj);
            }
        }
        for (; p > 0; --p) {
            const V3 xr = load(x, rows[r0 + p]);
            const double* row = block + p * width;
            for (index jj = 0; jj < std::min(p, width); ++jj) add_to(x, c0 + jj, -(row[jj] * xr));
        }
    }
    for (index r = 0; r < n; ++r) store(out, a.perm[r], load(x, r));
}

/// The thickness contacts in the iterations (the header above; the pairs from
/// collision/thick_system.hpp): each pair's force lambda_p >= 0 along its direction n_p at
/// the step's start, on its particles with the gap's coefficients c_p (J^T lambda, J the
/// pairs' rows d_p(x) = n_p . sum_k c_pk x_k), in f at every iterate; after each global
/// solve one dual step brings the multipliers toward d_p = r where they push.
namespace contacts {

/// The active pairs of a step (P of them), kept between steps (the vectors keep their room).
struct Pairs {
    std::vector<index> v;        // (P, 4) particles
    std::vector<double> c;       // (P, 4) the gap's coefficients (sum 0)
    std::vector<double> n;       // (P, 3) the gap's direction at the step's start
    std::vector<double> k;       // (P,) the dual step's scale 1 / (dt^2 R_p) [N/m]
    std::vector<double> lambda;  // (P,) the pair's force [N]
    std::vector<double> delta;   // (P,) scratch: the dual step's direction [N]
    std::vector<double> load;    // (N,) scratch: sum of |c| over each particle's pairs
    std::vector<double> b, dx;   // (N, 3) scratch: J^T delta [N] and A^-1 J^T delta [m]
    index count = 0;
};

inline V3 normal(const Pairs& pc, size_t p) {
    return {pc.n[3 * p], pc.n[3 * p + 1], pc.n[3 * p + 2]};
}

/// d_p(x) [m]: pair p's gap at x (N, 3) along its direction at the step's start.
inline double distance(const Pairs& pc, size_t p, const double* x) {
    const V3 n = normal(pc, p);
    double d = 0.0;
    for (size_t l = 0; l < 4; ++l) d += pc.c[4 * p + l] * dot(n, load(x, pc.v[4 * p + l]));
    return d;
}

/// The step's pairs: those nearer than 2 h at the step's start q0 (N, 3), for a step dt [s]
/// from the velocities v0 (N, 3) (thick_system::each_near), with a free particle; their
/// forces 0, their scales k_p = 1 / (dt^2 R_p), R_p = sum_i |c_pi| S_i / m_i over the pair's
/// free particles i, S_i the sum of |c| over i's pairs.
inline void begin(const Model& m, double* q0, const double* v0, double dt,
                  const ContactBuffers& w, Pairs& pc) {
    pc.v.clear();
    pc.c.clear();
    pc.n.clear();
    pc.count = 0;
    const double* inv_mass = m.particles.inv_mass;
    thick_system::each_near(m, q0, v0, dt, w, 2.0 * m.soft_contacts.thickness,
                            [&](index, const index* v, const double* c, V3 g, double d) {
                                bool free = false;
                                for (int l = 0; l < 4; ++l)
                                    free = free || (inv_mass[v[l]] > 0.0 && c[l] != 0.0);
                                if (!free) return;  // all pinned
                                pc.v.insert(pc.v.end(), v, v + 4);
                                pc.c.insert(pc.c.end(), c, c + 4);
                                pc.n.push_back(g.x / d);
                                pc.n.push_back(g.y / d);
                                pc.n.push_back(g.z / d);
                                ++pc.count;
                            });
    if (pc.count == 0) return;
    const size_t count = static_cast<size_t>(pc.count);
    pc.load.assign(static_cast<size_t>(m.particles.count), 0.0);
    for (size_t e = 0; e < 4 * count; ++e)
        pc.load[static_cast<size_t>(pc.v[e])] += std::abs(pc.c[e]);
    pc.k.resize(count);
    pc.lambda.assign(count, 0.0);
    for (size_t p = 0; p < count; ++p) {
        double r = 0.0;
        for (size_t l = 0; l < 4; ++l) {
            const index i = pc.v[4 * p + l];
            r += std::abs(pc.c[4 * p + l]) * pc.load[static_cast<size_t>(i)] * inv_mass[i];
        }
        pc.k[p] = 1.0 / (dt * dt * r);
    }
}

/// f (N, 3) += J^T lambda, the pairs' forces [N].
inline void add_forces(const Pairs& pc, double* f) {
    for (size_t p = 0; p < static_cast<size_t>(pc.count); ++p) {
        if (pc.lambda[p] == 0.0) continue;
        const V3 n = normal(pc, p);
        for (size_t l = 0; l < 4; ++l)
            add_to(f, pc.v[4 * p + l], (pc.lambda[p] * pc.c[4 * p + l]) * n);
    }
}

/// dx (N, 3) = A^-1 J^T delta by the factor a (scratch (N, 3) its vector); pinned rows
/// of J^T delta are left 0, so their dx is 0.
inline void motion(const Model& m, const Factor& a, Pairs& pc, double* scratch) {
    const size_t count = static_cast<size_t>(pc.count);
    pc.b.assign(static_cast<size_t>(3 * m.particles.count), 0.0);
    pc.dx.resize(pc.b.size());
    for (size_t p = 0; p < count; ++p) {
        if (pc.delta[p] == 0.0) continue;
        const V3 n = normal(pc, p);
        for (size_t l = 0; l < 4; ++l) {
            const index i = pc.v[4 * p + l];
            if (m.particles.inv_mass[i] > 0.0)
                add_to(pc.b.data(), i, (pc.delta[p] * pc.c[4 * p + l]) * n);
        }
    }
    solve(a, pc.b.data(), scratch, pc.dx.data());
}

/// One dual step after a global solve reached x (N, 3) with the forces lambda in f: each
/// pair's violation e_p = r - d_p(x) [m], the direction delta_p = max(k_p e_p, -lambda_p),
/// its motion dx = A^-1 J^T delta (one solve with the factor a, scratch (N, 3) its
/// vector), and the step alpha = delta . e / delta . J dx that minimises the dual's
/// quadratic along delta (exact line search), capped where a multiplier would reach 0
/// (the cap is >= 1); then lambda += alpha delta and x += alpha dx, the global step's
/// solution with those forces.
inline void dual_step(const Model& m, const Factor& a, double r, Pairs& pc, double* x,
                      double* scratch) {
    const size_t count = static_cast<size_t>(pc.count);
    pc.delta.resize(count);
    double de = 0.0, cap = std::numeric_limits<double>::infinity();
    for (size_t p = 0; p < count; ++p) {
        const double e = r - distance(pc, p, x);
        const double delta = std::max(pc.k[p] * e, -pc.lambda[p]);
        pc.delta[p] = delta;
        de += delta * e;
        if (delta < 0.0) cap = std::min(cap, pc.lambda[p] / -delta);
    }
    if (!(de > 0.0)) return;  // nothing to move (every pair apart and not pushing)
    motion(m, a, pc, scratch);
    double curvature = 0.0;  // delta . J dx = delta^T J A^-1 J^T delta
    for (size_t p = 0; p < count; ++p)
        if (pc.delta[p] != 0.0) curvature += pc.delta[p] * distance(pc, p, pc.dx.data());
    if (!(curvature > 0.0)) return;
    const double alpha = std::min(de / curvature, cap);
    for (size_t p = 0; p < count; ++p)
        pc.lambda[p] = std::max(0.0, pc.lambda[p] + alpha * pc.delta[p]);
    for (size_t k = 0; k < pc.dx.size(); ++k) x[k] += alpha * pc.dx[k];
}

}  // namespace contacts

/// The forces projective dynamics keeps explicit, at time t [s] for the iterate q, qd
/// (N, 3), into f (N, 3) [N] (refreshing the volumes, dV/dx and pressures in gas): every
/// term's but the projected ones' (forms::eval_forces<kUnprojected>).
inline void forces(const Model& m, const Control& c, double t, const double* q, const double* qd,
                   const BodyGas& gas, const LaneBuffers& lanes, double* f) {
    forms::eval_forces<forms::Which::kUnprojected>(m, c, t, q, qd, gas, lanes, f);
}

/// rhs (N, 3) = M y / h^2 + f + the springs' and attachments' projection terms at the iterate
/// x (x0 at the step's start); pinned rows (inverse mass 0): y, their identity rows.
inline void right_hand_side(const Model& m, const Control& c, double h, const double* x,
                            const double* x0, const double* y, const double* f, double* rhs) {
    const double inv_h = 1.0 / h;
    const double inv_h2 = inv_h * inv_h;
    for (index i = 0; i < m.particles.count; ++i) {
        if (m.particles.inv_mass[i] > 0.0)
            store(rhs, i, m.particles.mass[i] * inv_h2 * load(y, i) + load(f, i));
        else
            store(rhs, i, load(y, i));
    }
    forms::project(m, c, h, x, x0, rhs);
}

/// One backward Euler step of `iterations` local-global iterations from w.q0, w.v0 at time t,
/// starting from y = x0 + dt v0; the factor is built for dt. Leaves x1 in q and
/// v1 = (x1 - x0) / dt in qd; pinned particles keep their velocity. The other forces are
/// taken at t + dt, the end of the step.
inline void step(const Model& m, const Control& c, double t, double dt, index iterations,
                 const Factor& a, double* q, double* qd, const ProjectiveBuffers& w,
                 contacts::Pairs& pairs) {
    const bool touching = pairs.count > 0;
    const double reach = (1.0 + thick_system::kBand) * m.soft_contacts.thickness;
    const index n = m.particles.count;
    for (index i = 0; i < n; ++i) {
        const V3 y = load(w.q0, i) + dt * load(w.v0, i);
        store(w.y, i, y);
        store(q, i, y);
    }
    const double inv_dt = 1.0 / dt;
    for (index it = 0; it < iterations; ++it) {
        for (index i = 0; i < n; ++i) store(qd, i, inv_dt * (load(q, i) - load(w.q0, i)));
        forces(m, c, t + dt, q, qd, w.gas, w.lanes, w.f);
        if (touching) contacts::add_forces(pairs, w.f);
        right_hand_side(m, c, dt, q, w.q0, w.y, w.f, w.rhs);
        solve(a, w.rhs, w.x, q);
        if (touching) contacts::dual_step(m, a, reach, pairs, q, w.x);
    }
    for (index i = 0; i < n; ++i) {
        if (m.particles.inv_mass[i] > 0.0) {
            store(qd, i, inv_dt * (load(q, i) - load(w.q0, i)));
        } else {
            store(q, i, load(w.y, i));
            store(qd, i, load(w.v0, i));
        }
    }
}

/// The steps of simulate, inside loop::run (the run's start and the gas state's begin and
/// finish around them).
inline RunResult run_steps(const Model& m, const Control& c, const RunParams& p,
                          const StateView& s, const Factor& a, const ProjectiveBuffers& w) {
    const index n3 = 3 * m.particles.count;
    BodyGas volumes_only = w.gas;  // the checks need the volumes, not dV/dx (half the time)
    volumes_only.volume_gradient = nullptr;
    const bool flowing = gas_state::flowing(m, c);
    contacts::Pairs pairs;  // the thickness contacts in each step's iterations
    for (index step_index = 0; step_index < p.steps; ++step_index) {
        if (stop_requested(p, step_index)) return {STOPPED, step_index, -1, 0.0};
        const double t = p.time_at(step_index);
        loop::copy(s.q, w.q0, n3);
        loop::copy(s.qd, w.v0, n3);
        volume::evaluate(m, s.q, volumes_only);
        RunResult r = loop::check_volumes(m, w.gas.volume, p.ratio_min, p.ratio_max);
        if (r.status != OK) {
            r.steps_done = step_index;
            return r;
        }
        if (flowing) {  // the flows at the step's start, from its pressures
            gas::pressures(m, c, t, volumes_only);
            gas_state::forward_euler(m, c, t, p.dt, s.q, s.qd, s, volumes_only);
        }
        contacts::begin(m, w.q0, w.v0, p.dt, w.contact, pairs);
        step(m, c, t, p.dt, p.iterations, a, s.q, s.qd, w, pairs);
        // contacts and particle checks; a failure (or a hash too small) undoes the step
        r = loop::end_step(m, c, p, step_index, t, s, w.q0, w.v0, w.contact);
        if (flowing) r = gas_state::end_step(m, s, w.gas, r, step_index, w.q0, w.v0);
        if (r.status != OK) return r;
    }
    return {OK, p.steps, -1, 0.0};
}

/// Advance s.q, s.qd (and the gas state: solvers/gas_state.hpp, forward Euler with the
/// rates at each step's start, so the iterations' forces at the step's end see the gas
/// there) by p.steps steps of p.dt from p.time_at(0), p.iterations iterations each. The checks,
/// contacts and restores are the explicit loop's (solvers/explicit.hpp).
inline RunResult simulate(const Model& m, const Control& c, const RunParams& p,
                          const StateView& s, const Factor& a, const ProjectiveBuffers& w) {
    return loop::run(m, c, p, s, w.contact, w.gas, [&] { return run_steps(m, c, p, s, a, w); });
}

}  // namespace softbody::SOFTBODY_KERNELS::projective
