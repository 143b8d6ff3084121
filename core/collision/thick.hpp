// Surface contacts with a thickness h (soft_contacts.thickness > 0): vertex-triangle and
// edge-edge pairs between bodies, and within a body when soft_contacts.self_contact, pairs
// of adjacent elements (a vertex of the triangle, edges sharing a vertex) left out. The
// contact stage of a step, from the step's start positions q0 to the positions q the
// solver reached:
//   1. T, the mass-weighted mean displacement of the bodies' free particles: a translation
//      common to all changes no distance, so the broad phase and the bound below look at
//      u_i = q_i - q0_i - T only (a body in free fall finds no pair from its fall).
//   2. Broad phase: a spatial hash of the triangles' boxes over their corners' q0 and
//      q0 + u, grown by the margin g >= h (soft_contacts.margin); each vertex's and each
//      edge's box over the same points is looked up in it. Every pair whose boxes meet is a
//      candidate, with its distance D at the step's start. Any pair of primitives that could
//      meet below (every path stays in its box grown by h / 2) is a candidate. Most steps
//      take their candidates from a list kept between steps instead (see contacts()).
//   3. A pre-existing crossing (an edge through a non-adjacent triangle at q0: an initial
//      self-intersection, or a collider that pushed one sheet through another) stops the
//      run with Status CROSSED and says where; nothing is changed.
//   4. The displacement bound (conservative, "Offset Geometric Contact" / Codimensional
//      IPC): each particle's u_i is scaled by s_i in [0, 1] so that for every candidate
//      pair the relative displacement of its particles, max |s_i u_i - s_j u_j|, is at most
//      kGamma D. Along the straight path from q0 to q0 + T + s u the pair's distance then
//      stays >= (1 - kGamma) D > 0: no vertex-triangle or edge-edge contact, hence no
//      crossing, whatever the step. A violating pair caps its particles at
//      s_k |u_k| <= kGamma D / 2 (pinned particles keep their motion, and take their share
//      of the budget); passes repeat until none violates (each pair caps at most once).
//   5. Response at the bounded positions: a pair closer than h is pushed apart to h along
//      its gap (mass-weighted, barycentric weights on both sides), and its approaching
//      relative velocity is reflected with the restitution, its tangential part reduced by
//      the friction (the surface mode's velocity-level rule); every impulse has its
//      opposite, so momentum is conserved. Each particle's response move is clipped to
//      h / 2 (it stays in its grown box), then step 4 runs again on the whole displacement.
// Velocities are not changed by the bound (a particle it holds back keeps its velocity,
// and the response turns it once it is within h).
#pragma once

#include <cstring>

#include "collision/soft.hpp"
#include "model.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::thick {

constexpr double kGamma = 0.4;  // fraction of a pair's start distance its relative motion may close
constexpr index kSlots = ContactBuffers::kPairSlots;  // kind, four particles, D (bits)
enum : index { kVertexTriangle = 0, kEdgeEdge = 1 };

/// Closest points of segments p1-q1 and p2-q2: parameters s, t in [0, 1] (Ericson,
/// Real-Time Collision Detection 5.1.9; a degenerate segment is a point).
inline void closest_segments(V3 p1, V3 q1, V3 p2, V3 q2, double& s, double& t) {
    const V3 d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
    const double a = dot(d1, d1), e = dot(d2, d2), f = dot(d2, r);
    const double tiny = 1e-300;
    auto clamp01 = [](double x) { return std::min(1.0, std::max(0.0, x)); };
    if (a <= tiny && e <= tiny) {
        s = t = 0.0;
        return;
    }
    if (a <= tiny) {
        s = 0.0;
        t = clamp01(f / e);
        return;
    }
    const double c = dot(d1, r);
    if (e <= tiny) {
        t = 0.0;
        s = clamp01(-c / a);
        return;
    }
    const double b = dot(d1, d2), denom = a * e - b * b;
    s = denom > 0.0 ? clamp01((b * f - c * e) / denom) : 0.0;
    t = (b * s + f) / e;
    if (t < 0.0) {
        t = 0.0;
        s = clamp01(-c / a);
    } else if (t > 1.0) {
        t = 1.0;
        s = clamp01((b - c) / a);
    }
}

