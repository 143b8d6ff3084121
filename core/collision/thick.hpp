// Surface contacts with a thickness h (soft_contacts.thickness > 0): vertex-triangle and
// edge-edge pairs between bodies, and within a body when soft_contacts.self_contact, pairs
// of adjacent elements (a vertex of the triangle, edges sharing a vertex) left out. The
// contact stage of a step, from the step's start positions q0 to the positions q the
// solver reached:
//   1. T, the mass-weighted mean displacement of the bodies' free particles: a translation
//      common to all changes no distance, so the broad phase and the bound below look at
//      u_i = q_i - q0_i - T only (a body in free fall finds no pair from its fall). One pass
//      finds T and bounds mu >= max |u_i| (and the list's drift) by the displacements' box;
//      a second pass, only where the boxes say the list may no longer hold, measures the
//      largest offsets and sums the drift's affine fit, and a third, only where the
//      translation's bound would build the list again, the fit's residual (see contacts():
//      a body that spins, breathes or shears keeps its list).
//   2. Broad phase: a spatial hash of the triangles' boxes over their corners' q0 and
//      q0 + u (each particle's box computed once a gather), grown by the margin g >= h
//      (soft_contacts.margin); each triangle's box over the same points is looked up in it
//      for the triangles after it (a list's gather, its boxes over q0 alone, grows the
//      hashed boxes by the largest half extent of a triangle's box too and reads only the
//      cell of each triangle's box centre: each_triangle), and each vertex-triangle and
//      edge-edge pair is found
//      through the pair of triangles that own its primitives (collect()). Every pair whose
//      boxes meet is a candidate, with its distance D at the step's start; in a step's swept
//      boxes only where D is at most its reach, h plus the most its particles' moves, at
//      any scales the bound may give them, can close it (swept_reach): a pair beyond that
//      stays more than h apart up to the response, and apart after it.
//      Any pair of primitives that could meet below (every path stays in its box grown by
//      h / 2) is a candidate. Most steps take their candidates from a list kept between
//      steps instead, and read only its rows that could matter (see contacts()).
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
//      Steps 4 and 5 read and write only the particles of the pairs they are given (w.scale
//      is 1 between calls), so a step with no near pair costs one pass over the particles.
//   6. Where the bound held particles back, their velocities follow (hold()): each held
//      particle's velocity changes by its bound's move over dt (the velocity of its bounded
//      step), less the mass-weighted mean change of its group of held pairs (momentum is
//      conserved: the limit of equal and opposite impulses on the pairs). Left as they
//      were, they would propose the same long step again, every step (the vacuum-packed
//      ball: moves of centimetres proposed, held back to millimetres, step after step).
//      The bound limits a pair's whole relative motion, sliding included, so a held pair
//      loses its relative velocity beyond kGamma D a step along the surface as well as
//      toward it: sheets within the list that slide over each other faster than
//      kGamma D / dt lose the excess, as a friction would, whatever the friction set (a
//      bound on the approach alone would keep it; not built).
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
    // both ends strictly on one side of the triangle's plane: no crossing (the test below
    // would find its parameter s outside (0, 1))
    const V3 n = cross(e1, e2);
    const double da = dot(a - p0, n), db = dot(b - p0, n);
    if ((da > 0.0 && db > 0.0) || (da < 0.0 && db < 0.0)) return false;
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
    bool check = true;  // the crossing check at q0 (off: a gather whose step's stage checks)
    // a list's patch (patch_list): the particles gathered again (moved[8 i] != 0; null: a
    // whole gather), and the rows kept before the new ones
    const double* moved = nullptr;
    index first = 0;
    // a swept gather's slack [m]: each particle's box grown by it and each pair's reach by
    // twice it, so that its rows serve a later pass from the same q0 whose particles each
    // stay within it of their swept paths (reuse_swept)
    double slack = 0.0;
    // a patch's crossing check (st.check too): the pairs of triangles it meets, each with a
    // moved corner (collider_crossing); off, a patch makes none
    bool check_patch = false;
    // a gather over q0 alone (a list's): the largest half extent of a triangle's box along an
    // axis (tri_boxes()); the hash's boxes grow by it too, so that each triangle looks up the
    // one cell of its box's centre (each_triangle). Negative: box look-ups (a swept gather).
    double half = -1.0;
};

/// Box of particle i over q0 and q0 + u (u = q - q0 - T), grown by st.slack, or q0 alone,
/// into lo, hi.
inline void swept_box(const Stage& st, index i, double* lo, double* hi) {
    const double grow = st.swept ? st.slack : 0.0;
    for (int k = 0; k < 3; ++k) {
        const double a = st.q0[3 * i + k];
        const double b = st.swept ? st.q[3 * i + k] - (&st.T.x)[k] : a;
        lo[k] = std::min(a, b) - grow;
        hi[k] = std::max(a, b) + grow;
    }
}

/// Every particle's box (swept_box) into w.particle_box (N, 6: lo, hi), once per gather.
inline void fill_boxes(const Stage& st) {
    for (index i = 0; i < st.m.particles.count; ++i)
        swept_box(st, i, st.w.particle_box + 6 * i, st.w.particle_box + 6 * i + 3);
}

/// Particle i's box from w.particle_box: lo, then hi at +3.
inline const double* particle_box(const Stage& st, index i) {
    return st.w.particle_box + 6 * i;
}

/// The box of edge a-b (its particles' boxes joined) into lo, hi.
inline void edge_box(const Stage& st, index a, index b, double* lo, double* hi) {
    const double* pa = particle_box(st, a);
    const double* pb = particle_box(st, b);
    for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(pa[k], pb[k]);
        hi[k] = std::max(pa[3 + k], pb[3 + k]);
    }
}

/// Whether boxes [lo, hi] and [lo2, hi2] meet when grown by `grow` (without branches: the
/// look-ups below test many boxes whose outcome no predictor guesses).
inline bool boxes_meet(const double* lo, const double* hi, const double* lo2, const double* hi2,
                       double grow) {
    bool apart = false;
    for (int k = 0; k < 3; ++k) apart |= (hi[k] + grow < lo2[k]) | (hi2[k] + grow < lo[k]);
    return !apart;
}

/// The triangles' boxes (over their corners' boxes) into w.tri_box (T, 6); returns the
/// largest half extent of one along an axis [m], and the largest magnitude of a box's
/// coordinate into `scale` [m]. Reads w.particle_box (fill_boxes).
inline double tri_boxes(const Stage& st, double& scale) {
    const Model& m = st.m;
    const ContactBuffers& w = st.w;
    double half = 0.0;
    scale = 0.0;
    for (index t = 0; t < m.triangles.count; ++t) {
        double* box = w.tri_box + 6 * t;
        const index* tri = m.triangles.indices + 3 * t;
        const double *a = particle_box(st, tri[0]), *b = particle_box(st, tri[1]),
                     *c = particle_box(st, tri[2]);
        for (int k = 0; k < 3; ++k) {
            box[k] = std::min(std::min(a[k], b[k]), c[k]);
            box[3 + k] = std::max(std::max(a[3 + k], b[3 + k]), c[3 + k]);
            half = std::max(half, 0.5 * (box[3 + k] - box[k]));
            scale = std::max(scale, std::max(std::fabs(box[k]), std::fabs(box[3 + k])));
        }
    }
    return half;
}

/// Hash of the triangles' boxes (w.tri_box, tri_boxes()) grown by g, and by st.half too
/// where it is not negative, into w.hash_*. Counts first; returns the entries needed, and
/// stores no entry when they exceed the capacity (soft::hash_triangles' contract).
inline index build_hash(const Stage& st) {
    const Model& m = st.m;
    const ContactBuffers& w = st.w;
    const double grow = st.g + std::max(st.half, 0.0);
    return soft::hash_triangles(m, w, [&](index t, index* r) {
        const double* box = w.tri_box + 6 * t;
        const index* tri = m.triangles.indices + 3 * t;
        if (st.moved != nullptr && st.moved[8 * tri[0]] == 0.0 && st.moved[8 * tri[1]] == 0.0 &&
            st.moved[8 * tri[2]] == 0.0) {  // a patch hashes the triangles that moved alone
            r[0] = r[1] = r[2] = 0;
            r[3] = r[4] = r[5] = -1;
            return;
        }
        for (int k = 0; k < 3; ++k) {
            r[k] = soft::cell_of((box[k] - grow) * st.inv);
            r[3 + k] = soft::cell_of((box[3 + k] + grow) * st.inv);
        }
    });
}

/// Each triangle t2 > `after` whose grown box meets the box [lo, hi], once: calls visit(t2).
/// The buckets' entries are in triangle order (hash_triangles adds them so), so each bucket
/// is read from its end down to the first entry at or below `after`; w.tri_mark[t2] holds
/// the last query (`query`, unique to the caller's lookup) that saw t2, so a triangle met
/// again in another cell of the range (or in a bucket two cells share) is skipped.
/// In a gather whose hash grew its boxes by st.half >= 0 beyond g (a list's), only the cell
/// of [lo, hi]'s centre is read: a box grown by g that meets [lo, hi] reaches, along each
/// axis, within half the extent of [lo, hi] (at most st.half) of its centre, so t2's hashed
/// box, grown by g + st.half, holds the centre and has an entry in the centre's cell (a box
/// look-up reads every cell the box meets, and meets each triangle in most of them again).
template <class Visit>
inline void each_triangle(const Stage& st, const double* lo, const double* hi, index after,
                          index query, Visit visit) {
    const ContactBuffers& w = st.w;
    const index* entries = w.hash_entries->data;
    index* mark = w.tri_mark;
    index r[6];
    for (int k = 0; k < 3; ++k) {
        if (st.half >= 0.0) {
            r[k] = r[3 + k] = soft::cell_of(0.5 * (lo[k] + hi[k]) * st.inv);
        } else {
            r[k] = soft::cell_of(lo[k] * st.inv);
            r[3 + k] = soft::cell_of(hi[k] * st.inv);
        }
    }
    constexpr int kFound = 128;
    index found[kFound];  // the triangles met, gathered without a branch on each
    int n = 0;
    for (index ix = r[0]; ix <= r[3]; ++ix)
        for (index iy = r[1]; iy <= r[4]; ++iy)
            for (index iz = r[2]; iz <= r[5]; ++iz) {
                const index h = soft::cell_hash(ix, iy, iz, w.hash_table);
                for (index e = w.hash_start[h + 1]; e-- > w.hash_start[h];) {
                    const index t = entries[e];
                    if (t <= after) break;  // the rest of the bucket is below too
                    const double* box = w.tri_box + 6 * t;
                    const bool fresh = mark[t] != query;
                    mark[t] = query;
                    found[n] = t;
                    n += fresh & boxes_meet(lo, hi, box, box + 3, st.g);
                    if (n == kFound) {
                        for (int k = 0; k < n; ++k) visit(found[k]);
                        n = 0;
                    }
                }
            }
    for (int k = 0; k < n; ++k) visit(found[k]);
}

