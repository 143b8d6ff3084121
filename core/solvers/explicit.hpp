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
#include "simd.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::explicit_solver {

/// The vertex-major pass over groups [g0, g1): for every particle, kLanes at a time, its
/// weight, its springs (kSprings; projective dynamics solves them implicitly) and dV/dx
/// from its faces, with its share of its body's exact volume (each face seen from its three
/// corners: 3 x 6 V in all, added to body_six_v (B,)). The ring's neighbour rows serve a
/// spring and two faces each. Writes the particles' rows of f and gas.volume_gradient (N, 3)
/// and nothing else's.
template <bool kSprings>
inline void vertex_pass_groups(const Model& m, const double* rows, const BodyGas& gas, double* f,
                               index g0, index g1, double* body_six_v) {
    const index n = m.particle_count;
    for (index g = g0; g < g1; ++g)
        for (int lane0 = 0; lane0 < kGroup; lane0 += kLanes) {
            const index first = kGroup * g + lane0;
            if (first >= n) break;
            index own[kLanes];
            for (int l = 0; l < kLanes; ++l) own[l] = first + l;
            const Rows self = load_rows(rows, own);
            const Rows ref = load_rows(rows, m.lane_reference + first);
            const vd rx = self.x - ref.x, ry = self.y - ref.y, rz = self.z - ref.z;
            vd fx, fy, fz, gx{}, gy{}, gz{}, six_v{};
            gravity::lane_force(m, first, fx, fy, fz);  // weight m g
            // the ring: damped edge springs, and the faces between consecutive neighbours
            vd ux0{}, uy0{}, uz0{}, ux{}, uy{}, uz{};
            for (index s = m.ring_slot_start[g]; s < m.ring_slot_start[g + 1]; ++s) {
                const index e = kGroup * s + lane0;
                const Rows o = load_rows(rows, m.ring_slot_other + e);
                const vd dx = o.x - self.x, dy = o.y - self.y, dz = o.z - self.z;
                if constexpr (kSprings)
                    springs::lane_pair(self, o, dx, dy, dz,
                                       load_lanes(m.ring_slot_rest_length + e),
                                       load_lanes(m.ring_slot_stiffness + e),
                                       load_lanes(m.ring_slot_damping + e), fx, fy, fz);
                if (s == m.ring_slot_start[g]) {
                    ux0 = dx, uy0 = dy, uz0 = dz;  // the face closing the ring comes last
                } else {
                    gas::lane_face(ux, uy, uz, dx, dy, dz, load_lanes(m.ring_slot_face + e), rx,
                                   ry, rz, gx, gy, gz, six_v);
                }
                ux = dx, uy = dy, uz = dz;
            }
            if (m.ring_slot_start[g + 1] > m.ring_slot_start[g])
                gas::lane_face(ux, uy, uz, ux0, uy0, uz0,
                               load_lanes(m.ring_slot_face + kGroup * m.ring_slot_start[g] + lane0),
                               rx, ry, rz, gx, gy, gz, six_v);
            if constexpr (kSprings)
                springs::lane_force(m, rows, g, lane0, self, fx, fy, fz);  // springs off the rings
            gas::lane_faces(m, rows, g, lane0, self, rx, ry, rz, gx, gy, gz, six_v);  // odd fans
            for (int l = 0; l < kLanes && first + l < n; ++l) {
                const index i = first + l;
                store(f, i, {fx[l], fy[l], fz[l]});
                store(gas.volume_gradient, i, {gx[l], gy[l], gz[l]});
                const index body = m.particle_body[i];
                if (body >= 0) body_six_v[body] += six_v[l];
            }
        }
}

/// The packed rows (8 G, 8) of the vertex-major pass: x, v of particles [i0, i1) on one line
/// each.
inline void pack_rows(const double* q, const double* qd, double* rows, index i0, index i1) {
    for (index i = i0; i < i1; ++i)
        for (int k = 0; k < 3; ++k) {
            rows[kRow * i + k] = q[3 * i + k];
            rows[kRow * i + 3 + k] = qd[3 * i + k];
        }
}

