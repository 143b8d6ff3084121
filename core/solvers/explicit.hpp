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

/// Sums into body_six_v (B,) in particle order, in a register while the particles' body
/// stays the same (a store and reload per particle would chain each sum on the last).
struct VolumeSums {
    double* body_six_v;
    index body = -1;
    double sum = 0.0;
    void add(index b, double value) {
        if (b != body) {
            flush();
            body = b;
            if (b >= 0) sum = body_six_v[b];
        }
        if (b >= 0) sum += value;
    }
    void flush() {
        if (body >= 0) body_six_v[body] = sum;
        body = -1;
    }
};

/// The vertex-major pass over groups [g0, g1): for every particle, kLanes at a time, its
/// weight, its springs (kSprings; projective dynamics solves them implicitly) and dV/dx
/// from its faces, with its share of its body's exact volume (each face seen from its three
/// corners: 3 x 6 V in all, added to body_six_v (B,)). The ring's neighbour rows serve a
/// spring and two faces each. Writes the particles' rows of f and gas.volume_gradient (N, 3)
/// and nothing else's.
template <bool kSprings>
inline void vertex_pass_groups(const Model& m, const double* rows, const BodyGas& gas, double* f,
                               index g0, index g1, double* body_six_v) {
    const index n = m.particles.count;
    VolumeSums sums{body_six_v};
    for (index g = g0; g < g1; ++g)
        for (int lane0 = 0; lane0 < kGroup; lane0 += kLanes) {
            const index first = kGroup * g + lane0;
            if (first >= n) break;
            index own[kLanes];
            for (int l = 0; l < kLanes; ++l) own[l] = first + l;
            const Rows self = load_rows(rows, own);
            const Rows ref = load_rows(rows, m.slots.reference + first);
            const vd rx = self.x - ref.x, ry = self.y - ref.y, rz = self.z - ref.z;
            vd fx, fy, fz, gx{}, gy{}, gz{}, six_v{};
            gravity::lane_force(m, first, fx, fy, fz);  // weight m g
            // the ring: damped edge springs, and the faces between consecutive neighbours
            vd ux0{}, uy0{}, uz0{}, ux{}, uy{}, uz{};
            for (index s = m.slots.ring_start[g]; s < m.slots.ring_start[g + 1]; ++s) {
                const index e = kGroup * s + lane0;
                const Rows o = load_rows(rows, m.slots.ring_other + e);
                const vd dx = o.x - self.x, dy = o.y - self.y, dz = o.z - self.z;
                if constexpr (kSprings)
                    springs::lane_pair(self, o, dx, dy, dz,
                                       load_lanes(m.slots.ring_rest_length + e),
                                       load_lanes(m.slots.ring_stiffness + e),
                                       load_lanes(m.slots.ring_damping + e), fx, fy, fz);
                if (s == m.slots.ring_start[g]) {
                    ux0 = dx, uy0 = dy, uz0 = dz;  // the face closing the ring comes last
                } else {
                    gas::lane_face(ux, uy, uz, dx, dy, dz, load_lanes(m.slots.ring_face + e), rx,
                                   ry, rz, gx, gy, gz, six_v);
                }
                ux = dx, uy = dy, uz = dz;
            }
            if (m.slots.ring_start[g + 1] > m.slots.ring_start[g])
                gas::lane_face(ux, uy, uz, ux0, uy0, uz0,
                               load_lanes(m.slots.ring_face + kGroup * m.slots.ring_start[g] + lane0),
                               rx, ry, rz, gx, gy, gz, six_v);
            if constexpr (kSprings)
                springs::lane_force(m, rows, g, lane0, self, fx, fy, fz);  // springs off the rings
            gas::lane_faces(m, rows, g, lane0, self, rx, ry, rz, gx, gy, gz, six_v);  // odd fans
            for (int l = 0; l < kLanes && first + l < n; ++l) {
                const index i = first + l;
                store(f, i, {fx[l], fy[l], fz[l]});
                store(gas.volume_gradient, i, {gx[l], gy[l], gz[l]});
                sums.add(m.particles.body[i], six_v[l]);
            }
        }
    sums.flush();
}