/// Whether particles of bodies a and b may touch (other bodies always, the same body with
/// self-contact).
inline bool bodies_pair(const Stage& st, index a, index b) { return a != b || st.self; }

/// Appends a candidate pair (kind, v, start distance D, twice: the step's and the gather's);
/// writes nothing when the buffer is full (the count still grows: the caller grows the
/// buffer to it and starts again).
inline void add_pair(const ContactBuffers& w, index& count, index kind, const index* v,
                     double distance) {
    if ((count + 1) * kSlots <= w.pairs->capacity) {
        index* row = w.pairs->data + kSlots * count;
        row[0] = kind;
        for (int k = 0; k < 4; ++k) row[1 + k] = v[k];
        std::memcpy(row + 5, &distance, sizeof(double));
        std::memcpy(row + 6, &distance, sizeof(double));
    }
    ++count;
}

/// A row's distance at the step's start (slot 5).
inline double pair_distance(const index* row) {
    double d = 0.0;
    std::memcpy(&d, row + 5, sizeof(double));
    return d;
}

/// A row's distance where its gather was made (slot 6: the list's build positions).
inline double build_distance(const index* row) {
    double d = 0.0;
    std::memcpy(&d, row + 6, sizeof(double));
    return d;
}

/// Candidate pairs of one kind waiting for their distances: their particles, and (load())
/// their four points at q0 as a structure of arrays (x[3 k + d][p]: point k's coordinate
/// d), so that the lower bounds below run in vector lanes.
struct Batch {
    static constexpr int kSize = 64;
    int n = 0;
    index v[kSize][4];
    double x[12][kSize];
    double bound[kSize];  // a lower bound on each pair's squared distance
    double reach[kSize];  // a swept gather's: the distance below which each pair is kept
    /// Writes pair u in the next row, and counts it when `keep` (room: n < kSize).
    void push(const index* u, bool keep) {
        for (int k = 0; k < 4; ++k) v[n][k] = u[k];
        n += keep;
    }
    /// The counted pairs' points at q0 into x.
    void load(const double* q0) {
        for (int p = 0; p < n; ++p)
            for (int k = 0; k < 4; ++k)
                for (int d = 0; d < 3; ++d) x[3 * k + d][p] = q0[3 * v[p][k] + d];
    }
};

/// Each edge-edge pair's squared distance into b.bound: closest_segments' arithmetic
/// without its branches (selects in their place, the same operations in the same order, so
/// the same value as gap()'s), 0 for a pair with a degenerate segment (left to gap()).
inline void edge_bounds(Batch& b) {
    auto clamp01 = [](double x) { return std::min(1.0, std::max(0.0, x)); };
    const double tiny = 1e-300;
    for (int p = 0; p < b.n; ++p) {
        const double d1x = b.x[3][p] - b.x[0][p], d1y = b.x[4][p] - b.x[1][p],
                     d1z = b.x[5][p] - b.x[2][p];
        const double d2x = b.x[9][p] - b.x[6][p], d2y = b.x[10][p] - b.x[7][p],
                     d2z = b.x[11][p] - b.x[8][p];
        const double rx = b.x[0][p] - b.x[6][p], ry = b.x[1][p] - b.x[7][p],
                     rz = b.x[2][p] - b.x[8][p];
        const double a = d1x * d1x + d1y * d1y + d1z * d1z;
        const double e = d2x * d2x + d2y * d2y + d2z * d2z;
        const double f = d2x * rx + d2y * ry + d2z * rz;
        const double c = d1x * rx + d1y * ry + d1z * rz;
        const double bb = d1x * d2x + d1y * d2y + d1z * d2z;
        const bool degenerate = !(a > tiny) || !(e > tiny);
        const double as = degenerate ? 1.0 : a, es = degenerate ? 1.0 : e;
        const double denom = a * e - bb * bb;
        const double ds = denom > 0.0 ? denom : 1.0;
        double s = denom > 0.0 ? clamp01((bb * f - c * e) / ds) : 0.0;
        double t = (bb * s + f) / es;
        const bool low = t < 0.0, high = t > 1.0;
        s = low ? clamp01(-c / as) : (high ? clamp01((bb - c) / as) : s);
        t = low ? 0.0 : (high ? 1.0 : t);
        const double gx = (b.x[0][p] + s * d1x) - (b.x[6][p] + t * d2x);
        const double gy = (b.x[1][p] + s * d1y) - (b.x[7][p] + t * d2y);
        const double gz = (b.x[2][p] + s * d1z) - (b.x[8][p] + t * d2z);
        b.bound[p] = degenerate ? 0.0 : gx * gx + gy * gy + gz * gz;
    }
}

/// A lower bound on each vertex-triangle pair's squared distance into b.bound, without
/// branches: the squared distance to the triangle's plane where the vertex projects inside
/// the triangle or within 1e-6 of its size outside (never more than the distance), else the
/// least squared distance to its three edges (the distance then: the closest point is on
/// the boundary).
inline void vertex_bounds(Batch& b) {
    auto clamp01 = [](double x) { return std::min(1.0, std::max(0.0, x)); };
    for (int p = 0; p < b.n; ++p) {
        const double px = b.x[0][p], py = b.x[1][p], pz = b.x[2][p];
        const double ax = b.x[3][p], ay = b.x[4][p], az = b.x[5][p];
        const double bx = b.x[6][p], by = b.x[7][p], bz = b.x[8][p];
        const double cx = b.x[9][p], cy = b.x[10][p], cz = b.x[11][p];
        const double abx = bx - ax, aby = by - ay, abz = bz - az;
        const double bcx = cx - bx, bcy = cy - by, bcz = cz - bz;
        const double cax = ax - cx, cay = ay - cy, caz = az - cz;
        const double apx = px - ax, apy = py - ay, apz = pz - az;
        const double bpx = px - bx, bpy = py - by, bpz = pz - bz;
        const double cpx = px - cx, cpy = py - cy, cpz = pz - cz;
        // the normal (ab x -ca) and the signed sub-areas of the projection
        const double nx = aby * (-caz) - abz * (-cay), ny = abz * (-cax) - abx * (-caz),
                     nz = abx * (-cay) - aby * (-cax);
        const double nn = nx * nx + ny * ny + nz * nz;
        auto area = [=](double ux, double uy, double uz, double wx, double wy, double wz) {
            return (uy * wz - uz * wy) * nx + (uz * wx - ux * wz) * ny + (ux * wy - uy * wx) * nz;
        };
        const double slack = -1e-6 * nn;
        const bool inside = (nn > 0.0) & (area(abx, aby, abz, apx, apy, apz) >= slack) &
                            (area(bcx, bcy, bcz, bpx, bpy, bpz) >= slack) &
                            (area(cax, cay, caz, cpx, cpy, cpz) >= slack);
        const double h = apx * nx + apy * ny + apz * nz;
        const double plane = h * h / (nn > 0.0 ? nn : 1.0);
        auto edge = [=](double ex, double ey, double ez, double ux, double uy, double uz) {
            const double ee = ex * ex + ey * ey + ez * ez;
            const double t = clamp01((ux * ex + uy * ey + uz * ez) / (ee > 0.0 ? ee : 1.0));
            const double dx = ux - t * ex, dy = uy - t * ey, dz = uz - t * ez;
            return dx * dx + dy * dy + dz * dz;
        };
        const double rim = std::min(std::min(edge(abx, aby, abz, apx, apy, apz),
                                             edge(bcx, bcy, bcz, bpx, bpy, bpz)),
                                    edge(cax, cay, caz, cpx, cpy, cpz));
        b.bound[p] = inside ? plane : rim;
    }
}

/// Each pair's reach in a swept gather into b.reach: h plus the most its particles' paths
/// can close its distance, max(max_k |u_k|, max |u_a - u_b|) over its particles k and the
/// pairs a, b of particles on its two sides (u = q - q0 - T; the first `side` particles
/// are the first side). The stage moves particle k to q0 + T + a_k u_k + e_k, a_k in [0, 1]
/// (the bound's scale, of the whole move after the response too) and |e_k| <= h / 2 (the
/// response's clipped move): the relative move of a and b is at most
/// |a_a u_a - a_b u_b| + h, and |a_a u_a - a_b u_b| (convex in a_a, a_b) is largest at a
/// corner of [0, 1]^2: 0, |u_a|, |u_b| or |u_a - u_b|. A pair's gap with the coefficients
/// of its closest points at q0 (each side's weights sum to 1) then stays at least D minus
/// that much along the straight path, so a pair whose distance D at q0 is over its reach
/// stays more than h apart up to the response (which then has nothing to do for it), and
/// more than 0 after its moves (a crossing needs 0): neither the bound nor the response
/// needs it (as a pair whose boxes stay farther apart than the margin g >= h). With a
/// slack (Stage::slack), twice the slack more (reuse_swept).
inline void swept_reach(const Stage& st, Batch& b, int side) {
    const double h = st.m.soft_contacts.thickness;
    for (int p = 0; p < b.n; ++p) {
        V3 u[4];
        double most = 0.0;
        for (int k = 0; k < 4; ++k) {
            const index i = b.v[p][k];
            u[k] = load(st.q, i) - load(st.q0, i) - st.T;
            most = std::max(most, dot(u[k], u[k]));
        }
        for (int k = 0; k < side; ++k)
            for (int l = side; l < 4; ++l) {
                const V3 r = u[k] - u[l];
                most = std::max(most, dot(r, r));
            }
        b.reach[p] = std::sqrt(most) + h + 2.0 * st.slack;
    }
}

/// A swept gather's batches (collect(), st.swept with no distance to keep below): each
/// pair whose distance at q0 is at most its reach (swept_reach) into w.pairs, with that
/// distance. The lower bounds (vertex_bounds, edge_bounds: an edge-edge pair's is its
/// squared distance where neither segment is degenerate) drop the others before gap()
/// measures them. Empties the batches.
inline void flush_swept(const Stage& st, Batch& vt, Batch& ee, index& count) {
    vt.load(st.q0);
    ee.load(st.q0);
    vertex_bounds(vt);
    edge_bounds(ee);
    swept_reach(st, vt, 1);
    swept_reach(st, ee, 2);
    auto measure = [&](index kind, const index* v, double reach) {
        double c[4];
        const V3 d = gap(st.q0, kind, v, c);
        const double dist = std::sqrt(dot(d, d));
        if (dist <= reach) add_pair(st.w, count, kind, v, dist);
    };
    for (int p = 0; p < vt.n; ++p)  // the bound within its 1e-6 slack of the distance
        if (vt.bound[p] <= vt.reach[p] * vt.reach[p] * (1.0 + 1e-6))
            measure(kVertexTriangle, vt.v[p], vt.reach[p]);
    for (int p = 0; p < ee.n; ++p) {
        if (ee.bound[p] > 0.0) {  // the distance itself
            const double dist = std::sqrt(ee.bound[p]);
            if (dist <= ee.reach[p]) add_pair(st.w, count, kEdgeEdge, ee.v[p], dist);
        } else {  // a degenerate segment, or touching: gap() says
            measure(kEdgeEdge, ee.v[p], ee.reach[p]);
        }
    }
    vt.n = ee.n = 0;
}