/// The gap of a pair at positions x: sum_k c_k x_k, with its coefficients c (sum 0): the
/// vertex minus the closest point of the triangle, or the first edge's closest point
/// minus the second's.
inline V3 gap(const double* x, index kind, const index* v, double* c) {
    const V3 a = load(x, v[0]), b = load(x, v[1]), d = load(x, v[2]), e = load(x, v[3]);
    if (kind == kVertexTriangle) {
        const soft::TrianglePoint p = soft::closest_point_on_triangle(a, b, d, e);
        c[0] = 1.0;
        c[1] = -p.wa;
        c[2] = -p.wb;
        c[3] = -p.wc;
        return a - p.x;
    }
    double s = 0.0, t = 0.0;
    closest_segments(a, b, d, e, s, t);
    c[0] = 1.0 - s;
    c[1] = s;
    c[2] = -(1.0 - t);
    c[3] = -t;
    return (a + s * (b - a)) - (d + t * (e - d));
}

/// Whether segment a-b passes through the inside of triangle (p0, p1, p2) (Moller-Trumbore;
/// touching an edge of it or ending on it within round-off does not count).
inline bool segment_crosses(V3 a, V3 b, V3 p0, V3 p1, V3 p2) {
    const V3 d = b - a, e1 = p1 - p0, e2 = p2 - p0;
    const V3 h = cross(d, e2);
    const double det = dot(e1, h);
    const double scale = std::sqrt(dot(d, d) * dot(e1, e1) * dot(e2, e2));
    if (!(std::fabs(det) > 1e-12 * scale)) return false;  // parallel or degenerate
    const double inv = 1.0 / det;
    const V3 sv = a - p0;
    const double u = inv * dot(sv, h);
    const V3 qv = cross(sv, e1);
    const double w = inv * dot(d, qv), s = inv * dot(e2, qv);
    constexpr double kIn = 1e-9;
    return u > kIn && w > kIn && u + w < 1.0 - kIn && s > kIn && s < 1.0 - kIn;
}

/// The stage's shared values.
struct Stage {
    const Model& m;
    const double* q0;  // (N, 3) the step's start
    double* q;         // (N, 3) the positions, changed in place
    const ContactBuffers& w;
    V3 T;              // the common translation
    double inv;        // 1 / cell size
    double g;          // the distance boxes grow by before they are compared
    bool self;         // pairs within a body too
    bool swept = true; // boxes over q0 and q - T (the step's pairs), or q0 alone (the list's)
    double keep = std::numeric_limits<double>::infinity();  // pairs nearer than this are kept
};

/// Box of particle i over q0 and q0 + u (u = q - q0 - T), or q0 alone, into lo, hi.
inline void particle_box(const Stage& st, index i, double* lo, double* hi) {
    for (int k = 0; k < 3; ++k) {
        const double a = st.q0[3 * i + k];
        const double b = st.swept ? st.q[3 * i + k] - (&st.T.x)[k] : a;
        lo[k] = std::min(a, b);
        hi[k] = std::max(a, b);
    }
}

inline bool boxes_meet(const double* lo, const double* hi, const double* lo2, const double* hi2,
                       double grow) {
    for (int k = 0; k < 3; ++k)
        if (hi[k] + grow < lo2[k] || hi2[k] + grow < lo[k]) return false;
    return true;
}

/// Hash of the triangles' boxes (over their corners' boxes, grown by g) into w.hash_*, the
/// boxes themselves into w.tri_box (T, 6). Counts first; returns the entries needed, and
/// stores no entry when they exceed the capacity (soft::hash_triangles' contract).
inline index build_hash(const Stage& st) {
    const Model& m = st.m;
    const ContactBuffers& w = st.w;
    for (index t = 0; t < m.triangles.count; ++t) {
        double* box = w.tri_box + 6 * t;
        for (int k = 0; k < 3; ++k) {
            box[k] = std::numeric_limits<double>::infinity();
            box[3 + k] = -std::numeric_limits<double>::infinity();
        }
        for (int c = 0; c < 3; ++c) {
            double lo[3], hi[3];
            particle_box(st, m.triangles.indices[3 * t + c], lo, hi);
            for (int k = 0; k < 3; ++k) {
                box[k] = std::min(box[k], lo[k]);
                box[3 + k] = std::max(box[3 + k], hi[k]);
            }
        }
    }
    return soft::hash_triangles(m, w, [&](index t, index* r) {
        const double* box = w.tri_box + 6 * t;
        for (int k = 0; k < 3; ++k) {
            r[k] = soft::cell_of((box[k] - st.g) * st.inv);
            r[3 + k] = soft::cell_of((box[3 + k] + st.g) * st.inv);
        }
    });
}