/// The vertex-major pass over every particle (see vertex_pass_groups), on the opt-in threads
/// when there are: chunk c takes a fixed run of groups and keeps its own volume sums, added
/// in chunk order, so a run repeats to the bit whatever the threads' timing.
template <bool kSprings = true>
inline void vertex_pass(const Model& m, const double* q, const double* qd, const BodyGas& gas,
                        const LaneBuffers& lanes, double* f) {
    const int chunks = lanes.parallel != nullptr ? lanes.parallel->chunks : 1;
    const index bodies = m.body_count, groups = m.group_count;
    if (chunks <= 1) {
        pack_rows(q, qd, lanes.rows, 0, m.particle_count);
        for (index b = 0; b < bodies; ++b) gas.volume[b] = 0.0;
        vertex_pass_groups<kSprings>(m, lanes.rows, gas, f, 0, groups, gas.volume);
    } else {
        struct Work {
            const Model* m;
            const double *q, *qd;
            const BodyGas* gas;
            const LaneBuffers* lanes;
            double* f;
            int chunks;
        } work{&m, q, qd, &gas, &lanes, f, chunks};
        lanes.parallel->run(*lanes.parallel, [](void* context, int c) {
            const Work& w = *static_cast<const Work*>(context);
            // chunk c's groups: a fixed share of them, whatever the timing
            const index g0 = w.m->group_count * c / w.chunks;
            const index g1 = w.m->group_count * (c + 1) / w.chunks;
            pack_rows(w.q, w.qd, w.lanes->rows, std::min(kGroup * g0, w.m->particle_count),
                      std::min(kGroup * g1, w.m->particle_count));
        }, &work);
        lanes.parallel->run(*lanes.parallel, [](void* context, int c) {
            const Work& w = *static_cast<const Work*>(context);
            double* six_v = w.lanes->chunk_volume + c * w.m->body_count;
            for (index b = 0; b < w.m->body_count; ++b) six_v[b] = 0.0;
            vertex_pass_groups<kSprings>(*w.m, w.lanes->rows, *w.gas, w.f, w.m->group_count * c / w.chunks,
                               w.m->group_count * (c + 1) / w.chunks, six_v);
        }, &work);
        for (index b = 0; b < bodies; ++b) {
            double six_v = 0.0;
            for (int c = 0; c < chunks; ++c) six_v += lanes.chunk_volume[c * bodies + b];
            gas.volume[b] = six_v;
        }
    }
    for (index b = 0; b < bodies; ++b) gas.volume[b] /= 18.0;  // each face thrice: 3 x 6 V
}

/// Whether the force pass runs vertex-major: with SIMD lanes, or on threads (each thread
/// then writes only its own particles' rows).
inline bool use_vertex_pass(const LaneBuffers& lanes) {
    return kLanes > 1 || (lanes.parallel != nullptr && lanes.parallel->chunks > 1);
}

/// All forces at time t [s] for q, qd (N, 3) into f (N, 3) [N]: the list of physics terms.
/// With SIMD lanes (or threads) the weight, springs and dV/dx come from the vertex-major
/// pass; on the scalar path, term by term over springs and faces (half the arithmetic: each
/// spring and face once, which is what pays without lanes). The same terms either way; the
/// sums run in another order, so the paths agree to round-off.
inline void eval_forces(const Model& m, const Control& c, double t, const double* q,
                        const double* qd, const BodyGas& gas, const LaneBuffers& lanes,
                        double* f) {
    if (use_vertex_pass(lanes)) {
        vertex_pass(m, q, qd, gas, lanes, f);  // weight, springs, dV/dx, exact volumes
        volume::evaluate(m, q, gas, true);     // bounding and Monte Carlo volumes
    } else {
        gravity::force(m, f);           // weight m g (initialises the accumulator)
        springs::force(m, q, qd, f);    // damped Hooke springs: edges, bending, user
        volume::evaluate(m, q, gas);    // volumes and dV/dx
    }
    gas::pressures(m, c, t, gas);        // the gas law's P(V, t)
    gas::force(m, gas, f);               // (P - P_ambient) dV/dx
    attachments::force(m, c, q, qd, f);  // springs to anchor points
    external::force(m, c, f);            // per-step forces from Control
    external::grab_force(c, q, qd, f);   // a grabbed particle pulled to a target
    drag::force(m, c, q, qd, f);         // air drag on faces (skipped when off)
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
        eval_forces(m, c, t + 0.5 * dt, w.qs, w.vs, w.gas, w.lanes, w.f);
        stage(m, w.q0, w.v0, dt, w.vs, w.f, q, qd);
    } else if (scheme == 2) {  // classical RK4
        for (index k = 0; k < 3 * n; ++k) w.acc_q[k] = w.acc_v[k] = 0.0;
        accumulate(m, 1.0, w.v0, w.f, w.acc_q, w.acc_v);
        stage(m, w.q0, w.v0, 0.5 * dt, w.v0, w.f, w.qs, w.vs);
        eval_forces(m, c, t + 0.5 * dt, w.qs, w.vs, w.gas, w.lanes, w.f);
        accumulate(m, 2.0, w.vs, w.f, w.acc_q, w.acc_v);
        stage(m, w.q0, w.v0, 0.5 * dt, w.vs, w.f, w.qs, w.vs);
        eval_forces(m, c, t + 0.5 * dt, w.qs, w.vs, w.gas, w.lanes, w.f);
        accumulate(m, 2.0, w.vs, w.f, w.acc_q, w.acc_v);
        stage(m, w.q0, w.v0, dt, w.vs, w.f, w.qs, w.vs);
        eval_forces(m, c, t + dt, w.qs, w.vs, w.gas, w.lanes, w.f);
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
        eval_forces(m, c, t + dt, q, w.vs, w.gas, w.lanes, w.f);
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
        eval_forces(m, c, t, s.q, s.qd, w.gas, w.lanes, w.f);
        RunResult r = loop::check_volumes(m, w.gas.volume, p.ratio_min, p.ratio_max);
        if (r.status != OK) {
            r.steps_done = step_index;
            return r;
        }
        step(m, c, p.scheme, t, p.dt, s.q, s.qd, w);
        // contacts and particle checks; a failure (or a hash too small) undoes the step
        r = loop::end_step(m, c, p, step_index, t, s, w.q0, w.v0, w.contact);
        if (r.status != OK) return r;
    }
    return {OK, p.steps, -1, 0.0};
}

}  // namespace softbody::SOFTBODY_KERNELS::explicit_solver