/// Whether an owned edge of triangle e (its corners' indices ei) passes through triangle f
/// (corners fi) at q0, an edge sharing a corner with f left out; writes the first such edge's
/// first particle and f into w.crossing. When all three corners of e lie strictly on one
/// side of f's plane no edge of e can cross it (segment_crosses' own first test, with the
/// same arithmetic), so the edges are not tested one by one; the same for the corners of e
/// that are not f's, when only they make edges that are not left out.
inline bool edge_through(const Stage& st, index e, const index* ei, index f, const index* fi) {
    const Model& m = st.m;
    // the corners of e that are no corner of f: an edge with a shared corner is left out
    int apart[3], n_apart = 0;
    for (int k = 0; k < 3; ++k)
        if (ei[k] != fi[0] && ei[k] != fi[1] && ei[k] != fi[2]) apart[n_apart++] = k;
    if (n_apart < 2) return false;  // no edge of e without a corner of f
    const V3 p0 = load(st.q0, fi[0]), p1 = load(st.q0, fi[1]), p2 = load(st.q0, fi[2]);
    const V3 n = cross(p1 - p0, p2 - p0);
    int above = 0, below = 0;
    for (int j = 0; j < n_apart; ++j) {
        const double side = dot(load(st.q0, ei[apart[j]]) - p0, n);
        above += side > 0.0;
        below += side < 0.0;
    }
    if (above == n_apart || below == n_apart) return false;
    for (int k = 0; k < 3; ++k) {
        if (m.triangles.edge_owner[3 * e + k] == 0) continue;
        const index a = ei[k], b = ei[(k + 1) % 3];
        const bool touches =
            fi[0] == a || fi[1] == a || fi[2] == a || fi[0] == b || fi[1] == b || fi[2] == b;
        if (touches || !segment_crosses(load(st.q0, a), load(st.q0, b), p0, p1, p2)) continue;
        st.w.crossing[0] = a;
        st.w.crossing[1] = f;
        return true;
    }
    return false;
}

/// The box of triangle tri (its three corners) at q0 into lo, hi.
inline void start_box(const Stage& st, const index* tri, double* lo, double* hi) {
    for (int k = 0; k < 3; ++k) {
        const double a = st.q0[3 * tri[0] + k], b = st.q0[3 * tri[1] + k],
                     c = st.q0[3 * tri[2] + k];
        lo[k] = std::min(std::min(a, b), c);
        hi[k] = std::max(std::max(a, b), c);
    }
}

/// Whether two triangles' boxes at q0 meet (without growth): an edge of one crossing the
/// other at q0 lies in both. box (6: lo, hi) is the first's at q0; the second's is its
/// gathered box box2 (6) when the gather's boxes are over q0 alone, else its corners' (tri2)
/// box at q0 (a swept gather's boxes also hold the step's paths: many more of them meet).
inline bool starts_meet(const Stage& st, const double* box, const index* tri2,
                        const double* box2) {
    if (!st.swept) return boxes_meet(box, box + 3, box2, box2 + 3, 0.0);
    double at0[6];
    start_box(st, tri2, at0, at0 + 3);
    return boxes_meet(box, box + 3, at0, at0 + 3, 0.0);
}

/// Whether no pair of primitives of triangles t (corners tri) and t2 (corners tri2) that
/// share no particle can be nearer than `limit` [m] at q0: a lower bound on every such pair's
/// distance along one axis a, the gap between the two sides' projections on it (for points
/// x, y, |y - x| >= a.(y - x) / |a|), over `limit`. A primitive is its particles' hull, so
/// its projection lies within its particles'. Triangles with no common corner: the whole
/// triangles' projections, a from t's centroid to t2's. One common corner s: a pair holds s
/// on one side at most, so the bound is the lesser of t2 without s against t and t2
/// against t without s, a between the midpoints of the edges opposite s. Two common corners
/// (neighbours across an edge): not tried (the other common corner lies on both sides, so
/// no such bound exceeds 0). A bound within 1e-6 of the limit does not count (the distances
/// are measured otherwise). A static gather's pairs are kept below st.keep: one of two
/// triangles over it has none (collect()).
inline bool apart_beyond(const double* q0, const index* tri, const index* tri2, double limit) {
    int shared = 0, s = -1, s2 = -1;
    for (int k = 0; k < 3; ++k)
        for (int l = 0; l < 3; ++l)
            if (tri[k] == tri2[l]) {
                ++shared;
                s = k;
                s2 = l;
            }
    if (shared > 1 || !(limit < std::numeric_limits<double>::infinity())) return false;
    V3 p[3], r[3];
    for (int k = 0; k < 3; ++k) {
        p[k] = load(q0, tri[k]);
        r[k] = load(q0, tri2[k]);
    }
    V3 a = (r[0] + r[1] + r[2]) - (p[0] + p[1] + p[2]);  // 3 x the centroids' difference
    if (shared == 1) a = (r[0] + r[1] + r[2] - r[s2]) - (p[0] + p[1] + p[2] - p[s]);
    double hi = -std::numeric_limits<double>::infinity(), hi_apart = hi;  // t: all, without s
    double lo = std::numeric_limits<double>::infinity(), lo_apart = lo;   // t2: all, without s
    for (int k = 0; k < 3; ++k) {
        const double x = dot(a, p[k]), y = dot(a, r[k]);
        hi = std::max(hi, x);
        lo = std::min(lo, y);
        if (k != s) hi_apart = std::max(hi_apart, x);
        if (k != s2) lo_apart = std::min(lo_apart, y);
    }
    const double gap = shared == 0 ? lo - hi : std::min(lo_apart - hi, lo - hi_apart);
    return gap > 0.0 && gap * gap > limit * limit * dot(a, a) * (1.0 + 1e-6);
}

/// The candidate pairs into w.pairs; returns their count, or -1 after writing a crossing
/// found at q0 into w.crossing (particle, triangle). Every pair is found through the pair
/// of triangles that own its primitives, once: each triangle t looks up the triangles
/// t2 > t whose grown boxes meet its box (each_triangle), and for each such pair
///   - the crossing check, when the two triangles' boxes at q0 meet (starts_meet): the owned
///     edges of each through the other (an edge crossing a triangle at q0 lies in its
///     owner's box at q0, which then meets the triangle's);
///   - vertex-triangle: the corners each owns (w.vertex_owner: the first triangle a
///     particle is a corner of) against the other triangle, where the vertex's box meets
///     it grown by g (a vertex's box lies in its owner's);
///   - edge-edge: the owned edges of each against the other's, where their boxes meet
///     grown by g (an edge's box lies in its owner's).
/// A primitive's own triangle holds only pairs that share a vertex, so t2 = t is skipped. A
/// particle of a body that is no triangle's corner looks up the triangles near it alone.
/// Each pair's distance at q0 is measured (gap), and the pair kept when it is below keep.
/// A gather over q0 alone passes over a pair of triangles shown farther apart than keep
/// along one axis (apart_beyond): none of its pairs would be kept, and none of its edges
/// crosses the other triangle (the rows and the check come out the same).
inline index collect(const Stage& st) {
    const Model& m = st.m;
    const ContactBuffers& w = st.w;
    const index tris = m.triangles.count;
    index* owner = w.vertex_owner;
    for (index i = 0; i < m.particles.count; ++i) owner[i] = -1;
    for (index t = tris; t-- > 0;)  // the first triangle of each corner is the last written
        for (int k = 0; k < 3; ++k) owner[m.triangles.indices[3 * t + k]] = t;
    // a patch: a pair is gathered when one of its particles moved (bit 6 of tri_owns: a
    // triangle with a moved corner)
    const double* moved = st.moved;
    const bool patch = moved != nullptr;
    auto involved = [&](const index* v) {
        return !patch || ((moved[8 * v[0]] != 0.0) | (moved[8 * v[1]] != 0.0) |
                          (moved[8 * v[2]] != 0.0) | (moved[8 * v[3]] != 0.0));
    };
    for (index t = 0; t < tris; ++t) {
        w.tri_mark[t] = -1;
        index owns = 0;
        for (int k = 0; k < 3; ++k) {
            const index i = m.triangles.indices[3 * t + k];
            owns |= index(owner[i] == t) << k;
            owns |= index(m.triangles.edge_owner[3 * t + k] != 0) << (3 + k);
            if (patch) owns |= index(moved[8 * i] != 0.0) << 6;
        }
        w.tri_owns[t] = owns;
    }
    index count = st.first;
    bool crossed = false;
    // pairs whose squared distance is at least keep^2 (1 + 1e-6) are far: their bound (at
    // most the squared distance, within round-off far below that margin) at or above it
    // drops them; the others' distances are measured by gap() and compared with keep
    const double far = st.keep * st.keep * (1.0 + 1e-6);
    auto measure = [&](index kind, const index* v) {
        double c[4];
        const V3 d = gap(st.q0, kind, v, c);
        const double dist = std::sqrt(dot(d, d));
        if (dist < st.keep) add_pair(w, count, kind, v, dist);
    };
    Batch vt, ee;
    const bool bounded = far < std::numeric_limits<double>::infinity();  // else all kept
    auto flush = [&]() {
        if (st.swept && !bounded) return flush_swept(st, vt, ee, count);
        if (bounded) {
            vt.load(st.q0);
            ee.load(st.q0);
            vertex_bounds(vt);
            edge_bounds(ee);
        }
        for (int p = 0; p < vt.n; ++p)
            if (!bounded || vt.bound[p] < far) measure(kVertexTriangle, vt.v[p]);
        for (int p = 0; p < ee.n; ++p)
            if (!bounded || ee.bound[p] < far) measure(kEdgeEdge, ee.v[p]);
        vt.n = ee.n = 0;
    };
    // a candidate is written in the batch's next row whether it counts or not, and counted
    // when it does: no branch on its outcome
    auto vertex_triangle = [&](index i, index t2) {
        const index* tri2 = m.triangles.indices + 3 * t2;
        const double* pb = particle_box(st, i);
        const double* box2 = w.tri_box + 6 * t2;
        const bool apart = (tri2[0] != i) & (tri2[1] != i) & (tri2[2] != i);  // else adjacent
        if (vt.n == Batch::kSize) flush();
        const index v[4] = {i, tri2[0], tri2[1], tri2[2]};
        vt.push(v, apart & boxes_meet(pb, pb + 3, box2, box2 + 3, st.g) & involved(v));
    };
    // particles that are no triangle's corner (none in a mesh body): their own look-up
    for (index b = 0; b < m.bodies.count; ++b)
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1];
             ++i) {
            if (owner[i] >= 0) continue;
            const double* box = particle_box(st, i);
            each_triangle(st, box, box + 3, -1, -2 - i, [&](index t2) {
                if (bodies_pair(st, b, m.triangles.body[t2])) vertex_triangle(i, t2);
            });
        }
    for (index t = 0; t < tris && !crossed; ++t) {
        const index* tri = m.triangles.indices + 3 * t;
        const index body = m.triangles.body[t];
        const double* box = w.tri_box + 6 * t;
        // t's owned edges and their boxes, its owned corners
        const index owns = w.tri_owns[t];
        index edges = 0, edge[3][2];
        double elo[3][3], ehi[3][3];
        for (int k = 0; k < 3; ++k) {
            if (!((owns >> (3 + k)) & 1)) continue;
            edge[edges][0] = tri[k];
            edge[edges][1] = tri[(k + 1) % 3];
            edge_box(st, tri[k], tri[(k + 1) % 3], elo[edges], ehi[edges]);
            ++edges;
        }
        index corners = 0, corner[3];
        for (int k = 0; k < 3; ++k)
            if ((owns >> k) & 1) corner[corners++] = tri[k];
        double at0[6];  // swept: t's box at q0, where an edge of it crossing t2 lies
        if (st.swept) start_box(st, tri, at0, at0 + 3);
        // a patch's hash holds the moved triangles alone: a moved t meets those after it,
        // any other t all of them, so each pair of triangles with a moved one meets once
        const index after = patch && !((w.tri_owns[t] >> 6) & 1) ? -1 : t;
        auto visit = [&](index t2) {
            if (crossed || (!st.self && body == m.triangles.body[t2])) return;
            const index* tri2 = m.triangles.indices + 3 * t2;
            if (!st.swept && apart_beyond(st.q0, tri, tri2, st.keep)) return;
            const double* box2 = w.tri_box + 6 * t2;
            if ((!patch || st.check_patch) && st.check &&
                starts_meet(st, st.swept ? at0 : box, tri2, box2) &&
                (edge_through(st, t, tri, t2, tri2) || edge_through(st, t2, tri2, t, tri))) {
                crossed = true;
                return;
            }
            for (index k = 0; k < corners; ++k) vertex_triangle(corner[k], t2);
            const index owns2 = w.tri_owns[t2];
            for (int k = 0; k < 3; ++k)
                if ((owns2 >> k) & 1) vertex_triangle(tri2[k], t);
            for (int k2 = 0; k2 < 3; ++k2) {
                if (!((owns2 >> (3 + k2)) & 1)) continue;
                const index c = tri2[k2], d = tri2[(k2 + 1) % 3];
                double clo[3], chi[3];
                edge_box(st, c, d, clo, chi);
                for (index k = 0; k < edges; ++k) {
                    const index a = edge[k][0], b = edge[k][1];
                    const bool apart = (c != a) & (c != b) & (d != a) & (d != b);  // else adjacent
                    if (ee.n == Batch::kSize) flush();
                    const index v[4] = {a, b, c, d};
                    const bool meet = boxes_meet(elo[k], ehi[k], clo, chi, st.g);
                    ee.push(v, apart & meet & involved(v));
                }
            }
        };
        each_triangle(st, box, box + 3, after, t, visit);
        flush();
    }
    flush();
    return crossed ? -1 : count;
}