/// Each triangle whose grown box meets the box [lo, hi], once (in the first grid cell the
/// two share): calls visit(t); stops when visit returns false.
template <class Visit>
inline bool each_triangle(const Stage& st, const double* lo, const double* hi, Visit visit) {
    const ContactBuffers& w = st.w;
    index r[6];
    for (int k = 0; k < 3; ++k) {
        r[k] = soft::cell_of(lo[k] * st.inv);
        r[3 + k] = soft::cell_of(hi[k] * st.inv);
    }
    for (index ix = r[0]; ix <= r[3]; ++ix)
        for (index iy = r[1]; iy <= r[4]; ++iy)
            for (index iz = r[2]; iz <= r[5]; ++iz) {
                const index h = soft::cell_hash(ix, iy, iz, w.hash_table);
                for (index e = w.hash_start[h]; e < w.hash_start[h + 1]; ++e) {
                    const index t = w.hash_entries->data[e];
                    const double* box = w.tri_box + 6 * t;
                    if (!boxes_meet(lo, hi, box, box + 3, st.g)) continue;
                    // the first cell of the two ranges' overlap: visited there only
                    const index c[3] = {ix, iy, iz};
                    bool first = true;
                    for (int k = 0; k < 3 && first; ++k) {
                        const index start = std::max(r[k], soft::cell_of((box[k] - st.g) * st.inv));
                        first = c[k] == start;
                    }
                    if (first && !visit(t)) return false;
                }
            }
    return true;
}

/// Whether particles of bodies a and b may touch (other bodies always, the same body with
/// self-contact).
inline bool bodies_pair(const Stage& st, index a, index b) { return a != b || st.self; }

/// Appends a candidate pair (kind, v, start distance D); false when the buffer is full
/// (the count still grows: the caller grows the buffer to it and starts again).
inline void add_pair(const ContactBuffers& w, index& count, index kind, const index* v,
                     double distance) {
    if ((count + 1) * kSlots <= w.pairs->capacity) {
        index* row = w.pairs->data + kSlots * count;
        row[0] = kind;
        for (int k = 0; k < 4; ++k) row[1 + k] = v[k];
        std::memcpy(row + 5, &distance, sizeof(double));
    }
    ++count;
}

inline double pair_distance(const index* row) {
    double d = 0.0;
    std::memcpy(&d, row + 5, sizeof(double));
    return d;
}

/// The candidate pairs into w.pairs; returns their count, or -1 after writing a crossing
/// found at q0 into w.crossing (particle, triangle).
inline index collect(const Stage& st) {
    const Model& m = st.m;
    const ContactBuffers& w = st.w;
    index count = 0;
    bool crossed = false;
    // vertices against triangles
    for (index b = 0; b < m.bodies.count; ++b)
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1];
             ++i) {
            double lo[3], hi[3];
            particle_box(st, i, lo, hi);
            each_triangle(st, lo, hi, [&](index t) {
                const index* tri = m.triangles.indices + 3 * t;
                if (!bodies_pair(st, b, m.triangles.body[t])) return true;
                if (tri[0] == i || tri[1] == i || tri[2] == i) return true;  // adjacent
                const index v[4] = {i, tri[0], tri[1], tri[2]};
                double c[4];
                const V3 d = gap(st.q0, kVertexTriangle, v, c);
                const double dist = std::sqrt(dot(d, d));
                if (dist < st.keep) add_pair(w, count, kVertexTriangle, v, dist);
                return true;
            });
        }
    // edges against edges (each edge once, in the triangle that owns it), and edges through
    // triangles at the start
    for (index t = 0; t < m.triangles.count && !crossed; ++t)
        for (int k = 0; k < 3 && !crossed; ++k) {
            const index* tri = m.triangles.indices + 3 * t;
            if (m.triangles.edge_owner[3 * t + k] == 0) continue;
            const index a = tri[k], b = tri[(k + 1) % 3];
            const index body = m.triangles.body[t];
            double lo[3], hi[3], lo2[3], hi2[3];
            particle_box(st, a, lo, hi);
            particle_box(st, b, lo2, hi2);
            for (int d = 0; d < 3; ++d) {
                lo[d] = std::min(lo[d], lo2[d]);
                hi[d] = std::max(hi[d], hi2[d]);
            }
            each_triangle(st, lo, hi, [&](index t2) {
                const index* tri2 = m.triangles.indices + 3 * t2;
                if (!bodies_pair(st, body, m.triangles.body[t2])) return true;
                const bool touches = tri2[0] == a || tri2[1] == a || tri2[2] == a ||
                                     tri2[0] == b || tri2[1] == b || tri2[2] == b;
                if (!touches &&
                    segment_crosses(load(st.q0, a), load(st.q0, b), load(st.q0, tri2[0]),
                                    load(st.q0, tri2[1]), load(st.q0, tri2[2]))) {
                    w.crossing[0] = a;
                    w.crossing[1] = t2;
                    crossed = true;
                    return false;
                }
                for (int k2 = 0; k2 < 3; ++k2) {
                    if (m.triangles.edge_owner[3 * t2 + k2] == 0) continue;
                    if (t2 < t || (t2 == t && k2 <= k)) continue;  // the pair once
                    const index c = tri2[k2], d = tri2[(k2 + 1) % 3];
                    if (c == a || c == b || d == a || d == b) continue;  // adjacent
                    double clo[3], chi[3], dlo[3], dhi[3];
                    particle_box(st, c, clo, chi);
                    particle_box(st, d, dlo, dhi);
                    for (int e = 0; e < 3; ++e) {
                        clo[e] = std::min(clo[e], dlo[e]);
                        chi[e] = std::max(chi[e], dhi[e]);
                    }
                    if (!boxes_meet(lo, hi, clo, chi, st.g)) continue;
                    const index v[4] = {a, b, c, d};
                    double cc[4];
                    const V3 g = gap(st.q0, kEdgeEdge, v, cc);
                    const double dist = std::sqrt(dot(g, g));
                    if (dist < st.keep) add_pair(w, count, kEdgeEdge, v, dist);
                }
                return true;
            });
        }
    return crossed ? -1 : count;
}

