// The thickness contacts (collision/thick.hpp) where a step's solve or a step's end needs
// more than the stage: read from the stage's pair list (w.pairs rows: kind, four
// particles, D; *w.list their count, -1 when there is none), never written but for building
// the list the way the stage builds it.
//
// 1. Contacts inside the implicit solve (backward Euler, BDF2: solvers/implicit.hpp). At a
//    step's start x0, each listed pair closer than h + a (a = kBand h, the activation
//    distance; the pair's gap g = sum_k c_k x_k, d = |g|, n = g / d) enters the linear system
//    as a one-sided penalty E = k / 2 (h + a - d)^2 along n (zero beyond h + a): its force
//    k (h + a - d) c_k n on particle k in the right-hand side, its Gauss-Newton Hessian
//    k (c c^T) x n n^T (PSD) in the system's product and in the preconditioner's diagonal
//    (Jacobi's scalars, the smoother's 3 x 3 blocks). The penalty's zero is a above the
//    thickness, like IPC's barrier distance d^ above 0: sheets pressed together settle in
//    the band [h, h + a), so the stage after the step (which holds h) has nothing to do at
//    rest; a quadratic penalty keeps the system linear and PSD where a log barrier would
//    need a line search and several Newton iterations per step. The stiffness follows from
//    the pair's effective mass along n, m_c = 1 / sum_k c_k^2 / m_k, and the step h_s:
//    k = kStiffness m_c / h_s^2, so an isolated pair's approach over one step is cut to
//    1 / (1 + kStiffness) of its free value and a pair pushed into the band is taken back
//    kStiffness / (1 + kStiffness) of the way in one step: with kStiffness = 4 an approach
//    of up to 5 a = 2.5 h per step ends in the band, above h, without the stage (8 and 16
//    left the stage less still on a ball resting on a cloth, for 20-50 % more CG
//    iterations on the vacuum-packed ball). The system is the penalty's linearisation at
//    x0, as every term's: a pair that opens past h + a within the step is held by
//    k (d - h - a) in that step only (the next step's set leaves it out). The stage after
//    the step still runs (bound, response): the no-crossing guarantee is its, unchanged.
//    Pairs come from the stage's list, valid at x0 or built there (it holds every pair
//    nearer than 2 h, so a <= h). The coefficients c sum to 0 (the
//    gap's barycentric weights), so the forces, and the Hessian's products, come in equal
//    and opposite shares: momentum is conserved; their torque about any point is
//    sum_k c_k x0_k x n (...) = d n x n (...) = 0 at x0, so within a body they need no turn
//    (implicit_solver::keep_own_torque takes them as forces from outside a body, where
//    between bodies they are).
// 2. Crossings caused by colliders: the rigid colliders act after the thickness stage and
//    may push one sheet through another. collider_crossing() looks, for the listed
//    vertex-triangle pairs touching a particle the colliders moved, whether an edge of the
//    pair's vertex (its ring of face neighbours) now passes through the pair's triangle; a
//    step without a list builds one at its end, with the list's full crossing check.
#pragma once

#include <vector>

#include "collision/thick.hpp"
#include "model.hpp"
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
    index count = 0;
    void clear() {
        v.clear();
        c.clear();
        n.clear();
        k.clear();
        push.clear();
        count = 0;
    }
};

/// Whether the model has thickness contacts.
inline bool enabled(const Model& m) {
    return m.soft_contacts.mode == SoftContactMode::SURFACE && m.soft_contacts.thickness > 0.0;
}