/// The float32 vertex-major pass over groups [g0, g1) (lanes.rows_f set): the ring's springs
/// and faces as in vertex_pass_groups, in float lanes from body-local float rows, with
/// float copies of the ring tables; the weight, the sums into f, dV/dx and the volumes, the
/// springs off the rings and the faces of broken fans (from the float64 rows) in float64.
/// Positions, velocities and the integration stay float64: the float32 part only perturbs
/// the forces by the rounding of x - x_ref and v to float32 (2^-24 of their size).
inline void vertex_pass_groups_f32(const Model& m, const LaneBuffers& lanes, const BodyGas& gas,
                                   double* f, index g0, index g1, double* body_six_v) {
    const index n = m.particles.count;
    VolumeSums sums{body_six_v};
    for (index g = g0; g < g1; ++g)
        for (int lane0 = 0; lane0 < kGroup; lane0 += kLanesF) {
            const index first = kGroup * g + lane0;
            if (first >= n) break;
            index own[kLanesF];
            for (int l = 0; l < kLanesF; ++l) own[l] = first + l;
            const RowsF self = load_rows_f(lanes.rows_f, own);
            vf fx{}, fy{}, fz{}, gx{}, gy{}, gz{}, six_v{};
            vf ux0{}, uy0{}, uz0{}, ux{}, uy{}, uz{};
            for (index s = m.slots.ring_start[g]; s < m.slots.ring_start[g + 1]; ++s) {
                const index e = kGroup * s + lane0;
                const RowsF o = load_rows_f(lanes.rows_f, m.slots.ring_other + e);
                const vf dx = o.x - self.x, dy = o.y - self.y, dz = o.z - self.z;
                springs::lane_pair(self, o, dx, dy, dz, load_lanes_f(lanes.ring_rest_length_f + e),
                                   load_lanes_f(lanes.ring_stiffness_f + e),
                                   load_lanes_f(lanes.ring_damping_f + e), fx, fy, fz);
                if (s == m.slots.ring_start[g]) {
                    ux0 = dx, uy0 = dy, uz0 = dz;  // the face closing the ring comes last
                } else {
                    gas::lane_face(ux, uy, uz, dx, dy, dz, load_lanes_f(lanes.ring_face_f + e),
                                   self.x, self.y, self.z, gx, gy, gz, six_v);
                }
                ux = dx, uy = dy, uz = dz;
            }
            if (m.slots.ring_start[g + 1] > m.slots.ring_start[g])
                gas::lane_face(ux, uy, uz, ux0, uy0, uz0,
                               load_lanes_f(lanes.ring_face_f + kGroup * m.slots.ring_start[g] + lane0),
                               self.x, self.y, self.z, gx, gy, gz, six_v);
            for (int l = 0; l < kLanesF && first + l < n; ++l) {
                const index i = first + l;
                const double mass = m.slots.mass[i];
                f[3 * i] = mass * m.gravity[0] + static_cast<double>(fx[l]);
                f[3 * i + 1] = mass * m.gravity[1] + static_cast<double>(fy[l]);
                f[3 * i + 2] = mass * m.gravity[2] + static_cast<double>(fz[l]);
                store(gas.volume_gradient, i,
                      {static_cast<double>(gx[l]), static_cast<double>(gy[l]),
                       static_cast<double>(gz[l])});
                sums.add(m.particles.body[i], static_cast<double>(six_v[l]));
            }
        }
    sums.flush();
    if (!lanes.extra_slots) return;
    // springs off the rings and faces of broken fans: in float64, added to what is there
    for (index g = g0; g < g1; ++g) {
        if (m.slots.spring_start[g + 1] == m.slots.spring_start[g] &&
            m.slots.face_start[g + 1] == m.slots.face_start[g])
            continue;
        for (int lane0 = 0; lane0 < kGroup; lane0 += kLanes) {
            const index first = kGroup * g + lane0;
            if (first >= n) break;
            index own[kLanes];
            for (int l = 0; l < kLanes; ++l) own[l] = first + l;
            const Rows self = load_rows(lanes.rows, own);
            const Rows ref = load_rows(lanes.rows, m.slots.reference + first);
            const vd rx = self.x - ref.x, ry = self.y - ref.y, rz = self.z - ref.z;
            vd fx{}, fy{}, fz{}, gx{}, gy{}, gz{}, six_v{};
            springs::lane_force(m, lanes.rows, g, lane0, self, fx, fy, fz);
            gas::lane_faces(m, lanes.rows, g, lane0, self, rx, ry, rz, gx, gy, gz, six_v);
            for (int l = 0; l < kLanes && first + l < n; ++l) {
                const index i = first + l;
                add_to(f, i, {fx[l], fy[l], fz[l]});
                add_to(gas.volume_gradient, i, {gx[l], gy[l], gz[l]});
                sums.add(m.particles.body[i], six_v[l]);
            }
        }
    }
    sums.flush();
}

