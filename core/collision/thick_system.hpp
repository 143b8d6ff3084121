// The thickness contacts (collision/thick.hpp) where a step's solve or a step's end needs
// more than the stage: read from the stage's pair list (w.pairs rows: kind, four
// particles, D; *w.list their count, -1 when there is none), never written but for building
// the list the way the stage builds it, or, where the stage will not keep a list this
// step, for gathering the pairs near at the step's start into its rows.
//
// 1. Contacts inside the implicit solve (backward Euler, BDF2: solvers/implicit.hpp). At a
//    step's start x0, each listed pair closer than h + a (a = kBand h, the activation
//    distance; the pair's gap g = sum_k c_k x_k, d = |g|, n = g / d) enters the linear system
//    as a one-sided penalty E = k / 2 (h + a - d)^2 along n (zero beyond h + a): its force
//    k (h + a - d) c_k n on particle k in the right-hand side, its Gauss-Newton Hessian
//    k (c c^T) x n n^T (PSD) in the system's product and in the preconditioner (Jacobi's
//    diagonal; the smoother's diagonal blocks, and its blocks between a pair's particles in
//    the Gauss-Seidel sweeps). The penalty's zero is a above the
//    thickness, like IPC's barrier distance d^ above 0: sheets pressed together settle in
//    the band [h, h + a), so the stage after the step (which holds h) has nothing to do at
//    rest; a quadratic penalty keeps the system linear and PSD where a log barrier would
//    need a line search and several Newton iterations per step. The stiffness follows from
//    the pair's effective mass along n, m_c = 1 / sum_k c_k^2 / m_k, and the step h_s:
//    k = kStiffness m_c / h_s^2, so an isolated pair's approach over one step is cut to
//    1 / (1 + kStiffness) of its free value and a pair pushed into the band is taken back
//    kStiffness / (1 + kStiffness) of the way in one step: with kStiffness = 4 an approach
//    of up to 5 a = 2.5 h per step ends in the band, above h, without the stage (8 and 16
//    left the stage less still on a ball resting on a cloth but, measured with the
//    smoother's diagonal blocks alone, cost the vacuum-packed ball 20-50 % more CG
//    iterations than 4). The system is the penalty's linearisation at
//    x0, as every term's: a pair that opens past h + a within the step is held by
//    k (d - h - a) in that step only (the next step's set leaves it out). The stage after
//    the step still runs (bound, response): the no-crossing guarantee is its, unchanged.
//    Pairs come from the stage's list, valid at x0 or built there (it holds every pair
//    nearer than 2 h, so a <= h), or, in a step whose forecast motion will make the stage
//    sweep, from a gather of the pairs nearer than h + a. The coefficients c sum to 0 (the
//    gap's barycentric weights), so the forces, and the Hessian's products, come in equal
//    and opposite shares: momentum is conserved; their torque about any point is
//    sum_k c_k x0_k x n (...) = d n x n (...) = 0 at x0, so within a body they need no turn
//    (implicit_solver::keep_own_torque takes them as forces from outside a body, where
//    between bodies they are).
//    Projective dynamics cannot put the penalty into its prefactored matrix: each_near()
//    hands it the same pairs (nearer than 2 h there), which its iterations take
//    explicitly, with multipliers (solvers/projective.hpp).
// 2. Crossings caused by colliders: the stage cannot hold back a particle a rigid collider
//    caught and carried farther than its pairs' distances allow, nor see the colliders'
//    last push (loop::thick_with_colliders runs the stage around them). collider_crossing()
//    looks, for the listed vertex-triangle pairs touching a particle that moved in the
//    contacts, whether an edge of the pair's vertex (its ring of face neighbours) now
//    passes through the pair's triangle; in a step without a list, the gather's crossing
//    check over the triangles with a corner that moved.
#pragma once

#include <vector>

#include "collision/thick.hpp"
#include "model.hpp"
#include "simd.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::thick_system {

constexpr double kBand = 0.5;       // the activation distance a over the thickness h
constexpr double kStiffness = 4.0;  // h_s^2 k / m_c, each pair's stiffness over its mass

