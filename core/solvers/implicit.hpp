// Backward Euler and BDF2 (softbody.solvers.implicit), one Newton step each, solved
// matrix-free by preconditioned CG, and their time loop.
//
// Backward Euler on M v' = f(x, v), linearised at the step's start:
//     (M - h C - h^2 K) dv = h (f0 + K y) [+ M (v0 - v_-1) / 3 for BDF2],   v1 = v0 + dv,
// with C = df/dv, K = df/dx at the start, h = dt and y = dt v0 (backward Euler) or
// h = 2/3 dt and y = (x0 - x_-1) / 3 + h v0 (BDF2, Choi & Ko 2002); then x1 = x0 + dt v1,
// or x1 = (4 x0 - x_-1) / 3 + h v1. The products C p and K p come term by term
// (forms::apply_jacobians); the preconditioner is one multigrid V-cycle (the true blocks
// smoothed on the finest level: every term's diagonal share and every kStencil term's
// blocks between particles; the Laplacian hierarchy below) or Jacobi (every term's
// add_jacobi_diagonal). The
// start forces are vertex-major on the SIMD paths, term by term on the scalar one. The
// thickness contacts' pairs near at the start add their penalty's force to f0 and its
// stiffness to K, the Jacobi diagonal and the smoother (collision/thick_system.hpp).
#pragma once

#include <vector>

#include "collision/thick_system.hpp"
#include "model.hpp"
#include "solvers/common.hpp"
#include "solvers/forms.hpp"
#include "solvers/gas_state.hpp"
#include "solvers/multigrid.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::implicit_solver {

/// The linearisation at the step's start (x0 in w.q0, the gas there in w.gas) that the
/// terms' Jacobian products and smoother blocks read.
inline Linearization at_start(const ImplicitBuffers& w) {
    Linearization l;
    l.q = w.q0;
    l.volume_gradient = w.gas.volume_gradient;
    l.scratch = w.linearization;
    return l;
}

/// out = alpha_m M p + alpha_c C p + alpha_k K p at the step's start: the system matrix's
/// product, term by term (forms::apply_jacobians), and the thickness contacts' stiffness
/// (collision/thick_system.hpp) in K.
inline void apply_at_start(const Model& m, const Control& c, const ImplicitBuffers& w,
                           double alpha_m, double alpha_c, double alpha_k, const double* p,
                           double* out, const thick_system::System& contact) {
    forms::apply_jacobians(m, c, at_start(w), alpha_m, alpha_c, alpha_k, p, out);
    if (contact.count > 0) thick_system::add_product(contact, alpha_k, p, out);
}

/// sum over free particles of a_i . b_i (pinned rows are not unknowns).
inline double dot_free(const Model& m, const double* a, const double* b) {
    double s = 0.0;
    for (index i = 0; i < m.particles.count; ++i)
        if (m.particles.inv_mass[i] > 0.0) s += dot(load(a, i), load(b, i));
    return s;
}

/// out = a^-1 for a 3 x 3 block (row-major) by the adjugate.
inline void invert_3x3(const double* a, double* out) {
    const double c00 = a[4] * a[8] - a[5] * a[7];
    const double c01 = a[5] * a[6] - a[3] * a[8];
    const double c02 = a[3] * a[7] - a[4] * a[6];
    const double inv_det = 1.0 / (a[0] * c00 + a[1] * c01 + a[2] * c02);
    out[0] = c00 * inv_det;
    out[3] = c01 * inv_det;
    out[6] = c02 * inv_det;
    out[1] = (a[2] * a[7] - a[1] * a[8]) * inv_det;
    out[4] = (a[0] * a[8] - a[2] * a[6]) * inv_det;
    out[7] = (a[1] * a[6] - a[0] * a[7]) * inv_det;
    out[2] = (a[1] * a[5] - a[2] * a[4]) * inv_det;
    out[5] = (a[2] * a[3] - a[0] * a[5]) * inv_det;
    out[8] = (a[0] * a[4] - a[1] * a[3]) * inv_det;
}