/// Step 4: the scales s (w.scale) of u = q - q0 - T that keep every candidate pair's
/// relative displacement within kGamma of its start distance; returns the passes made.
inline void bound(const Stage& st, index pairs) {
    const Model& m = st.m;
    const ContactBuffers& w = st.w;
    const index n = m.particles.count;
    double* s = w.scale;
    for (index i = 0; i < n; ++i) s[i] = 1.0;
    auto u = [&](index i) { return load(st.q, i) - load(st.q0, i) - st.T; };
    for (index pass = 0; pass <= pairs; ++pass) {
        bool changed = false;
        for (index p = 0; p < pairs; ++p) {
            const index* row = w.pairs->data + kSlots * p;
            const index* v = row + 1;
            const double limit = kGamma * pair_distance(row);
            double free_most = 0.0, pinned_most = 0.0;
            V3 du[4];
            double len[4];
            for (int k = 0; k < 4; ++k) {
                du[k] = u(v[k]);
                len[k] = std::sqrt(dot(du[k], du[k]));
                if (m.particles.inv_mass[v[k]] == 0.0)
                    pinned_most = std::max(pinned_most, len[k]);
                else
                    free_most = std::max(free_most, s[v[k]] * len[k]);
            }
            if (free_most + pinned_most <= 0.5 * limit) continue;  // cannot violate
            // the relative displacement between the two sides' particles
            const int side_a = row[0] == kVertexTriangle ? 1 : 2;
            double most = 0.0;
            for (int k = 0; k < side_a; ++k)
                for (int l = side_a; l < 4; ++l) {
                    const double sk = m.particles.inv_mass[v[k]] == 0.0 ? 1.0 : s[v[k]];
                    const double sl = m.particles.inv_mass[v[l]] == 0.0 ? 1.0 : s[v[l]];
                    const V3 r = sk * du[k] - sl * du[l];
                    most = std::max(most, dot(r, r));
                }
            if (most <= limit * limit) continue;
            // cap every free particle of the pair at (limit - pinned) / 2
            const double cap = std::max(0.0, 0.5 * (limit - pinned_most));
            for (int k = 0; k < 4; ++k) {
                if (m.particles.inv_mass[v[k]] == 0.0 || len[k] == 0.0) continue;
                const double sk = std::min(s[v[k]], cap / len[k]);
                if (sk < s[v[k]]) {
                    s[v[k]] = sk;
                    changed = true;
                }
            }
        }
        if (!changed) break;
    }
    for (index b = 0; b < m.bodies.count; ++b)
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1];
             ++i) {
            if (s[i] >= 1.0) continue;
            store(st.q, i, load(st.q0, i) + st.T + s[i] * u(i));
        }
}