/// The active pairs of a step (P of them), kept between steps (the vectors keep their room).
struct System {
    std::vector<index> v;      // (P, 4) particles
    std::vector<double> c;     // (P, 4) the gap's coefficients
    std::vector<double> n;     // (P, 3) the gap's direction at x0
    std::vector<double> k;     // (P,) stiffness [N/m]
    std::vector<double> push;  // (P,) the force at x0, k (h + a - d) [N]
    // the smoother's blocks between the pairs' particles, by particle, one per pair of
    // particles (i, j) that share a pair: particle i's are [row[i], row[i + 1]), those to
    // j < i before mid[i], those to j > i from it; col names j, block (3, 3) is
    // sum h_s^2 k c_i c_j n n^T over the pairs that hold both (the system matrix's block is
    // its negative)
    std::vector<index> row, mid, col;
    std::vector<double> block;
    // their making: each pair's twelve entries (i, j) by particle i (ptr: the counting sort's
    // starts; other: j; pair: 16 x the pair + 4 x i's place in it + j's), and each
    // particle's last row and block (tag, slot)
    std::vector<index> ptr, other, pair, tag, slot;
    index count = 0;
    void clear() {
        v.clear();
        c.clear();
        n.clear();
        k.clear();
        push.clear();
        ptr.clear();
        other.clear();
        pair.clear();
        row.clear();
        mid.clear();
        col.clear();
        block.clear();
        count = 0;
    }
};

/// Whether the model has thickness contacts.
inline bool enabled(const Model& m) {
    return m.soft_contacts.mode == SoftContactMode::SURFACE && m.soft_contacts.thickness > 0.0;
}

/// The largest displacement over a step dt [s] at the velocities v0 (N, 3) [m/s], after
/// the bodies' free particles' mass-weighted mean velocity: a forecast of the motion the
/// stage measures (its mu) before the solve has made it.
inline double forecast_motion(const Model& m, const double* v0, double dt) {
    double mass = 0.0;
    V3 sum{0.0, 0.0, 0.0};
    for (index i = 0; i < m.particles.count; ++i) {
        if (m.particles.inv_mass[i] == 0.0 || m.particles.body[i] < 0) continue;
        mass += m.particles.mass[i];
        sum = sum + m.particles.mass[i] * load(v0, i);
    }
    const V3 mean = mass > 0.0 ? (1.0 / mass) * sum : V3{0.0, 0.0, 0.0};
    double most = 0.0;
    for (index i = 0; i < m.particles.count; ++i) {
        if (m.particles.body[i] < 0) continue;
        const V3 u = load(v0, i) - mean;
        most = std::max(most, dot(u, u));
    }
    return dt * std::sqrt(most);
}

/// The pairs nearer than `reach` (<= 2 h) at q0 (N, 3) in w.pairs' first rows; returns
/// their count (rows beyond those nearer may follow: begin() filters). The stage's list
/// when it is valid at q0 (the particles drifted by at most half its skin since it was
/// built: it then holds every pair nearer than 2 h). Otherwise, when the step's forecast
/// motion (v0 (N, 3) over dt) is within half the margin, so that the stage will keep a
/// list, the list is built at q0 as the stage builds it, and the stage then uses it; when
/// the step will take its pairs from swept boxes, only the pairs nearer than reach are
/// gathered, the list left dropped, without the crossing check (the stage's gather at the
/// same q0, swept or a list's, checks it). 0 when none can be near (bodies apart, no
/// self-contact), or when the gather found a crossing at q0 or could not grow its buffers
/// (the stage after the step finds that again and stops the run).
inline index near_pairs(const Model& m, double* q0, const double* v0, double dt,
                        const ContactBuffers& w, double reach) {
    const double h = m.soft_contacts.thickness, g = m.soft_contacts.margin;
    if (*w.list >= 0 && thick::motion(m, q0, q0, w.q_build, true, true,
                                      2.0 * h + w.list_skin[0]).sigma <= 0.5 * w.list_skin[0])
        return *w.list;
    thick::Stage st{m, q0, q0, w, {0.0, 0.0, 0.0}, 1.0 / m.soft_contacts.cell_size,
                    g, m.soft_contacts.self_contact != 0};
    st.swept = false;
    if (!st.self && !thick::any_bodies_near(st)) return 0;
    *w.list = -1;
    if (forecast_motion(m, v0, dt) > 0.5 * g) {  // the stage will sweep: the near pairs only
        st.g = reach;
        st.keep = reach;
        st.check = false;
        return std::max<index>(thick::gather(st), 0);
    }
    return std::max<index>(thick::build_list(st, g), 0);
}