/// The finest-level smoother's blocks for step h: each term's share, then the inverses.
inline void prepare_blocks(const Model& m, const Control& c, double h, const ImplicitBuffers& w,
                           const MultigridView& mg, const thick_system::System& contact) {
    forms::smoother_blocks(m, c, at_start(w), h, mg.block, mg.stencils);
    if (contact.count > 0) thick_system::add_blocks(contact, h, mg.block);
    for (index i = 0; i < m.particles.count; ++i) invert_3x3(mg.block + 9 * i, mg.block_inv + 9 * i);
}

/// x_i = D_i^-1 (s + b_i), D_i particle i's diagonal block.
inline void solve_row(const MultigridView& mg, index i, V3 s, const double* b) {
    const double* d = mg.block_inv + 9 * i;
    const double s0 = s.x + b[3 * i], s1 = s.y + b[3 * i + 1], s2 = s.z + b[3 * i + 2];
    mg.x[3 * i] = d[0] * s0 + d[1] * s1 + d[2] * s2;
    mg.x[3 * i + 1] = d[3] * s0 + d[4] * s1 + d[5] * s2;
    mg.x[3 * i + 2] = d[6] * s0 + d[7] * s1 + d[8] * s2;
}

/// z = P^-1 r for r, z (N, 3), pinned rows 0: with a hierarchy, one V-cycle whose finest
/// level smooths with block Gauss-Seidel on the true spring blocks (forward from 0 down,
/// backward up) around the Laplacian hierarchy's correction; otherwise Jacobi with diag.
inline void precondition(const Model& m, const MultigridView* hierarchy, const double* diag,
                         const double* r, double* z, const thick_system::System& contact) {
    const index n = m.particles.count;
    const double* inv_mass = m.particles.inv_mass;
    if (hierarchy == nullptr) {
        for (index i = 0; i < n; ++i)
            for (int k = 0; k < 3; ++k) z[3 * i + k] = r[3 * i + k] / diag[i];
        return;
    }
    const MultigridView& mg = *hierarchy;
    // forward sweep from x = 0: row i reads only its springs to earlier particles
    for (index i = 0; i < n; ++i) {
        if (inv_mass[i] == 0.0) {
            store(mg.x, i, {0.0, 0.0, 0.0});
            continue;
        }
        V3 s{0.0, 0.0, 0.0};
        forms::add_entries<forms::Span::kEarlier>(mg.stencils, mg.x, i, s);
        thick_system::add_entries<-1>(contact, mg.x, i, s);
        solve_row(mg, i, s, r);
    }
    // its residual: row i's equation held when x_i was set, with x_j = 0 for j > i, so what
    // is left is those springs' blocks times their new x_j
    for (index i = 0; i < n; ++i) {
        if (inv_mass[i] == 0.0) {
            store(mg.r, i, {0.0, 0.0, 0.0});
            continue;
        }
        V3 s{0.0, 0.0, 0.0};
        forms::add_entries<forms::Span::kLater>(mg.stencils, mg.x, i, s);
        thick_system::add_entries<1>(contact, mg.x, i, s);
        store(mg.r, i, s);
    }
    if (mg.level_count > 0) {  // coarse correction with the Laplacian hierarchy
        multigrid::restrict_to(mg, 0, mg.r);
        multigrid::cycle_from(mg, 1);
        multigrid::prolong(mg, 0);
    } else {  // one level: the dense solve on the residual, keeping the smoothed x
        for (index k = 0; k < 3 * n; ++k) {
            mg.b[k] = mg.r[k];
            mg.r[k] = mg.x[k];
        }
        multigrid::coarse_solve(mg);
        for (index k = 0; k < 3 * n; ++k) mg.x[k] += mg.r[k];
    }
    for (index i = 0; i < n; ++i)
        if (inv_mass[i] == 0.0) store(mg.x, i, {0.0, 0.0, 0.0});
    for (index i = n - 1; i >= 0; --i) {  // backward sweep; pinned rows stay 0
        if (inv_mass[i] == 0.0) continue;
        V3 s{0.0, 0.0, 0.0};
        forms::add_entries<forms::Span::kAll>(mg.stencils, mg.x, i, s);
        thick_system::add_entries<0>(contact, mg.x, i, s);
        solve_row(mg, i, s, r);
    }
    for (index k = 0; k < 3 * n; ++k) z[k] = mg.x[k];
}