/// The stage's pair list valid at q0 (N, 3): kept when the particles have drifted by at most
/// half the margin since it was built (it then holds every pair nearer than 2 h at q0), else
/// built at q0 as thick::contacts builds it. False when there is none: no pairs can be near
/// (bodies apart, no self-contact), or the build found a crossing or could not grow its
/// buffers (the stage after the step finds that again and stops the run).
inline bool ensure_list(const Model& m, double* q0, const ContactBuffers& w) {
    const double h = m.soft_contacts.thickness, g = m.soft_contacts.margin;
    if (*w.list >= 0 && thick::drift(m, q0, w.q_build) <= 0.5 * g) return true;
    thick::Stage list{m, q0, q0, w, {0.0, 0.0, 0.0}, 1.0 / m.soft_contacts.cell_size,
                      g, m.soft_contacts.self_contact != 0};
    list.swept = false;
    if (!list.self && !thick::any_bodies_near(list)) return false;
    list.g = 2.0 * h + g;
    list.keep = list.g;
    *w.list = -1;
    const index pairs = thick::gather(list);
    if (pairs < 0) return false;
    const index n3 = 3 * m.particles.count;
    for (index k = 0; k < n3; ++k) w.q_build[k] = q0[k];
    *w.list = pairs;
    return true;
}

/// The active pairs at the step's start q0 (N, 3) for the solve's step h_s [s] into sys
/// (emptied first).
inline void begin(const Model& m, double* q0, const ContactBuffers& w, double h_s, System& sys) {
    sys.clear();
    if (!enabled(m) || !ensure_list(m, q0, w)) return;
    const double h = m.soft_contacts.thickness, reach = (1.0 + kBand) * h;
    const double* inv_mass = m.particles.inv_mass;
    for (index p = 0; p < *w.list; ++p) {
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
}

inline V3 normal(const System& sys, index p) {
    return {sys.n[3 * p], sys.n[3 * p + 1], sys.n[3 * p + 2]};
}

/// f (N, 3) += the pairs' forces at x0 [N].
inline void add_forces(const System& sys, double* f) {
    for (index p = 0; p < sys.count; ++p) {
        const V3 n = normal(sys, p);
        for (int l = 0; l < 4; ++l) add_to(f, sys.v[4 * p + l], (sys.push[p] * sys.c[4 * p + l]) * n);
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

/// Whether particle i is at another place in q than in before (both (N, 3)).
inline bool moved(const double* q, const double* before, index i) {
    return q[3 * i] != before[3 * i] || q[3 * i + 1] != before[3 * i + 1] ||
           q[3 * i + 2] != before[3 * i + 2];
}

/// Calls edge(j) for each face neighbour j of particle i (its ring, and the faces off it).
template <class Edge>
inline void each_neighbour(const Model& m, index i, Edge edge) {
    constexpr index kGroup = 8;
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

/// After the colliders moved particles from before (N, 3) to q (N, 3): whether an edge now
/// passes through a triangle. With the stage's list kept, for the listed vertex-triangle
/// pairs with a particle the colliders moved (the vertex i, a neighbour j, a corner):
/// whether an edge (i, j) of the pair's vertex passes through the pair's triangle (a pass
/// over the list). Without it (the step took its pairs from swept boxes: its own motion
/// was over half the margin) the list is built at q as the stage builds it, with its check
/// of every edge against the triangles near it; the next step starts from it. Writes where
/// into w.crossing: the edge's particle, and -1 - the triangle (a crossing the colliders
/// made, which contact_failure's caller names as such).
inline bool collider_crossing(const Model& m, double* q, const double* before,
                              const ContactBuffers& w) {
    const index n = m.particles.count;
    bool any = false;
    for (index i = 0; i < n && !any; ++i) any = moved(q, before, i);
    if (!any) return false;
    if (*w.list < 0) {
        thick::Stage list{m, q, q, w, {0.0, 0.0, 0.0}, 1.0 / m.soft_contacts.cell_size,
                          2.0 * m.soft_contacts.thickness + m.soft_contacts.margin,
                          m.soft_contacts.self_contact != 0};
        list.swept = false;
        list.keep = list.g;
        const index pairs = thick::gather(list);
        if (pairs == -1) {
            w.crossing[1] = -1 - w.crossing[1];
            return true;
        }
        if (pairs < -1) return false;  // no room: the next step's stage says so
        for (index k = 0; k < 3 * n; ++k) w.q_build[k] = q[k];
        *w.list = pairs;
        return false;
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