/// The active pairs at the step's start q0, v0 (N, 3) for a step dt [s] whose system has
/// the step h_s [s] (dt, or 2/3 dt for BDF2), into sys (emptied first).
inline void begin(const Model& m, double* q0, const double* v0, double dt, const ContactBuffers& w,
                  double h_s, System& sys) {
    sys.clear();
    if (!enabled(m)) return;
    const double h = m.soft_contacts.thickness, reach = (1.0 + kBand) * h;
    const index listed = near_pairs(m, q0, v0, dt, w, reach);
    const double* inv_mass = m.particles.inv_mass;
    for (index p = 0; p < listed; ++p) {
        const index* row = w.pairs->data + thick::kSlots * p;
        const index* v = row + 1;
        double c[4];
        const V3 g = thick::gap(q0, row[0], v, c);
        const double d = std::sqrt(dot(g, g));
        if (!(d < reach) || !(d > 1e-9 * h)) continue;  // inactive, or no direction
        double weight = 0.0;
        for (int k = 0; k < 4; ++k) weight += c[k] * c[k] * inv_mass[v[k]];
        if (!(weight > 0.0)) continue;  // all pinned
        const double k = kStiffness / (weight * h_s * h_s);
        for (int l = 0; l < 4; ++l) {
            sys.v.push_back(v[l]);
            sys.c.push_back(c[l]);
        }
        sys.n.push_back(g.x / d);
        sys.n.push_back(g.y / d);
        sys.n.push_back(g.z / d);
        sys.k.push_back(k);
        sys.push.push_back(k * (reach - d));
        ++sys.count;
    }
    if (sys.count == 0) return;
    // the blocks between the pairs' particles: each pair's entries by particle (a counting
    // sort), then each particle's entries to one other particle summed into one block (a
    // crumpled sheet's particle shares a pair with another in several pairs: the smoother's
    // three sweeps a CG iteration read each block once, not each entry), those to earlier
    // particles first
    auto at = [](index k) { return static_cast<size_t>(k); };
    const index n = m.particles.count, entries = 12 * sys.count;
    sys.ptr.assign(at(n + 1), 0);
    for (index p = 0; p < sys.count; ++p)
        for (int l = 0; l < 4; ++l) sys.ptr[at(sys.v[4 * p + l] + 1)] += 3;
    for (index i = 0; i < n; ++i) sys.ptr[at(i + 1)] += sys.ptr[at(i)];
    sys.other.resize(at(entries));
    sys.pair.resize(at(entries));
    for (index p = 0; p < sys.count; ++p)
        for (int l = 0; l < 4; ++l)
            for (int o = 0; o < 4; ++o) {
                if (o == l) continue;
                const size_t e = at(sys.ptr[at(sys.v[4 * p + l])]++);
                sys.other[e] = sys.v[4 * p + o];
                sys.pair[e] = 16 * p + 4 * l + o;  // the pair, i's place in it and j's
            }
    for (index i = n; i > 0; --i) sys.ptr[at(i)] = sys.ptr[at(i - 1)];  // back to the starts
    sys.ptr[0] = 0;
    sys.row.resize(at(n + 1));
    sys.mid.resize(at(n));
    sys.col.clear();
    sys.block.clear();
    sys.tag.assign(at(n), -1);
    sys.slot.resize(at(n));
    index blocks = 0;
    for (index i = 0; i < n; ++i) {
        sys.row[at(i)] = blocks;
        for (int later = 0; later < 2; ++later) {
            for (index e = sys.ptr[at(i)]; e < sys.ptr[at(i + 1)]; ++e) {
                const index j = sys.other[at(e)];
                if ((j > i) != (later != 0)) continue;
                if (sys.tag[at(j)] != i) {
                    sys.tag[at(j)] = i;
                    sys.slot[at(j)] = blocks++;
                    sys.col.push_back(j);
                    sys.block.resize(sys.block.size() + 9, 0.0);
                }
                const index code = sys.pair[at(e)], p = code >> 4;  // (shifts: code >= 0)
                const double* u = sys.n.data() + 3 * p;
                const double weight = h_s * h_s * sys.k[at(p)] *
                                      sys.c[at(4 * p + ((code >> 2) & 3))] *
                                      sys.c[at(4 * p + (code & 3))];
                double* b = sys.block.data() + 9 * sys.slot[at(j)];
                for (int r = 0; r < 3; ++r)
                    for (int k = 0; k < 3; ++k) b[3 * r + k] += weight * u[r] * u[k];
            }
            if (later == 0) sys.mid[at(i)] = blocks;
        }
    }
    sys.row[at(n)] = blocks;
}