/// Everything the step's matrix needs at its start (x0 in w.q0, the gas in w.gas): spring
/// blocks, pressure slopes, the smoother's blocks or the Jacobi diagonal, for step h.
inline void prepare(const Model& m, const Control& c, double t, double h,
                    const ImplicitBuffers& w, const MultigridView* mg,
                    const thick_system::System& contact) {
    forms::prepare(Eval{m, c, t, w.q0, w.v0, w.gas}, at_start(w));
    if (mg != nullptr) prepare_blocks(m, c, h, w, *mg, contact);
}

/// Jacobi's diagonal into w.cg_diag: each particle's mass and every term's share at the
/// step's start (forms::jacobi_diagonal).
inline void jacobi_diagonal(const Model& m, const Control& c, double h, const ImplicitBuffers& w,
                            const thick_system::System& contact) {
    forms::jacobi_diagonal(m, c, at_start(w), h, w.cg_diag);
    if (contact.count > 0) thick_system::add_diagonal(contact, h, w.cg_diag);
}

/// The terms whose forces come from outside a body (kFromOutside: anchors, the grab, the
/// air): their bits, for forms::apply_jacobians' skip.
inline unsigned outside_terms() {
    unsigned skip = 0;
    Terms::each([&](auto term, int k) {
        if (decltype(term)::kFromOutside) skip |= 1u << k;
    });
    return skip;
}

/// dv (w.cg_x) turned, body by body, so that the body's own forces (springs, gas, bending,
/// membranes) leave its angular momentum as it was: the torque of their linearised change
/// over the step, h sum_i (x_i - c) x (K dx)_i (dx = y + h dv the step's position change,
/// w.qs = y, c the body's mass centre), taken back by a rotation, I omega = -that torque,
/// dv_i += omega x (x_i - c), I the body's inertia about c (the rotation's M). Their
/// damping's torque, sum_i x_i x (C p)_i, is 0 as is (it does not act on rigid motion).
/// Bodies with a pinned particle, or joined to another body by a spring, take torque from
/// outside through their own terms and are left as they are.
///
/// Why: forces a body exerts on itself have no torque at any x, but their product K p
/// does where the start is out of balance: they turn with the body, so sum_i x_i x (K p)_i
/// = sum_i f_i x p_i with f the start's force. A balloon whose gas grew since the last step
/// (an inflator, an orifice, a schedule) starts each step with every vertex pushed out,
/// f_i = a m_i x_i, its stiff volume mode settling within the step, and that torque spins
/// it up by 1 / (1 - h^2 a) a step (2 % a step for a tank-fed balloon at 2 ms steps,
/// whatever CG's tolerance: its residual only seeds the spin). With the turn, backward
/// Euler keeps a free body's angular momentum to round-off (x1 - x0 = dt v1, so
/// sum_i m_i x1_i x v1_i = sum_i m_i x0_i x v1_i); BDF2 to its own step's error.
///
/// K dx costs no product of the whole system: CG leaves r = b - A dv (A = M - h C - h^2 K,
/// every term; b the right-hand side), so h K dv = (M dv - b + r) / h - C dv, and
/// K_own dx = K y + (M dv - b + r) / h - C dv - K_out dx with K y the right-hand side's
/// product (w.ky) and _out the terms from outside a body (kFromOutside), whose products
/// are cheap. The body's own damping C_own dv is left in: its torque is 0 (above).
/// Whether each body (B,) is joined to another by a spring: made once a run.
inline std::vector<unsigned char> joined_bodies(const Model& m) {
    std::vector<unsigned char> joined(static_cast<size_t>(m.bodies.count), 0);
    for (index s = 0; s < m.springs.count; ++s) {
        const index a = m.particles.body[m.springs.indices[2 * s]];
        const index b = m.particles.body[m.springs.indices[2 * s + 1]];
        if (a != b) {
            if (a >= 0) joined[static_cast<size_t>(a)] = 1;
            if (b >= 0) joined[static_cast<size_t>(b)] = 1;
        }
    }
    return joined;
}

