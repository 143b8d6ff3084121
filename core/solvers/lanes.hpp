// The vertex-major force pass: every particle, kLanes at a time, computes its own share of
// the terms that have a lane form (gravity::lane_force, springs::lane_pair and lane_force,
// gas::lane_face and lane_faces, membrane::lane_triangle and lane_force: the weight, the
// springs, dV/dx and the exact volumes, the membranes), reading its neighbours' rows and
// writing only its own. A fused kernel: one ring of neighbour rows serves a spring and two
// faces each, and the membrane triangles on those faces. The terms it covers say so (kLane),
// and solvers/forms.hpp skips their edge-major forces when it ran.
#pragma once

#include "model.hpp"
#include "simd.hpp"
#include "terms/gas.hpp"
#include "terms/gravity.hpp"
#include "terms/membrane.hpp"
#include "terms/springs.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::lanes {

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
/// spring and two faces each, and with kMembranes the membrane triangles on those faces
/// (each seen from its three corners) and those off the rings. Writes the particles' rows
/// of f and gas.volume_gradient (N, 3) and nothing else's.
template <bool kSprings, bool kMembranes = false>
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
            Rows first_row{}, last_row{};  // the ring's first and previous rows (membranes)
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
                    if constexpr (kMembranes) first_row = o;
                } else {
                    gas::lane_face(ux, uy, uz, dx, dy, dz, load_lanes(m.slots.ring_face + e), rx,
                                   ry, rz, gx, gy, gz, six_v);
                    if constexpr (kMembranes)
                        membrane::lane_triangle(m, membrane::ring_geometry(m, s, lane0),
                                                m.slots.ring_membrane_row + e, self, last_row, ux,
                                                uy, uz, o, dx, dy, dz, fx, fy, fz);
                }
                ux = dx, uy = dy, uz = dz;
                if constexpr (kMembranes) last_row = o;
            }
            if (m.slots.ring_start[g + 1] > m.slots.ring_start[g]) {
                const index e0 = kGroup * m.slots.ring_start[g] + lane0;
                gas::lane_face(ux, uy, uz, ux0, uy0, uz0, load_lanes(m.slots.ring_face + e0), rx,
                               ry, rz, gx, gy, gz, six_v);
                if constexpr (kMembranes)
                    membrane::lane_triangle(
                        m, membrane::ring_geometry(m, m.slots.ring_start[g], lane0),
                        m.slots.ring_membrane_row + e0, self, last_row, ux, uy, uz, first_row,
                        ux0, uy0, uz0, fx, fy, fz);
            }
            if constexpr (kSprings)
                springs::lane_force(m, rows, g, lane0, self, fx, fy, fz);  // springs off the rings
            if constexpr (kMembranes)
                membrane::lane_force(m, rows, g, lane0, self, fx, fy, fz);  // triangles off them
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

/// The membrane triangles on the ring's faces of particles [kGroup g + lane0, + kLanes)
/// (vertex_pass_groups' kMembranes part, for the float32 pass: its float64 rows), their
/// force added to fx, fy, fz [N].
inline void membrane_ring(const Model& m, const double* rows, index g, int lane0,
                          const Rows& self, vd& fx, vd& fy, vd& fz) {
    const index s0 = m.slots.ring_start[g], s1 = m.slots.ring_start[g + 1];
    if (s1 == s0) return;
    Rows first_row{}, last_row{};
    for (index s = s0; s < s1; ++s) {
        const index e = kGroup * s + lane0;
        const Rows o = load_rows(rows, m.slots.ring_other + e);
        if (s == s0)
            first_row = o;
        else
            membrane::lane_triangle(m, membrane::ring_geometry(m, s, lane0),
                                    m.slots.ring_membrane_row + e, self, last_row,
                                    last_row.x - self.x, last_row.y - self.y, last_row.z - self.z,
                                    o, o.x - self.x, o.y - self.y, o.z - self.z, fx, fy, fz);
        last_row = o;
    }
    membrane::lane_triangle(m, membrane::ring_geometry(m, s0, lane0),
                            m.slots.ring_membrane_row + kGroup * s0 + lane0, self, last_row,
                            last_row.x - self.x, last_row.y - self.y, last_row.z - self.z,
                            first_row, first_row.x - self.x, first_row.y - self.y,
                            first_row.z - self.z, fx, fy, fz);
}

/// The float32 vertex-major pass over groups [g0, g1) (lanes.rows_f set): the ring's springs
/// and faces as in vertex_pass_groups, in float lanes from body-local float rows, with
/// float copies of the ring tables; the weight, the sums into f, dV/dx and the volumes, the
/// springs off the rings, the faces of broken fans and the membranes (from the float64
/// rows) in float64.
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
                f[3 * i] = mass * m.gravity.acceleration[0] + static_cast<double>(fx[l]);
                f[3 * i + 1] = mass * m.gravity.acceleration[1] + static_cast<double>(fy[l]);
                f[3 * i + 2] = mass * m.gravity.acceleration[2] + static_cast<double>(fz[l]);
                store(gas.volume_gradient, i,
                      {static_cast<double>(gx[l]), static_cast<double>(gy[l]),
                       static_cast<double>(gz[l])});
                sums.add(m.particles.body[i], static_cast<double>(six_v[l]));
            }
        }
    sums.flush();
    if (!lanes.extra_slots) return;
    // springs off the rings, faces of broken fans and the membranes: in float64, added to
    // what is there
    const bool membranes = m.membranes.count > 0;
    for (index g = g0; g < g1; ++g) {
        if (m.slots.spring_start[g + 1] == m.slots.spring_start[g] &&
            m.slots.face_start[g + 1] == m.slots.face_start[g] && !membranes)
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
            if (membranes) {
                membrane_ring(m, lanes.rows, g, lane0, self, fx, fy, fz);
                membrane::lane_force(m, lanes.rows, g, lane0, self, fx, fy, fz);
            }
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

/// The float64 pass over groups [g0, g1) (vertex_pass_groups), with the membranes' lane
/// form when kMembranes and the model has any (and without the springs when it has none).
template <bool kSprings, bool kMembranes>
inline void groups_f64(const Model& m, const double* rows, const BodyGas& gas, double* f,
                       index g0, index g1, double* body_six_v) {
    if (kMembranes && m.membranes.count > 0) {
        if (kSprings && m.springs.count > 0)
            vertex_pass_groups<kSprings, true>(m, rows, gas, f, g0, g1, body_six_v);
        else  // a skin of membranes alone: no springs to walk
            vertex_pass_groups<false, true>(m, rows, gas, f, g0, g1, body_six_v);
    } else
        vertex_pass_groups<kSprings, false>(m, rows, gas, f, g0, g1, body_six_v);
}

/// The vertex-major pass over every particle (see vertex_pass_groups), on the opt-in threads
/// when there are: chunk c takes a fixed run of groups and keeps its own volume sums, added
/// in chunk order, so a run repeats to the bit whatever the threads' timing.
template <bool kSprings = true, bool kMembranes = true>
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
            groups_f64<kSprings, kMembranes>(m, lanes.rows, gas, f, 0, groups, gas.volume);
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
                groups_f64<kSprings, kMembranes>(*w.m, w.lanes->rows, *w.gas, w.f, g0, g1, six_v);
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

}  // namespace softbody::SOFTBODY_KERNELS::lanes