/// Calls pair(kind, v, c, g, d) for each pair nearer than reach (<= 2 h) at q0 (N, 3), for
/// a step dt [s] from the velocities v0 (N, 3): its kind (thick::kVertexTriangle or
/// kEdgeEdge), its four particles v, the gap's coefficients c (four, sum 0), the gap g at
/// q0 and its length d > 0. The pairs as begin() takes them (near_pairs), for projective
/// dynamics' iterations (solvers/projective.hpp).
template <class Pair>
inline void each_near(const Model& m, double* q0, const double* v0, double dt,
                      const ContactBuffers& w, double reach, Pair pair) {
    if (!enabled(m)) return;
    const double h = m.soft_contacts.thickness;
    const index listed = near_pairs(m, q0, v0, dt, w, reach);
    for (index p = 0; p < listed; ++p) {
        const index* row = w.pairs->data + thick::kSlots * p;
        double c[4];
        const V3 g = thick::gap(q0, row[0], row + 1, c);
        const double d = std::sqrt(dot(g, g));
        if (!(d < reach) || !(d > 1e-9 * h)) continue;  // inactive, or no direction
        pair(row[0], row + 1, c, g, d);
    }
}

inline V3 normal(const System& sys, index p) {
    return {sys.n[3 * p], sys.n[3 * p + 1], sys.n[3 * p + 2]};
}

/// f (N, 3) += the pairs' forces at x0 [N].
inline void add_forces(const System& sys, double* f) {
    for (index p = 0; p < sys.count; ++p) {
        const V3 n = normal(sys, p);
        for (int l = 0; l < 4; ++l)
            add_to(f, sys.v[4 * p + l], (sys.push[p] * sys.c[4 * p + l]) * n);
    }
}

/// out (N, 3) += alpha K p for p (N, 3), K = -k (c c^T) x n n^T the pairs' stiffness.
inline void add_product(const System& sys, double alpha, const double* p, double* out) {
    for (index q = 0; q < sys.count; ++q) {
        const V3 n = normal(sys, q);
        double s = 0.0;
        for (int l = 0; l < 4; ++l) s += sys.c[4 * q + l] * dot(n, load(p, sys.v[4 * q + l]));
        const double a = -alpha * sys.k[q] * s;
        for (int l = 0; l < 4; ++l) add_to(out, sys.v[4 * q + l], (a * sys.c[4 * q + l]) * n);
    }
}

/// Jacobi's diagonal diag (N,) [kg] += h_s^2 k c_k^2 (the trace of each particle's block).
inline void add_diagonal(const System& sys, double h_s, double* diag) {
    for (index q = 0; q < sys.count; ++q)
        for (int l = 0; l < 4; ++l) {
            const double c = sys.c[4 * q + l];
            diag[sys.v[4 * q + l]] += h_s * h_s * sys.k[q] * c * c;
        }
}

/// The smoother's diagonal blocks block (N, 3, 3) += h_s^2 k c_k^2 n n^T.
inline void add_blocks(const System& sys, double h_s, double* block) {
    for (index q = 0; q < sys.count; ++q) {
        const double* n = sys.n.data() + 3 * q;
        for (int l = 0; l < 4; ++l) {
            const double c = sys.c[4 * q + l];
            const double s = h_s * h_s * sys.k[q] * c * c;
            double* b = block + 9 * sys.v[4 * q + l];
            for (int r = 0; r < 3; ++r)
                for (int k = 0; k < 3; ++k) b[3 * r + k] += s * n[r] * n[k];
        }
    }
}

/// s -= the system matrix's blocks between particle i and the other particles of its pairs
/// times x (N, 3): those to particles j < i (kSide -1), j > i (+1), or all (0), as the
/// smoother's sweeps take the terms' stencils (implicit_solver::precondition).
template <int kSide>
inline void add_entries(const System& sys, const double* x, index i, V3& s) {
    if (sys.count == 0) return;
    const size_t at = static_cast<size_t>(i);
    const index first = kSide > 0 ? sys.mid[at] : sys.row[at];
    const index last = kSide < 0 ? sys.mid[at] : sys.row[at + 1];
    for (index e = first; e < last; ++e) {
        const V3 y = load(x, sys.col[static_cast<size_t>(e)]);
        const double* b = sys.block.data() + 9 * e;
        s = s - V3{b[0] * y.x + b[1] * y.y + b[2] * y.z, b[3] * y.x + b[4] * y.y + b[5] * y.z,
                   b[6] * y.x + b[7] * y.y + b[8] * y.z};
    }
}

/// Whether particle i is at another place in q than in before (both (N, 3)).
inline bool moved(const double* q, const double* before, index i) {
    return q[3 * i] != before[3 * i] || q[3 * i + 1] != before[3 * i + 1] ||
           q[3 * i + 2] != before[3 * i + 2];
}