inline void keep_own_torque(const Model& m, const Control& c, double h, bool bdf2,
                            const unsigned char* joined, const ImplicitBuffers& w,
                            const thick_system::System& contact) {
    const double* inv_mass = m.particles.inv_mass;
    const double* mass = m.particles.mass;
    // C_out dv + h K_out dv into cg_p, K_out y into cg_z: the outside terms alone
    const unsigned own_terms = ~outside_terms();
    forms::apply_jacobians(m, c, at_start(w), 0.0, 1.0, h, w.cg_x, w.cg_p, own_terms);
    forms::apply_jacobians(m, c, at_start(w), 0.0, 0.0, 1.0, w.qs, w.cg_z, own_terms);
    if (contact.count > 0) {  // the thickness contacts: from outside (no torque within a body)
        thick_system::add_product(contact, h, w.cg_x, w.cg_p);
        thick_system::add_product(contact, 1.0, w.qs, w.cg_z);
    }
    for (index i = 0; i < m.particles.count; ++i)
        for (int k = 0; k < 3; ++k) {
            const index r = 3 * i + k;
            double b = h * (w.f[r] + w.ky[r]);  // the right-hand side, as step() made it
            if (bdf2) b += mass[i] * (w.v0[r] - w.v_prev[r]) / 3.0;
            const double own_dv = (mass[i] * w.cg_x[r] - b + w.cg_r[r]) / h;
            w.cg_ap[r] = w.ky[r] + own_dv - w.cg_p[r] - w.cg_z[r];  // K_own dx (+ C_own dv)
        }
    for (index b = 0; b < m.bodies.count; ++b) {
        if (joined[b]) continue;
        const index first = m.bodies.particle_range[2 * b], last = m.bodies.particle_range[2 * b + 1];
        double total = 0.0;
        V3 centre = {0.0, 0.0, 0.0};
        bool held = false;
        for (index i = first; i < last; ++i) {
            held = held || inv_mass[i] == 0.0;
            total += mass[i];
            centre = centre + mass[i] * load(w.q0, i);
        }
        if (held || !(total > 0.0)) continue;
        centre = (1.0 / total) * centre;
        V3 torque = {0.0, 0.0, 0.0};
        double inertia[9] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0}, inverse[9];
        for (index i = first; i < last; ++i) {
            const V3 r = load(w.q0, i) - centre;
            torque = torque + cross(r, load(w.cg_ap, i));
            const double rr = dot(r, r);
            for (int k = 0; k < 3; ++k)
                for (int l = 0; l < 3; ++l)
                    inertia[3 * k + l] += mass[i] * ((k == l ? rr : 0.0) - (&r.x)[k] * (&r.x)[l]);
        }
        invert_3x3(inertia, inverse);
        const V3 tau = (-h) * torque;
        const V3 omega = {inverse[0] * tau.x + inverse[1] * tau.y + inverse[2] * tau.z,
                          inverse[3] * tau.x + inverse[4] * tau.y + inverse[5] * tau.z,
                          inverse[6] * tau.x + inverse[7] * tau.y + inverse[8] * tau.z};
        if (!(std::isfinite(omega.x) && std::isfinite(omega.y) && std::isfinite(omega.z)))
            continue;  // no inertia about some axis (a body on a line): no rotation to turn
        for (index i = first; i < last; ++i)
            add_to(w.cg_x, i, cross(omega, load(w.q0, i) - centre));
    }
}