/// Step 4: the scales s (w.scale) of u = q - q0 - T that keep the relative displacement of
/// each of the first `pairs` rows within kGamma of its start distance, applied to q. Only
/// the rows' particles are read and written: w.scale is 1 for every particle before and
/// after (a scaled particle is stored, then its scale set back to 1; with mark, to -1:
/// held back, its move in w.held, for hold(), which sets it back to 1).
/// The passes after the first read only the rows with a particle whose scale changed in
/// this pass or the last (w.held's slot 3 holds the pass of each particle's last change,
/// hold() writes it afresh): a row read once leaves its particles' scales within its limit
/// (or at 0), so it holds until one of them changes, and the rows skipped would change
/// nothing (the scales come out as when every row is read in every pass). Each particle's
/// u and |u| are measured once, into w.held's slots 4-7 (hold() writes them afresh).
inline void bound(const Stage& st, index pairs, bool mark = false) {
    const Model& m = st.m;
    const ContactBuffers& w = st.w;
    double* s = w.scale;
    double* changed_in = w.held;  // slot 3 of each particle's row: the pass of its last change
    auto u = [&](index i) { return load(st.q, i) - load(st.q0, i) - st.T; };
    for (index p = 0; p < pairs; ++p)
        for (int k = 0; k < 4; ++k) {
            const index i = w.pairs->data[kSlots * p + 1 + k];
            s[i] = 1.0;
            double* e = w.held + 8 * i;
            e[3] = -2.0;
            const V3 ui = u(i);
            e[4] = ui.x;
            e[5] = ui.y;
            e[6] = ui.z;
            e[7] = std::sqrt(dot(ui, ui));
            if (mark) e[0] = e[1] = e[2] = 0.0;
        }
    for (index pass = 0; pass <= pairs; ++pass) {
        bool changed = false;
        const double recent = static_cast<double>(pass - 1);
        for (index p = 0; p < pairs; ++p) {
            const index* row = w.pairs->data + kSlots * p;
            const index* v = row + 1;
            if (pass > 0 && changed_in[8 * v[0] + 3] < recent &&
                changed_in[8 * v[1] + 3] < recent && changed_in[8 * v[2] + 3] < recent &&
                changed_in[8 * v[3] + 3] < recent)
                continue;  // no scale of its particles changed since it was read
            const double limit = kGamma * pair_distance(row);
            double free_most = 0.0, pinned_most = 0.0;
            V3 du[4];
            double len[4];
            for (int k = 0; k < 4; ++k) {
                const double* e = w.held + 8 * v[k];
                du[k] = V3{e[4], e[5], e[6]};
                len[k] = e[7];
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
                    changed_in[8 * v[k] + 3] = static_cast<double>(pass);
                    changed = true;
                }
            }
        }
        if (!changed) break;
    }
    for (index p = 0; p < pairs; ++p)
        for (int k = 0; k < 4; ++k) {
            const index i = w.pairs->data[kSlots * p + 1 + k];
            if (s[i] >= 1.0 || s[i] < 0.0) continue;  // not held, or stored already
            const V3 was = load(st.q, i);
            store(st.q, i, load(st.q0, i) + st.T + s[i] * u(i));
            if (mark) {
                const V3 dq = load(st.q, i) - was;
                w.held[8 * i] = dq.x;
                w.held[8 * i + 1] = dq.y;
                w.held[8 * i + 2] = dq.z;
            }
            s[i] = mark ? -1.0 : 1.0;
        }
}

/// After bound(..., true): the velocities qd (N, 3) of the particles the bound held back
/// (w.scale -1) and of their pairs', for a step dt [s] (0: none changed). The bound
/// shortened their step but left their velocities, which would propose the same long step
/// again (and the next, each held back again). Each held particle's velocity changes by its
/// bound's move over the step, dq_i / dt (backward and symplectic Euler's q = q0 + dt qd:
/// the velocity its bounded step implies); then, for momentum, every particle of a group
/// of held pairs (pairs with a held particle, joined where they share a particle) takes
/// away the group's mass-weighted mean change (none where the group holds a pinned
/// particle: infinite mass). That is the limit of equal and opposite impulses on the held
/// pairs (particle k's velocity changing by c_k / m_k j, sum_k c_k = 0, barycentric
/// weights as respond's) that bring each pair's relative velocity sum_k c_k qd_k to its
/// relative displacement over the step, sum_k c_k (q_k - q0_k) / dt: a change common to a
/// group leaves every relative velocity in it as it is, and the mean's removal conserves
/// its momentum exactly. It is found directly (the groups by union-find): the impulses
/// pair by pair (Gauss-Seidel) give the first pairs' particles all the change, and a flat
/// sheet held back wrinkles; Jacobi's converge slowly at a sheet's border. No restitution
/// (the pairs have not met) and no friction: within h respond's rule acts next. w.scale
/// is back at 1 after; w.held (N, 8): the move, the group's root, and at a root the
/// group's sum of m dq and its mass.
inline void hold(const Stage& st, index pairs, double* qd, double dt) {
    const Model& m = st.m;
    const ContactBuffers& w = st.w;
    double* s = w.scale;
    double* x = w.held;
    const index* rows = w.pairs->data;
    auto particle = [&](index p, int k) { return rows[kSlots * p + 1 + k]; };
    auto reset = [&] {
        for (index p = 0; p < pairs; ++p)
            for (int k = 0; k < 4; ++k) s[particle(p, k)] = 1.0;
    };
    bool any = false;
    for (index p = 0; p < pairs && !any; ++p)
        for (int k = 0; k < 4; ++k) any |= s[particle(p, k)] < 0.0;
    if (!any || !(dt > 0.0)) return reset();
    auto root = [&](index i) {
        while (static_cast<index>(x[8 * i + 3]) != i) {
            const index up = static_cast<index>(x[8 * i + 3]);
            x[8 * i + 3] = x[8 * up + 3];  // path halving
            i = static_cast<index>(x[8 * up + 3]);
        }
        return i;
    };
    for (index p = 0; p < pairs; ++p)
        for (int k = 0; k < 4; ++k) {
            double* e = x + 8 * particle(p, k);
            e[3] = -1.0;  // in no held pair
            e[4] = e[5] = e[6] = e[7] = 0.0;
        }
    for (index p = 0; p < pairs; ++p) {
        const index v[4] = {particle(p, 0), particle(p, 1), particle(p, 2), particle(p, 3)};
        if (!(s[v[0]] < 0.0 || s[v[1]] < 0.0 || s[v[2]] < 0.0 || s[v[3]] < 0.0)) continue;
        for (int k = 0; k < 4; ++k)
            if (x[8 * v[k] + 3] < 0.0) x[8 * v[k] + 3] = static_cast<double>(v[k]);
        const index r0 = root(v[0]);
        for (int k = 1; k < 4; ++k) {
            const index r = root(v[k]);
            if (r != r0) x[8 * r + 3] = static_cast<double>(r0);
        }
    }
    // each grouped particle once (w.scale 2 once counted, 3 once moved): the groups' sums
    const double inf = std::numeric_limits<double>::infinity();
    for (index p = 0; p < pairs; ++p)
        for (int k = 0; k < 4; ++k) {
            const index i = particle(p, k);
            if (x[8 * i + 3] < 0.0 || s[i] == 2.0) continue;
            s[i] = 2.0;
            double* r = x + 8 * root(i);
            if (m.particles.inv_mass[i] == 0.0) {
                r[7] = inf;
                continue;
            }
            const double mi = m.particles.mass[i];
            for (int d = 0; d < 3; ++d) r[4 + d] += mi * x[8 * i + d];
            r[7] += mi;
        }
    const double inv_dt = 1.0 / dt;
    for (index p = 0; p < pairs; ++p)
        for (int k = 0; k < 4; ++k) {
            const index i = particle(p, k);
            if (s[i] != 2.0) continue;
            s[i] = 3.0;
            if (m.particles.inv_mass[i] == 0.0) continue;
            const double* r = x + 8 * root(i);
            const double share = r[7] < inf ? 1.0 / r[7] : 0.0;
            add_to(qd, i, inv_dt * V3{x[8 * i] - share * r[4], x[8 * i + 1] - share * r[5],
                                      x[8 * i + 2] - share * r[6]});
        }
    reset();
}