/// Step 5: pairs closer than h pushed apart to h, approaching ones' velocities turned.
inline void respond(const Stage& st, index pairs, double* qd) {
    const Model& m = st.m;
    const ContactBuffers& w = st.w;
    const double h = m.soft_contacts.thickness;
    const double e = m.soft_contacts.restitution, mu = m.soft_contacts.friction;
    for (index p = 0; p < pairs; ++p) {
        const index* row = w.pairs->data + kSlots * p;
        const index* v = row + 1;
        double c[4];
        V3 g = gap(st.q, row[0], v, c);
        double d = std::sqrt(dot(g, g));
        if (d >= h) continue;
        double weight = 0.0;
        for (int k = 0; k < 4; ++k) weight += c[k] * c[k] * m.particles.inv_mass[v[k]];
        if (weight == 0.0) continue;  // all pinned
        if (!(d > 1e-9 * h)) {        // touching: the side they started on
            double c0[4];
            g = gap(st.q0, row[0], v, c0);
            d = std::sqrt(dot(g, g));
            if (!(d > 0.0)) continue;
            d = 0.0;
        }
        const double gl = std::sqrt(dot(g, g));
        const V3 n{g.x / gl, g.y / gl, g.z / gl};
        const double lam = (h - d) / weight;
        for (int k = 0; k < 4; ++k)
            add_to(st.q, v[k], (c[k] * m.particles.inv_mass[v[k]] * lam) * n);
        V3 rv{0.0, 0.0, 0.0};
        for (int k = 0; k < 4; ++k) rv = rv + c[k] * load(qd, v[k]);
        const double vn = dot(rv, n);
        if (vn >= 0.0) continue;  // separating already
        const V3 tangent = rv - vn * n;
        const V3 j = (-(1.0 + e) * vn / weight) * n + (-mu / weight) * tangent;
        for (int k = 0; k < 4; ++k) add_to(qd, v[k], (c[k] * m.particles.inv_mass[v[k]]) * j);
    }
}

/// Whether any two bodies' boxes over q0 and q - T, grown by the margin, meet.
inline bool any_bodies_near(const Stage& st) {
    const Model& m = st.m;
    const ContactBuffers& w = st.w;
    for (index b = 0; b < m.bodies.count; ++b) {
        double* lo = w.body_lo + 3 * b;
        double* hi = w.body_hi + 3 * b;
        for (int k = 0; k < 3; ++k) {
            lo[k] = std::numeric_limits<double>::infinity();
            hi[k] = -std::numeric_limits<double>::infinity();
        }
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1];
             ++i) {
            double a[3], z[3];
            particle_box(st, i, a, z);
            for (int k = 0; k < 3; ++k) {
                lo[k] = std::min(lo[k], a[k]);
                hi[k] = std::max(hi[k], z[k]);
            }
        }
    }
    for (index a = 0; a < m.bodies.count; ++a)
        for (index b = a + 1; b < m.bodies.count; ++b)
            if (boxes_meet(w.body_lo + 3 * a, w.body_hi + 3 * a, w.body_lo + 3 * b,
                           w.body_hi + 3 * b, 2.0 * st.g))
                return true;
    return false;
}

/// The candidate pairs of a step into w.pairs, collected (broad phase, narrow phase, the
/// crossing check) with the stage's settings; grows the list when it must. Returns their
/// count; -1 for a crossing; or, below -1, minus the entries the hash or the list needed
/// (less 1) when its buffer could not grow to them.
inline index gather(const Stage& st) {
    const ContactBuffers& w = st.w;
    const index needed = build_hash(st);
    if (needed > w.hash_entries->capacity) {
        HashEntries& entries = *w.hash_entries;
        if (entries.grow == nullptr || !entries.grow(entries, needed)) return -1 - needed;
        build_hash(st);
    }
    index pairs = collect(st);
    if (pairs >= 0 && pairs * kSlots > w.pairs->capacity) {
        HashEntries& list = *w.pairs;
        if (list.grow == nullptr || !list.grow(list, pairs * kSlots)) return -1 - pairs * kSlots;
        pairs = collect(st);
    }
    return pairs;
}

/// The list's particles' largest offset from where it was built, after the common
/// translation C of the bodies' free particles between the two: max_i |q0_i - q_b,i - C|.
inline double drift(const Model& m, const double* q0, const double* qb) {
    double mass = 0.0;
    V3 sum{0.0, 0.0, 0.0};
    for (index b = 0; b < m.bodies.count; ++b)
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1];
             ++i) {
            if (m.particles.inv_mass[i] == 0.0) continue;
            mass += m.particles.mass[i];
            sum = sum + m.particles.mass[i] * (load(q0, i) - load(qb, i));
        }
    const V3 c = mass > 0.0 ? (1.0 / mass) * sum : V3{0.0, 0.0, 0.0};
    double most = 0.0;
    for (index b = 0; b < m.bodies.count; ++b)
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1];
             ++i) {
            const V3 d = load(q0, i) - load(qb, i) - c;
            most = std::max(most, dot(d, d));
        }
    return std::sqrt(most);
}