/// One backward Euler step, or with bdf2 one BDF2 step, from w.q0, w.v0 with w.f = f(x0, v0)
/// into q, qd; BDF2 reads the previous step's start in w.q_prev, w.v_prev, and both leave
/// this step's start there. dv is solved from the last step's dv (w.cg_x) when that is
/// closer, then turned so that each free body's own forces keep its angular momentum
/// (keep_own_torque). Returns the CG iterations used.
inline index step(const Model& m, const Control& c, double t, double dt, double* q, double* qd,
                  const ImplicitBuffers& w, const MultigridView* mg, double tolerance,
                  index max_iterations, bool bdf2, const unsigned char* joined,
                  const thick_system::System& contact) {
    const index n = m.particles.count;
    const double* inv_mass = m.particles.inv_mass;
    const double h = bdf2 ? dt * (2.0 / 3.0) : dt;
    for (index k = 0; k < 3 * n; ++k)  // y, the position change before dv
        w.qs[k] = bdf2 ? (w.q0[k] - w.q_prev[k]) / 3.0 + h * w.v0[k] : h * w.v0[k];
    prepare(m, c, t, h, w, mg, contact);
    apply_at_start(m, c, w, 0.0, 0.0, 1.0, w.qs, w.ky, contact);  // K y for the right-hand side
    if (mg == nullptr) jacobi_diagonal(m, c, h, w, contact);
    double rhs_norm = 0.0;
    for (index i = 0; i < n; ++i)
        for (int k = 0; k < 3; ++k) {
            const index r = 3 * i + k;
            double b = 0.0;
            if (inv_mass[i] > 0.0) {
                b = h * (w.f[r] + w.ky[r]);
                if (bdf2) b += m.particles.mass[i] * (w.v0[r] - w.v_prev[r]) / 3.0;
            }
            w.cg_r[r] = b;
            rhs_norm += b * b;
            if (inv_mass[i] == 0.0) w.cg_x[r] = 0.0;
        }
    rhs_norm = std::sqrt(rhs_norm);
    // warm start from the previous dv, kept only if its residual b - A dv_prev is smaller
    apply_at_start(m, c, w, 1.0, -h, -h * h, w.cg_x, w.cg_ap, contact);
    double warm = 0.0;
    for (index i = 0; i < n; ++i)
        if (inv_mass[i] > 0.0)
            for (int k = 0; k < 3; ++k) {
                const double d = w.cg_r[3 * i + k] - w.cg_ap[3 * i + k];
                warm += d * d;
            }
    if (std::isfinite(warm) && warm < rhs_norm * rhs_norm) {
        for (index i = 0; i < n; ++i)
            if (inv_mass[i] > 0.0)
                for (int k = 0; k < 3; ++k) w.cg_r[3 * i + k] -= w.cg_ap[3 * i + k];
    } else {
        for (index k = 0; k < 3 * n; ++k) w.cg_x[k] = 0.0;
        warm = rhs_norm * rhs_norm;
    }
    index iterations = 0;
    if (std::sqrt(warm) > tolerance * rhs_norm) {
        precondition(m, mg, w.cg_diag, w.cg_r, w.cg_z, contact);
        for (index k = 0; k < 3 * n; ++k) w.cg_p[k] = w.cg_z[k];
        double rz = dot_free(m, w.cg_r, w.cg_z);
        while (iterations < max_iterations) {
            apply_at_start(m, c, w, 1.0, -h, -h * h, w.cg_p, w.cg_ap, contact);
            const double pap = dot_free(m, w.cg_p, w.cg_ap);
            // pap < 0 (the pressure Hessian made the matrix indefinite at a large step) is
            // no breakdown: CG's recurrences hold for any symmetric matrix
            if (pap == 0.0 || !std::isfinite(pap)) break;  // breakdown: keep the last iterate
            const double alpha = rz / pap;
            double res = 0.0;
            for (index i = 0; i < n; ++i) {
                if (inv_mass[i] == 0.0) continue;
                for (int k = 0; k < 3; ++k) {
                    const index r = 3 * i + k;
                    w.cg_x[r] += alpha * w.cg_p[r];
                    w.cg_r[r] -= alpha * w.cg_ap[r];
                    res += w.cg_r[r] * w.cg_r[r];
                }
            }
            ++iterations;
            if (std::sqrt(res) <= tolerance * rhs_norm) break;
            precondition(m, mg, w.cg_diag, w.cg_r, w.cg_z, contact);
            const double rz_new = dot_free(m, w.cg_r, w.cg_z);
            const double beta = rz_new / rz;
            rz = rz_new;
            for (index k = 0; k < 3 * n; ++k) w.cg_p[k] = w.cg_z[k] + beta * w.cg_p[k];
        }
    }
    keep_own_torque(m, c, h, bdf2, joined, w, contact);
    for (index i = 0; i < n; ++i)
        for (int k = 0; k < 3; ++k) {
            const index r = 3 * i + k;
            const double v = w.v0[r] + w.cg_x[r];
            qd[r] = v;
            if (bdf2 && inv_mass[i] > 0.0)
                q[r] = (4.0 * w.q0[r] - w.q_prev[r]) / 3.0 + h * v;
            else
                q[r] = w.q0[r] + dt * v;  // pinned particles keep their set velocity
            w.q_prev[r] = w.q0[r];
            w.v_prev[r] = w.v0[r];
        }
    return iterations;
}