/// Step 5: pairs closer than h pushed apart to h, approaching ones' velocities turned. A
/// row whose distance at q0 (slot 5) less the most its particles moved apart from each
/// other since, max |(q_a - q0_a) - (q_b - q0_b)| over a and b on its two sides, is at
/// least h is not measured: its gap with its closest points' coefficients at q0 (each
/// side's weights sum to 1) changed by at most that much, so it is not closer than h.
inline void respond(const Stage& st, index pairs, double* qd) {
    const Model& m = st.m;
    const ContactBuffers& w = st.w;
    const double h = m.soft_contacts.thickness;
    const double e = m.soft_contacts.restitution, mu = m.soft_contacts.friction;
    for (index p = 0; p < pairs; ++p) {
        const index* row = w.pairs->data + kSlots * p;
        const index* v = row + 1;
        const double start = pair_distance(row);
        if (start >= h) {  // not measured when its particles' moves cannot bring it within h
            V3 du[4];
            for (int k = 0; k < 4; ++k) du[k] = load(st.q, v[k]) - load(st.q0, v[k]);
            const int side = row[0] == kVertexTriangle ? 1 : 2;
            double most = 0.0;
            for (int k = 0; k < side; ++k)
                for (int l = side; l < 4; ++l) {
                    const V3 r = du[k] - du[l];
                    most = std::max(most, dot(r, r));
                }
            if (start - std::sqrt(most) >= h) continue;
        }
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
            swept_box(st, i, a, z);
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
/// crossing check) with the stage's settings; grows the hash and the list when they must.
/// Returns their count; -1 for a crossing; or, below -1, minus the entries the hash needed
/// (less 1) when its buffer could not grow to them, or minus the pairs the list needed
/// (less 1) when it could not grow to them, with w.list[2] = 1 (0 for the hash).
inline index gather(const Stage& stage) {
    const ContactBuffers& w = stage.w;
    Stage st = stage;
    fill_boxes(st);
    double scale = 0.0;
    const double half = tri_boxes(st, scale);
    // a list's gather looks up its boxes' centres (each_triangle), the hashed boxes grown
    // by the largest half extent, and by a little more for the round-off of the centre, the
    // grown bounds and the comparisons (relative 1e-9 of the growth, 1e-12 of the largest
    // coordinate: far above the few rounding errors of a coordinate's size)
    st.half = st.swept ? -1.0 : half + 1e-9 * (half + st.g) + 1e-12 * scale;
    const index needed = build_hash(st);
    if (needed > w.hash_entries->capacity) {
        HashEntries& entries = *w.hash_entries;
        w.list[2] = 0;
        if (entries.grow == nullptr || !entries.grow(entries, needed)) return -1 - needed;
        build_hash(st);
    }
    index pairs = collect(st);
    if (pairs >= 0 && pairs * kSlots > w.pairs->capacity) {
        HashEntries& list = *w.pairs;
        w.list[2] = 1;
        if (list.grow == nullptr || !list.grow(list, pairs * kSlots)) return -1 - pairs;
        pairs = collect(st);
    }
    return pairs;
}

/// The first `count` rows (kSlots each) without those with a particle flagged in moved
/// (moved[8 i] != 0), the others kept in their order at the front; returns how many.
inline index drop_moved(index* rows, index count, const double* moved) {
    index kept = 0;
    for (index p = 0; p < count; ++p) {
        const index* row = rows + kSlots * p;
        if (moved[8 * row[1]] != 0.0 || moved[8 * row[2]] != 0.0 || moved[8 * row[3]] != 0.0 ||
            moved[8 * row[4]] != 0.0)
            continue;
        if (kept != p) std::memmove(rows + kSlots * kept, row, sizeof(index) * kSlots);
        ++kept;
    }
    return kept;
}

constexpr double kReuseMost = 0.25;  // the most particles (a share of all) a reuse gathers again

/// A later pass's candidate pairs from an earlier swept gather's rows (w.pairs rows
/// [0, count)): the earlier gather from the same q0 with the same T, over the positions
/// `from` (N, 3), with slack st.slack = `slack`; this pass's own positions st.q, no slack.
/// Returns the rows (kept first), or gather()'s codes.
///
/// Why the rows serve: with u = from - q0 - T, the earlier gather kept every pair whose
/// particles' boxes over q0 and q0 + u, grown by the slack, meet grown by g, and whose
/// distance D at q0 is at most h + M + 2 slack, M the most its particles' scaled moves
/// can close it, max |b_a u_a - b_b u_b| over b in [0, 1]^2 (swept_reach). This pass
/// moves particle k to q0 + T + a_k u'_k + e_k (u' = q - q0 - T, a_k in [0, 1], its
/// response |e_k| <= h / 2). A particle whose u'_k lies within the slack of the segment
/// [0, u_k], u'_k = c_k u_k + r_k (c_k in [0, 1], |r_k| <= slack), stays in its earlier box
/// (q0 + b u_k + a_k r_k with b = a_k c_k in [0, 1]: in the box of the segment, grown by the
/// slack), and for two such particles |a_a u'_a - a_b u'_b| <= |b_a u_a - b_b u_b| +
/// 2 slack <= M + 2 slack: this pass's boxes and reach of a pair of them lie within the
/// earlier gather's, so every pair of them this pass's own swept gather would keep is
/// among the rows (with its distance at q0, the same). The particles outside (`moved`: each
/// one's least |u'_k - c u_k| over c in [0, 1] over the slack) have their rows dropped and
/// their pairs gathered afresh for this pass (a patch, as patch_list's: a hash of the
/// triangles with a moved corner, looked up by every triangle, every pair with a moved
/// particle kept by this pass's own swept boxes and reach), after the kept rows: no pair
/// twice. No crossing check: the earlier gather made it at the same q0. A whole gather
/// instead (st's, with its check) when more than kReuseMost of the particles moved or a
/// moved particle of a body is no triangle's corner (a patch looks such a particle up in
/// the hash of the moved triangles alone).
inline index reuse_swept(const Stage& st, const double* from, double slack, index count) {
    const Model& m = st.m;
    const ContactBuffers& w = st.w;
    double* moved = w.held;  // its first slot a flag per particle (hold()'s scratch till then)
    index outside = 0;
    bool lone = false;
    for (index i = 0; i < m.particles.count; ++i) {
        const V3 x0 = load(st.q0, i);
        const V3 d = load(st.q, i) - x0 - st.T, u = load(from, i) - x0 - st.T;
        const double uu = dot(u, u);
        const double c = uu > 0.0 ? std::min(1.0, std::max(0.0, dot(d, u) / uu)) : 0.0;
        const V3 r = d - c * u;
        const bool out = !(dot(r, r) <= slack * slack);  // NaN: out
        moved[8 * i] = out ? 1.0 : 0.0;
        outside += out;
        lone |= out && m.particles.body[i] >= 0 && w.vertex_owner[i] < 0;
    }
    if (outside == 0) return count;
    if (lone || static_cast<double>(outside) > kReuseMost * static_cast<double>(m.particles.count))
        return gather(st);
    const index kept = drop_moved(w.pairs->data, count, moved);
    Stage part = st;
    part.moved = moved;
    part.first = kept;
    part.slack = 0.0;
    return gather(part);
}

constexpr int kBands = 64;  // the list's rows are ordered by band of build distance, R / 64 wide

/// The band of build distance d in a list of radius R: floor(64 d / R), within [0, 63].
inline int band_of(double d, double inv_width) {
    const double b = d * inv_width;
    return b >= 0.0 && b < kBands - 1 ? static_cast<int>(b) : (b >= 0.0 ? kBands - 1 : 0);
}

/// Orders rows [0, pairs) by band of their build distance, in place: counts per band, then
/// each row swapped into its band's next free place (an American flag sort), O(pairs).
inline void sort_bands(index* rows, index pairs, double inv_width) {
    index start[kBands + 1] = {}, next[kBands];
    for (index p = 0; p < pairs; ++p) ++start[band_of(build_distance(rows + kSlots * p), inv_width) + 1];
    for (int b = 0; b < kBands; ++b) start[b + 1] += start[b];
    for (int b = 0; b < kBands; ++b) next[b] = start[b];
    for (int b = 0; b < kBands; ++b)
        while (next[b] < start[b + 1]) {
            index* row = rows + kSlots * next[b];
            const int home = band_of(build_distance(row), inv_width);
            if (home == b) {
                ++next[b];
                continue;
            }
            index* there = rows + kSlots * next[home]++;
            for (index k = 0; k < kSlots; ++k) std::swap(row[k], there[k]);
        }
}

/// The rows of a list sorted by sort_bands whose build distance may be below x: all rows
/// before the first in a band above x's (a binary search).
inline index rows_below(const index* rows, index pairs, double x, double inv_width) {
    if (!(x * inv_width < kBands - 1)) return pairs;
    const int last = band_of(x, inv_width);
    index lo = 0, hi = pairs;
    while (lo < hi) {
        const index mid = lo + (hi - lo) / 2;
        if (band_of(build_distance(rows + kSlots * mid), inv_width) <= last)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/// Each of rows [from, to)'s distance at the step's start q0 into its slot 5.
inline void refresh(const double* q0, index* rows, index from, index to) {
    for (index p = from; p < to; ++p) {
        index* row = rows + kSlots * p;
        double c[4];
        const V3 g = gap(q0, row[0], row + 1, c);
        const double d = std::sqrt(dot(g, g));
        std::memcpy(row + 5, &d, sizeof(double));
    }
}

/// The bodies' motion: T, the mass-weighted mean displacement q - q0 of their free
/// particles; mu >= max_i |q_i - q0_i - T| over their particles; and, with a list (qb, its
/// build positions), the list's drift q0 - qb as a map that takes every gap vector of
/// length D_b at qb to one of length at least stretch D_b - 2 residual at q0 (see
/// contacts()), and sigma = residual + (1 - stretch) R / 2 for a list of radius R: the
/// drift of a translation alone (stretch 1) would have to be that large to bring a pair
/// from R as near. sigma may be negative (a list whose bodies grew).
struct Motion {
    V3 T{0.0, 0.0, 0.0};
    double mu = 0.0;
    double sigma = std::numeric_limits<double>::infinity();
    double stretch = 1.0;  // a lower bound on sigma_min(I + A), the affine part's
    double residual = std::numeric_limits<double>::infinity();  // max_i |e_i| [m]
    // the fit the residual was measured with, e_i = q0_i - qb_i - C - A (qb_i - c) (A = 0:
    // the translation's; set where motion() measured the residual itself)
    V3 C{0.0, 0.0, 0.0}, c{0.0, 0.0, 0.0};
    double A[9] = {};
    /// The smallest build distance a pair may have and still come within x at q0 (x >= 0):
    /// (x + 2 residual) / stretch.
    double reach(double x) const {
        return stretch > 0.0 ? (x + 2.0 * residual) / stretch
                             : std::numeric_limits<double>::infinity();
    }
};

/// The largest distance from c to a point of the box [lo, hi] (an upper bound on the
/// largest |x - c| over the points x it holds).
inline double farthest(const double* lo, const double* hi, V3 c) {
    double sum = 0.0;
    for (int k = 0; k < 3; ++k) {
        const double a = hi[k] - (&c.x)[k], b = (&c.x)[k] - lo[k];
        sum += std::max(a * a, b * b);
    }
    return std::sqrt(sum);
}

/// The least-squares affine part of a drift: A (3x3, row major) with d_i - C ~ A r_i, from
/// the mass-weighted sums rr = sum m r r^T, dr = sum m (d - C) r^T over the particles'
/// offsets r from their centre (both centred): A = dr (rr + eps tr(rr) I)^-1 (the small
/// ridge keeps a flat sheet's fit finite; any A is valid, the residual measured with it).
/// False when rr is degenerate (A = 0 then).
inline bool affine_fit(const double* rr, const double* dr, double* A) {
    for (int k = 0; k < 9; ++k) A[k] = 0.0;
    const double trace = rr[0] + rr[4] + rr[8];
    if (!(trace > 0.0) || !std::isfinite(trace)) return false;
    double s[9];
    for (int k = 0; k < 9; ++k) s[k] = rr[k];
    for (int k = 0; k < 3; ++k) s[4 * k] += 1e-9 * trace;
    const double inv_cof[9] = {s[4] * s[8] - s[5] * s[7], s[2] * s[7] - s[1] * s[8],
                               s[1] * s[5] - s[2] * s[4], s[5] * s[6] - s[3] * s[8],
                               s[0] * s[8] - s[2] * s[6], s[2] * s[3] - s[0] * s[5],
                               s[3] * s[7] - s[4] * s[6], s[1] * s[6] - s[0] * s[7],
                               s[0] * s[4] - s[1] * s[3]};  // the adjugate
    const double det = s[0] * inv_cof[0] + s[1] * inv_cof[3] + s[2] * inv_cof[6];
    if (!(det > 0.0) || !std::isfinite(det)) return false;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) {
            double sum = 0.0;
            for (int k = 0; k < 3; ++k) sum += dr[3 * r + k] * inv_cof[3 * k + c];
            A[3 * r + c] = sum / det;
        }
    for (int k = 0; k < 9; ++k)
        if (!std::isfinite(A[k])) {
            for (int l = 0; l < 9; ++l) A[l] = 0.0;
            return false;
        }
    return true;
}

/// A lower bound on the smallest singular value of F = I + A (A 3x3, row major): the square
/// root of Gershgorin's lower bound on the smallest eigenvalue of F^T F (symmetric, PSD),
/// less a relative 1e-12 for its round-off; 0 when that bound is not positive.
inline double least_stretch(const double* A) {
    double F[9];
    for (int k = 0; k < 9; ++k) F[k] = A[k] + (k % 4 == 0 ? 1.0 : 0.0);
    double B[9];
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
            B[3 * r + c] = F[r] * F[c] + F[3 + r] * F[3 + c] + F[6 + r] * F[6 + c];
    double low = std::numeric_limits<double>::infinity();
    for (int r = 0; r < 3; ++r) {
        double off = 0.0;
        for (int c = 0; c < 3; ++c)
            if (c != r) off += std::fabs(B[3 * r + c]);
        low = std::min(low, B[4 * r] - off);
    }
    low -= 1e-12 * (B[0] + B[4] + B[8]);
    return low > 0.0 && std::isfinite(low) ? std::sqrt(low) : 0.0;
}

/// Motion in one pass over the particles: the means, and mu and the list's drift bounded by
/// the boxes of the displacements (a translation's drift: stretch 1). exact: true (or,
/// with a list, the boxes' bound over half its skin) takes a second pass for the largest
/// offsets themselves, and the sums of the drift's affine fit; where the translation's
/// drift still fails the list of radius `radius` [m], a third pass measures the fit's
/// residual, and the affine bound is kept where its sigma is smaller (a list the
/// translation's bound would build again; the passes cost a small fraction of a build).
/// With translate false, T = 0.
inline Motion motion(const Model& m, const double* q0, const double* q, const double* qb,
                     bool exact, bool translate = true, double radius = 0.0) {
    const double inf = std::numeric_limits<double>::infinity();
    double mass = 0.0, lo_u[3] = {inf, inf, inf}, hi_u[3] = {-inf, -inf, -inf};
    double lo_d[3] = {inf, inf, inf}, hi_d[3] = {-inf, -inf, -inf};
    V3 sum_u{0.0, 0.0, 0.0}, sum_d{0.0, 0.0, 0.0};
    for (index b = 0; b < m.bodies.count; ++b)
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1];
             ++i) {
            const V3 du = load(q, i) - load(q0, i);
            const V3 dd = qb != nullptr ? load(q0, i) - load(qb, i) : V3{0.0, 0.0, 0.0};
            for (int k = 0; k < 3; ++k) {
                lo_u[k] = std::min(lo_u[k], (&du.x)[k]);
                hi_u[k] = std::max(hi_u[k], (&du.x)[k]);
                lo_d[k] = std::min(lo_d[k], (&dd.x)[k]);
                hi_d[k] = std::max(hi_d[k], (&dd.x)[k]);
            }
            if (m.particles.inv_mass[i] == 0.0) continue;
            const double mi = m.particles.mass[i];
            mass += mi;
            sum_u = sum_u + mi * du;
            sum_d = sum_d + mi * dd;
        }
    Motion out;
    if (mass > 0.0 && translate) out.T = (1.0 / mass) * sum_u;
    const V3 C = mass > 0.0 ? (1.0 / mass) * sum_d : V3{0.0, 0.0, 0.0};
    out.C = C;
    if (!(hi_u[0] >= lo_u[0])) {  // no particle in a body
        out.sigma = out.residual = 0.0;
        return out;
    }
    out.mu = farthest(lo_u, hi_u, out.T);
    if (qb != nullptr) out.sigma = out.residual = farthest(lo_d, hi_d, C);
    const double skin = radius - 2.0 * m.soft_contacts.thickness;  // the list's S
    if (!exact && !(qb != nullptr && out.sigma + out.mu > 0.5 * skin)) return out;
    // the largest offsets, and the affine fit's sums about an origin near the bodies (their
    // round-off): rr = sum m r r^T, dr = sum m (d - C) r^T, r = qb - ref
    double rr[9] = {}, dr[9] = {};
    V3 ref{0.0, 0.0, 0.0}, sum_r{0.0, 0.0, 0.0};
    bool first = true;
    double mu = 0.0, sigma = 0.0;
    for (index b = 0; b < m.bodies.count; ++b)
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1];
             ++i) {
            const V3 u = load(q, i) - load(q0, i) - out.T;
            mu = std::max(mu, dot(u, u));
            if (qb == nullptr) continue;
            const V3 d = load(q0, i) - load(qb, i) - C;
            sigma = std::max(sigma, dot(d, d));
            if (m.particles.inv_mass[i] == 0.0) continue;
            if (first) ref = load(qb, i);
            first = false;
            const double mi = m.particles.mass[i];
            const V3 r = load(qb, i) - ref;
            sum_r = sum_r + mi * r;
            for (int a = 0; a < 3; ++a)
                for (int c = 0; c < 3; ++c) {
                    rr[3 * a + c] += mi * (&r.x)[a] * (&r.x)[c];
                    dr[3 * a + c] += mi * (&d.x)[a] * (&r.x)[c];
                }
        }
    out.mu = std::sqrt(mu);
    if (qb == nullptr) return out;
    out.residual = out.sigma = std::sqrt(sigma);
    out.stretch = 1.0;
    if (out.sigma + out.mu <= 0.5 * skin || !(mass > 0.0)) return out;
    // the affine fit about the centre c of the build positions (the sums centred there;
    // sum m (d - C) = 0, so dr needs no centring), and its residual
    const V3 rc = (1.0 / mass) * sum_r;
    const V3 c = ref + rc;
    for (int a = 0; a < 3; ++a)
        for (int k = 0; k < 3; ++k) rr[3 * a + k] -= mass * (&rc.x)[a] * (&rc.x)[k];
    double A[9];
    if (!affine_fit(rr, dr, A)) return out;
    const double stretch = least_stretch(A);
    if (!(stretch > 0.0) || 0.5 * (1.0 - stretch) * radius >= out.sigma) return out;
    double resid = 0.0;
    for (index b = 0; b < m.bodies.count; ++b)
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1];
             ++i) {
            const V3 d = load(q0, i) - load(qb, i) - C;
            const V3 r = load(qb, i) - c;
            const V3 e{d.x - (A[0] * r.x + A[1] * r.y + A[2] * r.z),
                       d.y - (A[3] * r.x + A[4] * r.y + A[5] * r.z),
                       d.z - (A[6] * r.x + A[7] * r.y + A[8] * r.z)};
            resid = std::max(resid, dot(e, e));
        }
    const double residual = std::sqrt(resid) * (1.0 + 1e-12);
    const double affine = residual + 0.5 * (1.0 - stretch) * radius;
    if (affine < out.sigma) {
        out.sigma = affine;
        out.stretch = stretch;
        out.residual = residual;
        out.c = c;
        for (int k = 0; k < 9; ++k) out.A[k] = A[k];
    }
    return out;
}