/// Calls edge(j) for each face neighbour j of particle i (its ring, and the faces off it).
template <class Edge>
inline void each_neighbour(const Model& m, index i, Edge edge) {
    const Slots& s = m.slots;
    const index g = i / kGroup, lane = i % kGroup;
    for (index k = s.ring_start[g]; k < s.ring_start[g + 1]; ++k) {
        const index j = s.ring_other[kGroup * k + lane];
        if (j != i) edge(j);  // padding repeats j_0 (tested twice) or names i itself
    }
    if (s.face_start == nullptr) return;
    for (index k = s.face_start[g]; k < s.face_start[g + 1]; ++k) {
        const index a = s.face_next[kGroup * k + lane], b = s.face_last[kGroup * k + lane];
        if (a != i) edge(a);
        if (b != i) edge(b);
    }
}

/// The triangle with corners (a, b, d) in that order, or -1.
inline index find_triangle(const Model& m, const index* corners) {
    for (index t = 0; t < m.triangles.count; ++t) {
        const index* tri = m.triangles.indices + 3 * t;
        if (tri[0] == corners[0] && tri[1] == corners[1] && tri[2] == corners[2]) return t;
    }
    return -1;
}

/// After the contacts moved particles from before (N, 3) (the solver's positions) to q
/// (N, 3): whether an edge now passes through a triangle. With the stage's list kept, for
/// the listed vertex-triangle pairs with a particle that moved (the vertex i, a neighbour
/// j, a corner):
/// whether an edge (i, j) of the pair's vertex passes through the pair's triangle (a pass
/// over the list). Without it (the step took its pairs from swept boxes: its own motion
/// was over half the margin) the gather's crossing check at q over the pairs of triangles
/// with a corner that moved (a patch, thick::Stage::check_patch: the hash of those
/// triangles, looked up by every triangle, each pair of triangles whose boxes at q meet
/// with a moved one tested both ways, every owned edge of each through the other). That
/// finds every crossing at q with a moved particle at an end of the edge or a corner of
/// the triangle; one among particles the contacts left where the solver put them is none
/// the contacts made (the stage's bound kept them apart along the step from a start its
/// gather checked). No list is built (the next step's near_pairs gathers what it needs).
/// Writes where into w.crossing: the edge's particle, and -1 - the triangle (a crossing the
/// colliders made, which contact_failure's caller names as such).
inline bool collider_crossing(const Model& m, double* q, const double* before,
                              const ContactBuffers& w) {
    const index n = m.particles.count;
    bool any = false;
    for (index i = 0; i < n && !any; ++i) any = moved(q, before, i);
    if (!any) return false;
    if (*w.list < 0) {
        thick::Stage at{m, q, q, w, {0.0, 0.0, 0.0}, 1.0 / m.soft_contacts.cell_size,
                        0.0, m.soft_contacts.self_contact != 0};
        at.swept = false;
        at.keep = 0.0;  // no pair kept: the check alone (boxes not grown: g = 0)
        double* flag = w.held;  // its first slot per particle (the stage's scratch, done)
        for (index i = 0; i < n; ++i) flag[8 * i] = moved(q, before, i) ? 1.0 : 0.0;
        at.moved = flag;
        at.check_patch = true;
        if (thick::gather(at) == -1) {
            w.crossing[1] = -1 - w.crossing[1];
            return true;
        }
        return false;  // none; or no room: the next step's stage says so
    }
    if (m.slots.ring_start == nullptr) return false;
    for (index p = 0; p < *w.list; ++p) {
        const index* row = w.pairs->data + thick::kSlots * p;
        if (row[0] != thick::kVertexTriangle) continue;
        const index i = row[1], *tri = row + 2;
        const bool corner = moved(q, before, i) || moved(q, before, tri[0]) ||
                            moved(q, before, tri[1]) || moved(q, before, tri[2]);
        bool crossed = false;
        each_neighbour(m, i, [&](index j) {
            if (crossed || j == tri[0] || j == tri[1] || j == tri[2]) return;  // touches it
            if (!corner && !moved(q, before, j)) return;
            crossed = thick::segment_crosses(load(q, i), load(q, j), load(q, tri[0]),
                                             load(q, tri[1]), load(q, tri[2]));
        });
        if (crossed) {
            w.crossing[0] = i;
            w.crossing[1] = -1 - find_triangle(m, tri);
            return true;
        }
    }
    return false;
}

}  // namespace softbody::SOFTBODY_KERNELS::thick_system