/// The float rows of particles [i0, i1): x - x_ref (x_ref the position of the particle's
/// slots.reference, its body's first particle) and v, rounded to float32.
inline void pack_rows_f32(const Model& m, const double* q, const double* qd, float* rows,
                          index i0, index i1) {
    for (index i = i0; i < i1; ++i) {
        const index r = m.slots.reference[i];
        for (int k = 0; k < 3; ++k) {
            rows[kRow * i + k] = static_cast<float>(q[3 * i + k] - q[3 * r + k]);
            rows[kRow * i + 3 + k] = static_cast<float>(qd[3 * i + k]);
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

/// The rows the pass reads for particles [i0, i1): the float32 ones when it runs in float32
/// (with the float64 ones too when it has slots off the rings), else the float64 ones.
inline void pack(const Model& m, const double* q, const double* qd, const LaneBuffers& lanes,
                 index i0, index i1) {
    if (lanes.rows_f != nullptr) {
        pack_rows_f32(m, q, qd, lanes.rows_f, i0, i1);
        if (!lanes.extra_slots) return;
    }
    pack_rows(q, qd, lanes.rows, i0, i1);
}

/// The vertex-major pass over every particle (see vertex_pass_groups), on the opt-in threads
/// when there are: chunk c takes a fixed run of groups and keeps its own volume sums, added
/// in chunk order, so a run repeats to the bit whatever the threads' timing.
template <bool kSprings = true>
inline void vertex_pass(const Model& m, const double* q, const double* qd, const BodyGas& gas,
                        const LaneBuffers& lanes, double* f) {
    const int chunks = lanes.parallel != nullptr ? lanes.parallel->chunks : 1;
    const index bodies = m.bodies.count, groups = m.slots.group_count;
    const bool f32 = kSprings && lanes.rows_f != nullptr;  // the float32 force pass
    if (chunks <= 1) {
        pack(m, q, qd, lanes, 0, m.particles.count);
        for (index b = 0; b < bodies; ++b) gas.volume[b] = 0.0;
        if (f32)
            vertex_pass_groups_f32(m, lanes, gas, f, 0, groups, gas.volume);
        else
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
            const index g0 = w.m->slots.group_count * c / w.chunks;
            const index g1 = w.m->slots.group_count * (c + 1) / w.chunks;
            pack(*w.m, w.q, w.qd, *w.lanes, std::min(kGroup * g0, w.m->particles.count),
                 std::min(kGroup * g1, w.m->particles.count));
        }, &work);
        lanes.parallel->run(*lanes.parallel, [](void* context, int c) {
            const Work& w = *static_cast<const Work*>(context);
            double* six_v = w.lanes->chunk_volume + c * w.m->bodies.count;
            for (index b = 0; b < w.m->bodies.count; ++b) six_v[b] = 0.0;
            const index g0 = w.m->slots.group_count * c / w.chunks;
            const index g1 = w.m->slots.group_count * (c + 1) / w.chunks;
            if (kSprings && w.lanes->rows_f != nullptr)
                vertex_pass_groups_f32(*w.m, *w.lanes, *w.gas, w.f, g0, g1, six_v);
            else
                vertex_pass_groups<kSprings>(*w.m, w.lanes->rows, *w.gas, w.f, g0, g1, six_v);
        }, &work);
        for (index b = 0; b < bodies; ++b) {
            double six_v = 0.0;
            for (int c = 0; c < chunks; ++c) six_v += lanes.chunk_volume[c * bodies + b];
            gas.volume[b] = six_v;
        }
    }
    for (index b = 0; b < bodies; ++b) gas.volume[b] /= 18.0;  // each face thrice: 3 x 6 V
}

/// Whether the force pass runs vertex-major: with SIMD lanes, in float32, or on threads
/// (each thread then writes only its own particles' rows).
inline bool use_vertex_pass(const LaneBuffers& lanes) {
    return kLanes > 1 || lanes.rows_f != nullptr ||
           (lanes.parallel != nullptr && lanes.parallel->chunks > 1);
}

/// The weight and springs into f (N, 3) [N], the volumes, dV/dx and pressures into gas, at
/// time t [s] for q, qd (N, 3): what eval_forces starts with, and what the fused symplectic
/// Euler step takes before its pass adds the rest.
inline void eval_body(const Model& m, const Control& c, double t, const double* q,
                      const double* qd, const BodyGas& gas, const LaneBuffers& lanes, double* f) {
    if (use_vertex_pass(lanes)) {
        vertex_pass(m, q, qd, gas, lanes, f);  // weight, springs, dV/dx, exact volumes
        volume::evaluate(m, q, gas, true);     // bounding and Monte Carlo volumes
    } else {
        gravity::force(m, f);           // weight m g (initialises the accumulator)
        springs::force(m, q, qd, f);    // damped Hooke springs: edges, bending, user
        volume::evaluate(m, q, gas);    // volumes and dV/dx
    }
    gas::pressures(m, c, t, gas);        // the gas law's P(V, t)
}

/// All forces at time t [s] for q, qd (N, 3) into f (N, 3) [N]: the list of physics terms.
/// With SIMD lanes (or threads) the weight, springs and dV/dx come from the vertex-major
/// pass; on the scalar path, term by term over springs and faces (half the arithmetic: each
/// spring and face once, which is what pays without lanes). The same terms either way; the
/// sums run in another order, so the paths agree to round-off.
inline void eval_forces(const Model& m, const Control& c, double t, const double* q,
                        const double* qd, const BodyGas& gas, const LaneBuffers& lanes,
                        double* f) {
    eval_body(m, c, t, q, qd, gas, lanes, f);
    gas::force(m, gas, f);               // (P - P_ambient) dV/dx
    attachments::force(m, c, q, qd, f);  // springs to anchor points
    external::force(m, c, f);            // per-step forces from Control
    external::grab_force(c, q, qd, f);   // a grabbed particle pulled to a target
    drag::force(m, c, q, qd, f);         // air drag on faces (skipped when off)
}

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

/// One step of `scheme` from (w.q0, w.v0) with the start forces in w.f, into q, qd.
inline void step(const Model& m, const Control& c, int scheme, double t, double dt, double* q,
                 double* qd, const ExplicitBuffers& w) {
    const index n = m.particles.count;
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
            const double h = dt * m.particles.inv_mass[i];
            for (int k = 0; k < 3; ++k) {
                const index r = 3 * i + k;
                const double v = w.v0[r] + h * w.f[r];
                qd[r] = v;
                q[r] = w.q0[r] + dt * v;
            }
        }
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
        eval_forces(m, c, t + dt, q, w.vs, w.gas, w.lanes, w.f);
        for (index i = 0; i < n; ++i) {
            const double h = 0.5 * dt * m.particles.inv_mass[i];
            for (int k = 0; k < 3; ++k) qd[3 * i + k] = w.vs[3 * i + k] + h * w.f[3 * i + k];
        }
    }
}