constexpr double kServe = 32.0;  // steps a new list's skin is sized to serve
constexpr double kMostSkin = 2.0;  // a list's skin at most, in margins g

/// The list's drift fit kept between steps, in w.list_skin[2..21]: whether it is set, A
/// (3x3), its centre c, C (the mean of q0 - qb - A (qb - c) at the last step, moved on by
/// that step's T: the next step's estimate), the last step's T, and least_stretch(A).
struct Fit {
    double* x;
    explicit Fit(const ContactBuffers& w) : x(w.list_skin + 2) {}
    bool set() const { return x[0] != 0.0; }
    const double* A() const { return x + 1; }
    V3 c() const { return V3{x[10], x[11], x[12]}; }
    V3 C() const { return V3{x[13], x[14], x[15]}; }
    V3 T() const { return V3{x[16], x[17], x[18]}; }
    double stretch() const { return x[19]; }
    /// The fit mo was measured with (its C the estimate for the next step, after T).
    void keep(const Motion& mo) {
        x[0] = 1.0;
        for (int k = 0; k < 9; ++k) x[1 + k] = mo.A[k];
        for (int k = 0; k < 3; ++k) {
            x[10 + k] = (&mo.c.x)[k];
            x[13 + k] = (&mo.C.x)[k] + (&mo.T.x)[k];
            x[16 + k] = (&mo.T.x)[k];
        }
        x[19] = mo.stretch;
    }
    /// A new list's: its drift 0 (A = 0, C = 0).
    void reset() {
        for (int k = 0; k < 20; ++k) x[k] = 0.0;
        x[0] = 1.0;
        x[19] = 1.0;
    }
};