/// Whether contacts moved a particle or changed its velocity (q, qd against their values
/// before contacts). BDF2 then takes its next step as backward Euler: it would read a
/// projection and a reflection as motion and carry them on (a dropped ball bounced higher
/// each time).
inline bool contacts_acted(index n3, const double* q, const double* qd, const double* q_before,
                           const double* qd_before) {
    for (index k = 0; k < n3; ++k)
        if (q[k] != q_before[k] || qd[k] != qd_before[k]) return true;
    return false;
}

/// The steps of simulate, inside loop::run (the run's start and the gas state's begin and
/// finish around them).
inline RunResult run_steps(const Model& m, const Control& c, const RunParams& p,
                          const ImplicitParams& ip, const StateView& s, const ImplicitBuffers& w,
                          const MultigridView* mg) {
    const index n3 = 3 * m.particles.count;
    const bool flowing = gas_state::flowing(m, c);
    const std::vector<unsigned char> joined = joined_bodies(m);  // for keep_own_torque
    thick_system::System contact;  // the thickness contacts in each step's solve
    for (index step_index = 0; step_index < p.steps; ++step_index) {
        if (stop_requested(p, step_index)) return {STOPPED, step_index, -1, 0.0};
        const double t = p.time_at(step_index);
        loop::copy(s.q, w.q0, n3);
        loop::copy(s.qd, w.v0, n3);
        forms::eval_forces(m, c, t, s.q, s.qd, w.gas, w.lanes, w.f);
        RunResult r = loop::check_volumes(m, w.gas.volume, p.ratio_min, p.ratio_max);
        if (r.status != OK) {
            r.steps_done = step_index;
            return r;
        }
        if (flowing) gas_state::forward_euler(m, c, t, p.dt, s.q, s.qd, s, w.gas);
        const bool two_step = ip.bdf2 && (step_index > 0 || ip.history) && w.contacts_acted[0] == 0;
        thick_system::begin(m, w.q0, w.v0, p.dt, w.contact, two_step ? p.dt * (2.0 / 3.0) : p.dt,
                            contact);
        thick_system::add_forces(contact, w.f);
        const index its = step(m, c, t, p.dt, s.q, s.qd, w, mg, ip.tolerance, ip.max_iterations,
                               two_step, joined.data(), contact);
        w.cg_stats[0] += 1;
        w.cg_stats[1] += its;
        w.cg_stats[2] = std::max(w.cg_stats[2], its);
        if (ip.bdf2) {  // contacts may move particles
            loop::copy(s.q, w.qs, n3);
            loop::copy(s.qd, w.vs, n3);
        }
        // contacts and particle checks; a failure (or a hash too small) undoes the step
        r = loop::end_step(m, c, p, step_index, t, s, w.q0, w.v0, w.contact);
        if (flowing) r = gas_state::end_step(m, s, w.gas, r, step_index, w.q0, w.v0);
        if (r.status != OK) return r;
        if (ip.bdf2) w.contacts_acted[0] = contacts_acted(n3, s.q, s.qd, w.qs, w.vs) ? 1 : 0;
    }
    return {OK, p.steps, -1, 0.0};
}

/// Advance s.q, s.qd (and the gas state: solvers/gas_state.hpp, forward Euler with the
/// rates at each step's start) by p.steps implicit steps (ip.bdf2: BDF2, else backward
/// Euler). BDF2 steps as backward Euler when it has no previous step (the run's first step
/// without ip.history) or the last step's contacts acted. Failures as explicit_solver::simulate.
inline RunResult simulate(const Model& m, const Control& c, const RunParams& p,
                          const ImplicitParams& ip, const StateView& s, const ImplicitBuffers& w,
                          const MultigridView* mg) {
    return loop::run(m, c, p, s, w.contact, w.gas,
                     [&] { return run_steps(m, c, p, ip, s, w, mg); });
}

}  // namespace softbody::SOFTBODY_KERNELS::implicit_solver