/// The stage (steps 1-5) on q, qd (N, 3) in place, from the step's start q0 (N, 3). Returns
/// 0; the entries the hash or the pair list needed when its buffer could not grow to them
/// (nothing resolved); or -1 for a crossing at q0 (w.crossing: particle, triangle; nothing
/// changed).
///
/// The pairs come from a list kept between steps (a Verlet list): the pairs nearer than
/// R = 2 h + g at the positions q_b where it was built. While the bodies' particles have
/// drifted by sigma (after a common translation) from q_b and move by mu in the step (after
/// T), with sigma + mu <= g / 2, a pair off the list starts the step at least R - 2 sigma
/// apart and ends it (bound, and response moves of h / 2 a side) at least
/// R - 2 (sigma + mu) - h >= h apart: neither the bound nor the response needs it. The list
/// is built again (at q0, with the crossing check) when that fails; a step whose own motion
/// is over g / 2 takes its pairs from the swept boxes instead (and the list is dropped).
inline index contacts(const Model& m, const double* q0, double* q, double* qd,
                      const ContactBuffers& w) {
    Stage st{m, q0, q, w, {0.0, 0.0, 0.0}, 1.0 / m.soft_contacts.cell_size,
             m.soft_contacts.margin, m.soft_contacts.self_contact != 0};
    // 1. the common translation, and the step's largest motion after it
    double mass = 0.0;
    V3 sum{0.0, 0.0, 0.0};
    for (index b = 0; b < m.bodies.count; ++b)
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1];
             ++i) {
            if (m.particles.inv_mass[i] == 0.0) continue;
            const double mi = m.particles.mass[i];
            mass += mi;
            sum = sum + mi * (load(q, i) - load(q0, i));
        }
    if (mass > 0.0) st.T = (1.0 / mass) * sum;
    if (!st.self && !any_bodies_near(st)) return 0;
    double mu = 0.0;
    for (index b = 0; b < m.bodies.count; ++b)
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1];
             ++i) {
            const V3 u = load(q, i) - load(q0, i) - st.T;
            mu = std::max(mu, dot(u, u));
        }
    mu = std::sqrt(mu);
    // 2-3. the pairs: the list (built again when it no longer covers the step), or the
    // step's swept boxes
    const double h = m.soft_contacts.thickness, slack = 0.5 * st.g;
    index pairs = 0;
    const index n3 = 3 * m.particles.count;
    if (mu <= slack) {
        if (*w.list < 0 || drift(m, q0, w.q_build) + mu > slack) {
            Stage list = st;
            list.swept = false;
            list.g = 2.0 * h + st.g;
            list.keep = list.g;
            *w.list = -1;
            pairs = gather(list);
            if (pairs == -1) return -1;  // crossed at the start
            if (pairs < -1) return -1 - pairs;
            for (index k = 0; k < n3; ++k) w.q_build[k] = q0[k];
            *w.list = pairs;
        }
        pairs = *w.list;
        for (index p = 0; p < pairs; ++p) {  // each pair's distance at this step's start
            index* row = w.pairs->data + kSlots * p;
            double c[4];
            const V3 g = gap(q0, row[0], row + 1, c);
            const double d = std::sqrt(dot(g, g));
            std::memcpy(row + 5, &d, sizeof(double));
        }
    } else {
        *w.list = -1;
        pairs = gather(st);
        if (pairs == -1) return -1;
        if (pairs < -1) return -1 - pairs;
    }
    // 4. the bound, 5. the response, its moves clipped to h / 2, and the bound again
    bound(st, pairs);
    for (index k = 0; k < n3; ++k) w.q_pre[k] = q[k];
    respond(st, pairs, qd);
    const double clip = 0.5 * h;
    for (index i = 0; i < m.particles.count; ++i) {
        const V3 d = load(q, i) - load(w.q_pre, i);
        const double len = std::sqrt(dot(d, d));
        if (len > clip) store(q, i, load(w.q_pre, i) + (clip / len) * d);
    }
    bound(st, pairs);
    return 0;
}

}  // namespace softbody::SOFTBODY_KERNELS::thick