/// The bodies' motion in one pass with the kept fit (Fit: any C, A give a valid bound, the
/// residual measured with them): T the mean displacement of the free particles, mu <=
/// max_i |u_i - T_last| + |T - T_last| (u_i = q_i - q0_i), the residual max_i |q0_i - qb_i -
/// C - A (qb_i - c)| with C the fit's estimate, and sigma from the fit's stretch; C out is
/// the mean the pass found (for the next step's estimate). With translate false, T = 0.
/// The pass runs every step a list serves: it takes its particles kLanes at a time, their
/// coordinates gathered into lanes (a block's last particle repeated where a body ends
/// inside it, with no mass: the largest values are unchanged), each lane keeping its own
/// largest values and sums, so that the arithmetic runs in vector lanes; the lanes' sums
/// are added at the end (a different order of the same terms: T and C differ from a
/// particle-by-particle sum by round-off alone, mu and the residual not at all).
inline Motion kept_motion(const Model& m, const double* q0, const double* q, const double* qb,
                          const Fit& fit, bool translate, double radius) {
    constexpr int kLanes = 8;
    const double* A = fit.A();
    const V3 c = fit.c(), C = fit.C(), T_last = translate ? fit.T() : V3{0.0, 0.0, 0.0};
    double mu_l[kLanes] = {}, resid_l[kLanes] = {}, mass_l[kLanes] = {};
    double su[3][kLanes] = {}, se[3][kLanes] = {};
    for (index b = 0; b < m.bodies.count; ++b) {
        const index first = m.bodies.particle_range[2 * b],
                    end = m.bodies.particle_range[2 * b + 1];
        for (index i0 = first; i0 < end; i0 += kLanes) {
            double x0[3][kLanes], xb[3][kLanes], du[3][kLanes], mi[kLanes];
            for (int l = 0; l < kLanes; ++l) {
                const bool in = i0 + l < end;
                const index i = in ? i0 + l : end - 1;
                for (int d = 0; d < 3; ++d) {
                    x0[d][l] = q0[3 * i + d];
                    xb[d][l] = qb[3 * i + d];
                    du[d][l] = q[3 * i + d] - x0[d][l];
                }
                mi[l] = in && m.particles.inv_mass[i] != 0.0 ? m.particles.mass[i] : 0.0;
            }
            for (int l = 0; l < kLanes; ++l) {
                const double rx = xb[0][l] - c.x, ry = xb[1][l] - c.y, rz = xb[2][l] - c.z;
                const double ex = x0[0][l] - xb[0][l] - (A[0] * rx + A[1] * ry + A[2] * rz);
                const double ey = x0[1][l] - xb[1][l] - (A[3] * rx + A[4] * ry + A[5] * rz);
                const double ez = x0[2][l] - xb[2][l] - (A[6] * rx + A[7] * ry + A[8] * rz);
                const double ux = du[0][l] - T_last.x, uy = du[1][l] - T_last.y,
                             uz = du[2][l] - T_last.z;
                const double fx = ex - C.x, fy = ey - C.y, fz = ez - C.z;
                const double uu = ux * ux + uy * uy + uz * uz, ff = fx * fx + fy * fy + fz * fz;
                mu_l[l] = mu_l[l] < uu ? uu : mu_l[l];
                resid_l[l] = resid_l[l] < ff ? ff : resid_l[l];
                mass_l[l] += mi[l];
                su[0][l] += mi[l] * du[0][l];
                su[1][l] += mi[l] * du[1][l];
                su[2][l] += mi[l] * du[2][l];
                se[0][l] += mi[l] * ex;
                se[1][l] += mi[l] * ey;
                se[2][l] += mi[l] * ez;
            }
        }
    }
    double mass = 0.0, mu = 0.0, resid = 0.0;
    V3 sum_u{0.0, 0.0, 0.0}, sum_e{0.0, 0.0, 0.0};
    for (int l = 0; l < kLanes; ++l) {
        mu = std::max(mu, mu_l[l]);
        resid = std::max(resid, resid_l[l]);
        mass += mass_l[l];
        sum_u = sum_u + V3{su[0][l], su[1][l], su[2][l]};
        sum_e = sum_e + V3{se[0][l], se[1][l], se[2][l]};
    }
    Motion out;
    if (mass > 0.0 && translate) out.T = (1.0 / mass) * sum_u;
    const V3 dT = out.T - T_last;
    out.mu = std::sqrt(mu) + std::sqrt(dot(dT, dT));
    out.stretch = fit.stretch();
    out.residual = std::sqrt(resid) * (1.0 + 1e-12);
    out.sigma = out.residual + 0.5 * (1.0 - out.stretch) * radius;
    for (int k = 0; k < 9; ++k) out.A[k] = A[k];
    out.c = c;
    out.C = C;
    if (mass > 0.0) out.C = (1.0 / mass) * sum_e;  // for keep(): the next step's estimate
    return out;
}

/// The list at st.q0 with skin s [m]: the pairs nearer than 2 h + s (gather, with its
/// crossing check), their rows ordered by band of build distance, the build positions in
/// w.q_build, w.list[0] their count and w.list_skin (s, 1 step served). Returns gather's
/// value (the count, -1 for a crossing, below -1 no room); the list stays dropped unless it
/// was built. Every builder of the list (the stage, the implicit solve's contacts) builds
/// it here, so the stage can read it.
inline index build_list(const Stage& st, double s) {
    const ContactBuffers& w = st.w;
    Stage list = st;
    list.swept = false;
    list.g = 2.0 * st.m.soft_contacts.thickness + s;
    list.keep = list.g;
    w.list[0] = -1;
    const index pairs = gather(list);
    if (pairs < 0) return pairs;
    for (index k = 0; k < 3 * st.m.particles.count; ++k) w.q_build[k] = st.q0[k];
    Fit(w).reset();
    sort_bands(w.pairs->data, pairs, kBands / list.g);
    w.list[0] = pairs;
    w.list_skin[0] = s;
    w.list_skin[1] = 1.0;
    return pairs;
}

constexpr double kPatchKeep = 0.5;   // a patch leaves residuals up to this share of the room
constexpr double kPatchRoom = 0.25;  // the least room (of S / 2) a patch is tried with
constexpr double kPatchMost = 0.25;  // the most particles (a share of all) a patch moves

/// The list patched where it drifted (contacts(), "a patch"): the particles whose residual
/// e_i (mo's fit) exceeds kPatchKeep of the room the step leaves, S / 2 - mu -
/// (1 - stretch) R / 2, are moved in w.q_build to where the fit maps to their q0, their
/// rows dropped and their pairs gathered again at the new w.q_build (without the crossing
/// check), the rows ordered again; drift: the list's drift for the step, after the patch.
/// whole: true (nothing changed but w.q_build) when a patch would not serve (too little
/// room, too many particles, a singular fit): build the list whole. Returns the list's
/// rows, or below -1 when a buffer could not grow to them (the list dropped, as gather()).
inline index patch_list(const Stage& st, const Motion& mo, Motion& drift, bool& whole) {
    const Model& m = st.m;
    const ContactBuffers& w = st.w;
    whole = true;
    const double S = w.list_skin[0], R = 2.0 * m.soft_contacts.thickness + S;
    const double bend = 0.5 * (1.0 - mo.stretch) * R;
    const double room = 0.5 * S - mo.mu - bend;  // the residual the list allows this step
    if (!(room > kPatchRoom * 0.5 * S) || !(mo.stretch > 0.0)) return 0;
    const double keep = kPatchKeep * room;
    // (I + A)^-1 by its adjugate
    const double* A = mo.A;
    const double F[9] = {1.0 + A[0], A[1], A[2], A[3], 1.0 + A[4], A[5], A[6], A[7], 1.0 + A[8]};
    const double adj[9] = {F[4] * F[8] - F[5] * F[7], F[2] * F[7] - F[1] * F[8],
                           F[1] * F[5] - F[2] * F[4], F[5] * F[6] - F[3] * F[8],
                           F[0] * F[8] - F[2] * F[6], F[2] * F[3] - F[0] * F[5],
                           F[3] * F[7] - F[4] * F[6], F[1] * F[6] - F[0] * F[7],
                           F[0] * F[4] - F[1] * F[3]};
    const double det = F[0] * adj[0] + F[1] * adj[3] + F[2] * adj[6];
    if (!(det > 0.0) || !std::isfinite(det)) return 0;
    auto map = [&](const double* M, V3 r) {
        return V3{M[0] * r.x + M[1] * r.y + M[2] * r.z, M[3] * r.x + M[4] * r.y + M[5] * r.z,
                  M[6] * r.x + M[7] * r.y + M[8] * r.z};
    };
    double* moved = w.held;  // its first slot a flag per particle (hold()'s scratch till then)
    for (index i = 0; i < m.particles.count; ++i) moved[8 * i] = 0.0;
    index count = 0, particles = 0;
    double most = 0.0;
    bool lone = false;  // a moved particle that is no triangle's corner (the last gather's)
    for (index b = 0; b < m.bodies.count; ++b)
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1];
             ++i) {
            ++particles;
            const V3 x0 = load(st.q0, i), xb = load(w.q_build, i);
            const V3 e = x0 - xb - mo.C - map(A, xb - mo.c);
            if (dot(e, e) <= keep * keep) {
                most = std::max(most, dot(e, e));
                continue;
            }
            // q0_i - C - c = (I + A) (x - c): x, the build position the fit maps to q0_i
            const V3 x = mo.c + (1.0 / det) * map(adj, x0 - mo.C - mo.c);
            const V3 e2 = x0 - x - mo.C - map(A, x - mo.c);
            most = std::max(most, dot(e2, e2));
            store(w.q_build, i, x);
            moved[8 * i] = 1.0;
            ++count;
            lone |= w.vertex_owner[i] < 0;
        }
    if (count == 0) return 0;  // the room left no particle to move (round-off): build whole
    const double residual = std::sqrt(most) * (1.0 + 1e-12);
    if (lone || static_cast<double>(count) > kPatchMost * static_cast<double>(particles) ||
        residual + bend + mo.mu > 0.5 * S)
        return 0;  // w.q_build is built again whole
    whole = false;
    // the rows between particles that stayed, in their order
    const index kept = drop_moved(w.pairs->data, w.list[0], moved);
    Stage part = st;
    part.q0 = w.q_build;
    part.swept = false;
    part.g = R;
    part.keep = R;
    part.moved = moved;
    part.first = kept;
    w.list[0] = -1;
    const index pairs = gather(part);
    if (pairs < 0) return pairs;  // no room (a patch makes no crossing check)
    sort_bands(w.pairs->data, pairs, kBands / R);
    w.list[0] = pairs;
    drift = mo;
    drift.residual = residual;
    drift.sigma = residual + bend;
    return pairs;
}