/// Whether symplectic Euler can end its steps in one fused pass (symplectic_pass): no term
/// added after the body's forces other than the pressure and Control forces (attachments,
/// the grab spring and drag would change the order of the sums), and bodies whose particle
/// ranges follow one another.
inline bool fused_symplectic(const Model& m, const Control& c, int scheme) {
    if (scheme != 3 || m.attachments.count > 0 || m.drag.active || c.grab_particle >= 0)
        return false;
    index end = 0;
    for (index b = 0; b < m.bodies.count; ++b) {
        if (m.bodies.particle_range[2 * b] < end) return false;
        end = m.bodies.particle_range[2 * b + 1];
    }
    return true;
}

/// Symplectic Euler's step in one pass over the flat (N, 3) arrays, kLanes values at a time:
/// f + (P - P_ambient) dV/dx + Control.particle_f (the terms eval_forces adds after
/// eval_body, in its order), v = v0 + h f with h = dt / m (h3 (N, 3), per component),
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

/// Symplectic Euler's steps with the end of each fused (fused_symplectic): the body's forces
/// (eval_body), the volume check, one pass for the rest of the forces, the kick, the drift
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
    for (index step_index = 0; step_index < p.steps; ++step_index) {
        if (stop_requested(p, step_index)) return {STOPPED, step_index, -1, 0.0};
        const double t = p.t0 + static_cast<double>(step_index) * p.dt;
        eval_body(m, c, t, s.q, s.qd, w.gas, w.lanes, w.f);
        RunResult r = loop::check_volumes(m, w.gas.volume, p.ratio_min, p.ratio_max);
        if (r.status != OK) {
            r.steps_done = step_index;
            return r;
        }
        colliders::Seen seen;
        symplectic_pass(m, c, p.dt, h3, w.gas, w.f, s.q, s.qd, w.q0, w.v0, seen);
        const index needed = loop::contacts(m, c, p, step_index, t + p.dt, s, w.q0, w.contact, &seen);
        if (needed > 0)
            r = {NEED_HASH, step_index, -1, static_cast<double>(needed)};
        else if (m.soft_contacts.mode != 0)  // soft contacts moved particles unseen
            r = loop::check_particles(m, s.q, s.qd, p.max_speed);
        else
            r = loop::check_seen(m, s.q, s.qd, p.max_speed, seen.bad, seen.most);
        if (r.status != OK) {
            loop::copy(w.q0, s.q, 3 * n);
            loop::copy(w.v0, s.qd, 3 * n);
            r.steps_done = step_index;
            return r;
        }
    }
    return {OK, p.steps, -1, 0.0};
}

/// Advance s.q, s.qd by p.steps steps of p.dt from p.t0. On a particle failure the state goes
/// back to the failing step's start; on a volume failure it is the state whose volume failed.
/// NEED_HASH (value: the entries needed) also leaves the state at the failing step's start.
inline RunResult simulate(const Model& m, const Control& c, const RunParams& p,
                          const StateView& s, const ExplicitBuffers& w) {
    const index n3 = 3 * m.particles.count;
    loop::begin_run(m, c, p, s, w.contact);
    if (fused_symplectic(m, c, p.scheme)) return simulate_symplectic_fused(m, c, p, s, w);
    for (index step_index = 0; step_index < p.steps; ++step_index) {
        if (stop_requested(p, step_index)) return {STOPPED, step_index, -1, 0.0};
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