/// The stage (steps 1-5) on q, qd (N, 3) in place, from the step's start q0 (N, 3); with
/// translate false, T = 0 (with rigid colliders near: the bound then holds particles back
/// toward where they started, outside the colliders, not toward q0 + T, which may be inside
/// one; loop::thick_with_colliders).
/// Returns
/// 0; the entries the hash, or the pairs the list, needed when its buffer could not grow to
/// them (nothing resolved; w.list[2] says which: 0 the hash, 1 the list); or -1 for a
/// crossing at q0 (w.crossing: particle, triangle; nothing changed).
///
/// The pairs come from a list kept between steps (a Verlet list): the pairs nearer than
/// R = 2 h + S at the positions q_b where it was built, S its skin. The list's drift
/// q0 - q_b is written as an affine map and a residual, q0_i = q_b,i + C + A (q_b,i - c)
/// + e_i (C, A the mass-weighted least-squares fit over the bodies' free particles, all
/// bodies together, c their centre at the build; any C, A would do, the residual is
/// measured with them). A pair's gap at any positions x is sum_k c_k x_k with fixed
/// barycentric coefficients summing to 0 (those of its closest points: 1 and -1 on each
/// side), so C drops out and A acts on the gap itself: at q0 the same coefficients give
/// (I + A) g_b + sum_k c_k e_k, of length at least sigma_min(I + A) |g_b| - 2 max |e|, and
/// the pair's distance at q0 (the least over coefficients) is at least
/// stretch D_b - 2 residual, with stretch <= sigma_min(I + A) (Gershgorin's lower bound on
/// the smallest eigenvalue of (I + A)^T (I + A), square-rooted: least_stretch) and
/// residual >= max |e_i|. A translation alone is the case A = 0, stretch 1, residual the
/// largest offset after C; where the translation's bound would build the list again,
/// motion() takes the affine one if it is larger at R (a spinning, breathing or sheared
/// body's drift is nearly affine: its residual stays small where its offsets after C do
/// not; two bodies that breathe differently leave a larger residual, and the translation's
/// bound then serves). Written as a drift
/// sigma = residual + (1 - stretch) R / 2, a pair off the list (D_b >= R) starts the step
/// at least stretch R - 2 residual = R - 2 sigma apart. While the bodies' particles move by
/// mu in the step (after T), with sigma + mu <= S / 2, such a pair stays (bound, and
/// response moves of h / 2 a side) at least R - 2 (sigma + mu) - h >= h apart along the
/// whole step: it can neither cross nor need a response, so neither the bound nor the
/// response needs it. The same holds for a listed pair whose build distance is at least
/// (2 (mu + r) + h + 2 residual) / stretch, r the largest response move (0 before the
/// response, at most h / 2): it starts at least 2 (mu + r) + h apart. The list's rows are
/// ordered by band of build distance, and a step reads only the rows below that (a
/// prefix: w.list[1] rows, their distance at q0 in slot 5). The skin S is chosen at each
/// build from the motion the last list saw (sigma + mu over the steps it served), so that a
/// list serves about kServe steps, between the margin g and kMostSkin g. The list is built
/// again (at q0, with the crossing check) when sigma + mu > S / 2; a step whose own motion
/// is over kMostSkin g / 2 takes its pairs from the swept boxes instead (and the list is
/// dropped). The step's own motion is bounded after T alone (not fitted by an affine map
/// too: on the implicit ball drop the step's affine residual stays 1-6 cm, over
/// kMostSkin g / 2, so it would not spare those steps their sweep; and with rigid
/// colliders near the bodies, or in a step it could keep its list without T, the stage
/// runs with T = 0, its bound holding particles toward q0: loop::thick_with_colliders).
///
/// The kept fit: a step first bounds the drift with the fit (C, A, c, stretch) kept from
/// the step before (kept_motion, one pass over the particles: any C and A serve, the
/// residual is measured with them; mu <= max |u_i - T_last| + |T - T_last|), and runs
/// motion()'s passes, which fit afresh, only where that bound fails.
///
/// Patches (where the drift bound fails, before a whole build): nothing above needs the
/// build positions q_b to be positions the bodies had at one time; it needs only that the
/// list holds every pair nearer than R at q_b, each particle's own q_b,i. A patch moves the
/// particles whose residual |e_i| (the step's fit) is over kPatchKeep of the room
/// rho = S / 2 - mu - (1 - stretch) R / 2 to x_i = c + (I + A)^-1 (q0_i - C - c), the point
/// the fit maps to q0_i (residual 0 to round-off, measured); the others keep q_b,i and a
/// residual <= kPatchKeep rho. The list then holds every pair nearer than R at the new q_b
/// again: a pair without a moved particle keeps its distance at q_b, so its row (and its
/// build distance) stays or it stays off; a pair with a moved particle has a primitive
/// whose owner triangle has a moved corner, and all such pairs are gathered again at the
/// new q_b with the list's own radius R (a hash of the triangles with a moved corner, grown
/// by R, looked up by every triangle). The radius cannot be less: a pair of a moved
/// particle and a kept one is measured between their build positions, x_i and the kept
/// q_b,j, and the drift bound covers both from there (stretch D_b - |e_i| - |e_j|, each side
/// at most the residual); a pair left off at D_b < R would start the step nearer than the
/// bound assumes. The step goes on with the largest residual after the patch (<=
/// kPatchKeep rho, so sigma + mu <= S / 2); later steps fit A over the mixed build
/// positions as over any others, and the fit's stretch bounds them alike. A patch makes no
/// crossing check (its gather runs at q_b, not at positions the bodies had; each step's
/// bound keeps them from crossing, the whole builds check). It is refused, and the list
/// built whole, when rho is under kPatchRoom of S / 2 (the fit's stretch and the step's
/// motion take the skin), when more than kPatchMost of the particles would move (a patch
/// looks up every triangle, and each triangle with a moved corner meets all its
/// neighbours, not half: on the ball drop a patch that moves a fifth of the particles
/// costs about a quarter of a whole build), or when a moved particle is no triangle's
/// corner.
/// dt [s]: the step, for the velocities of the particles the bound held back (hold; 0: a
/// pass from rest, none changed).
/// slack [m]: a step that sweeps gathers with this slack (Stage::slack); with reuse (N, 3),
/// a second pass from the same q0 (with the same T) after one that swept with that slack
/// over the positions `reuse` (w.list[1] >= 0 and no list: its rows still in w.pairs),
/// which takes its pairs from those rows where it sweeps (reuse_swept).
inline index contacts(const Model& m, const double* q0, double* q, double* qd,
                      const ContactBuffers& w, bool translate = true, double dt = 0.0,
                      double slack = 0.0, const double* reuse = nullptr) {
    Stage st{m, q0, q, w, {0.0, 0.0, 0.0}, 1.0 / m.soft_contacts.cell_size,
             m.soft_contacts.margin, m.soft_contacts.self_contact != 0};
    // 1. the common translation, the step's largest motion after it, the list's drift (its
    // affine fit and residual when the displacements' boxes do not show it small enough)
    const bool listed = w.list[0] >= 0;
    const double h = m.soft_contacts.thickness;
    double* skin = w.list_skin;  // the list's skin S, and the steps it has served
    // with a list, the kept fit's one pass first; where its bound fails, motion()'s own
    // (its fit then kept)
    Fit fit(w);
    const double list_radius = listed ? 2.0 * h + skin[0] : 0.0;
    Motion mo;
    bool quick = false;
    if (listed && fit.set()) {
        mo = kept_motion(m, q0, q, w.q_build, fit, translate, list_radius);
        quick = mo.sigma + mo.mu <= 0.5 * skin[0];
    }
    if (!quick) mo = motion(m, q0, q, listed ? w.q_build : nullptr, false, translate, list_radius);
    st.T = mo.T;
    if (!st.self && !any_bodies_near(st)) return 0;
    // 2-3. the pairs: the list (built again when it no longer covers the step), or the
    // step's swept boxes
    const double most_skin = kMostSkin * st.g;
    index* rows = nullptr;
    index pairs = 0, active = 0;
    double radius = 0.0;
    Motion drift;  // the list's drift as the rows read see it: none for a new list
    drift.residual = 0.0;
    bool whole = true;  // the list to be built whole (or the step's pairs swept)
    if (listed && mo.sigma + mo.mu <= 0.5 * skin[0]) {
        drift = mo;
        skin[1] += 1.0;
        whole = false;
        fit.keep(mo);
    } else if (listed && 2.0 * mo.mu <= most_skin) {
        pairs = patch_list(st, mo, drift, whole);
        if (pairs < -1) return -1 - pairs;
        if (!whole) {
            skin[1] += 1.0;
            fit.keep(mo);  // the moved particles' residual 0 with it, the others' kept
        }
    }
    if (!whole) {
    } else if (2.0 * mo.mu <= most_skin) {
        // a new list at q0, its skin from the motion per step the last one saw
        double rate = mo.mu;
        if (listed) rate = std::max(rate, (mo.sigma + mo.mu) / (skin[1] + 1.0));
        const double s = std::min(most_skin, std::max(st.g, 2.0 * kServe * rate));
        pairs = build_list(st, s);
        if (pairs == -1) return -1;  // crossed at the start
        if (pairs < -1) return -1 - pairs;
    } else {
        const index earlier = listed ? -1 : w.list[1];  // an earlier pass's swept rows
        w.list[0] = -1;
        st.slack = slack;
        pairs = reuse != nullptr && earlier >= 0 ? reuse_swept(st, reuse, slack, earlier)
                                                 : gather(st);
        if (pairs == -1) return -1;
        if (pairs < -1) return -1 - pairs;
        w.list[1] = pairs;  // every row, their distances at q0
        rows = w.pairs->data;
        active = pairs;
    }
    if (w.list[0] >= 0) {
        pairs = w.list[0];
        rows = w.pairs->data;
        radius = 2.0 * h + skin[0];
        active = rows_below(rows, pairs, drift.reach(2.0 * mo.mu + h), kBands / radius);
        refresh(q0, rows, 0, active);
        w.list[1] = active;
    }
    // 4. the bound, 5. the response, its moves clipped to h / 2, and the bound again (over
    // more of the list's rows when the response moved particles); after each bound, the
    // velocities of the pairs it held back (hold)
    bound(st, active, true);
    hold(st, active, qd, dt);
    for (index p = 0; p < active; ++p)
        for (int k = 0; k < 4; ++k) {
            const index i = rows[kSlots * p + 1 + k];
            store(w.q_pre, i, load(q, i));
        }
    respond(st, active, qd);
    const double clip = 0.5 * h;
    double moved = 0.0;
    for (index p = 0; p < active; ++p)
        for (int k = 0; k < 4; ++k) {
            const index i = rows[kSlots * p + 1 + k];
            const V3 d = load(q, i) - load(w.q_pre, i);
            const double len = std::sqrt(dot(d, d));
            if (len > clip) store(q, i, load(w.q_pre, i) + (clip / len) * d);
            moved = std::max(moved, std::min(len, clip));
        }
    if (moved > 0.0 && w.list[0] >= 0) {
        const index more =
            rows_below(rows, pairs, drift.reach(2.0 * (mo.mu + moved) + h), kBands / radius);
        refresh(q0, rows, active, more);
        active = more;
        w.list[1] = active;
    }
    bound(st, active, true);
    hold(st, active, qd, dt);
    return 0;
}

}  // namespace softbody::SOFTBODY_KERNELS::thick
