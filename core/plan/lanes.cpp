// The vertex-major tables (plan/lanes.hpp).
#include "plan/lanes.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>

namespace softbody {

// A particle's faces (i, j, k) as directed pairs j -> k, in fan order: a closed fan is
// one cycle, a fan on an open surface's border one path (begun at its free end). False
// when they make neither (two fans meeting at a vertex), and the particle's faces go to
// the plain face slots instead. `ring` gets j_0, j_1, ...; `closed` says which.
bool VertexLayout::fan_order(const std::vector<std::pair<index, index>>& pairs,
                         std::vector<index>& ring, bool& closed) {
    ring.clear();
    closed = false;
    if (pairs.empty()) return true;
    // sorted by their first end (O(F log F) for a fan of F faces, however large)
    std::vector<std::pair<index, index>> by_first(pairs), by_second;
    std::sort(by_first.begin(), by_first.end());
    for (const auto& [j, k] : pairs) by_second.push_back({k, j});
    std::sort(by_second.begin(), by_second.end());
    for (size_t a = 0; a < by_first.size(); ++a) {
        if (by_first[a].first == by_first[a].second) return false;
        if (a > 0 && (by_first[a].first == by_first[a - 1].first ||
                      by_second[a].first == by_second[a - 1].first))
            return false;  // two faces leave (or reach) one neighbour: not one fan
    }
    auto next_of = [&](index j) -> index {
        auto it = std::lower_bound(by_first.begin(), by_first.end(),
                                   std::pair<index, index>{j, std::numeric_limits<index>::min()});
        return it != by_first.end() && it->first == j ? it->second : -1;
    };
    auto has_incoming = [&](index j) {
        auto it = std::lower_bound(by_second.begin(), by_second.end(),
                                   std::pair<index, index>{j, std::numeric_limits<index>::min()});
        return it != by_second.end() && it->first == j;
    };
    index start = pairs[0].first;  // a closed fan: from its first face
    for (const auto& [j, k] : pairs)
        if (!has_incoming(j)) {
            start = j;  // an open fan: from its free end
            break;
        }
    index at = start;
    ring.push_back(at);
    for (size_t step = 0; step < pairs.size(); ++step) {
        const index next = next_of(at);
        if (next < 0) return false;
        if (next == start) {
            closed = step + 1 == pairs.size();
            return closed;
        }
        ring.push_back(next);
        at = next;
    }
    return ring.size() == pairs.size() + 1;  // an open fan: one node more than faces
}

// The vertex-major tables (model.hpp): for each group of 8 particles, as many slots as
// its busiest particle needs; every particle's own entries in order.
void VertexLayout::build(Model& m) {
    const index n = m.particles.count, groups = (n + kGroup - 1) / kGroup;
    const size_t lanes = static_cast<size_t>(kGroup * groups);
    m.slots.group_count = groups;
    lane_mass_.assign(lanes, 0.0);
    std::copy(m.particles.mass, m.particles.mass + n, lane_mass_.begin());
    lane_reference_.resize(lanes);
    for (size_t i = 0; i < lanes; ++i) lane_reference_[i] = static_cast<index>(i);
    for (index b = 0; b < m.bodies.count; ++b)
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1]; ++i)
            lane_reference_[static_cast<size_t>(i)] = m.bodies.particle_range[2 * b];
    m.slots.mass = lane_mass_.data();
    m.slots.reference = lane_reference_.data();

    // each particle's springs (other end, spring) and faces (j, k), in model order
    std::vector<std::vector<std::pair<index, index>>> springs(static_cast<size_t>(n)),
        faces(static_cast<size_t>(n));
    for (index s = 0; s < m.springs.count; ++s) {
        const index i = m.springs.indices[2 * s], j = m.springs.indices[2 * s + 1];
        springs[static_cast<size_t>(i)].push_back({j, s});
        springs[static_cast<size_t>(j)].push_back({i, s});
    }
    for (index t = 0; t < m.triangles.count; ++t)
        for (int c = 0; c < 3; ++c)
            faces[static_cast<size_t>(m.triangles.indices[3 * t + c])].push_back(
                {m.triangles.indices[3 * t + (c + 1) % 3], m.triangles.indices[3 * t + (c + 2) % 3]});

    // per particle: its ring (neighbour, spring or -1, face weight), its other springs
    // and the faces of a broken fan
    struct Ring {
        std::vector<index> other, spring;
        std::vector<double> face;
    };
    std::vector<Ring> rings(static_cast<size_t>(n));
    std::vector<std::vector<std::pair<index, index>>> extra_springs(static_cast<size_t>(n)),
        extra_faces(static_cast<size_t>(n));
    std::vector<index> order;
    for (index i = 0; i < n; ++i) {
        const size_t own = static_cast<size_t>(i);
        bool closed = false;
        std::vector<char> used(springs[own].size(), 0);
        if (!fan_order(faces[own], order, closed)) {
            extra_faces[own] = faces[own];
            order.clear();
        }
        Ring& r = rings[own];
        // the particle's springs sorted by other end (then spring): the ring takes the
        // first spring to each neighbour, the rest stay extra springs
        std::vector<std::pair<index, index>>& mine = springs[own];
        std::sort(mine.begin(), mine.end());
        for (size_t s = 0; s < order.size(); ++s) {
            index spring = -1;
            auto it = std::lower_bound(mine.begin(), mine.end(),
                                       std::pair<index, index>{order[s], std::numeric_limits<index>::min()});
            for (; it != mine.end() && it->first == order[s]; ++it) {
                const size_t k = static_cast<size_t>(it - mine.begin());
                if (!used[k]) {
                    used[k] = 1;
                    spring = it->second;
                    break;
                }
            }
            r.other.push_back(order[s]);
            r.spring.push_back(spring);
            r.face.push_back(s > 0 || closed ? 1.0 : 0.0);  // slot 0: the closing face
        }
        for (size_t k = 0; k < springs[own].size(); ++k)
            if (!used[k]) extra_springs[own].push_back(springs[own][k]);
    }

    auto starts = [&](auto count, std::vector<index>& start) {
        start.assign(static_cast<size_t>(groups + 1), 0);
        for (index g = 0; g < groups; ++g) {
            size_t most = 0;
            for (index i = kGroup * g; i < std::min(n, kGroup * (g + 1)); ++i)
                most = std::max(most, count(static_cast<size_t>(i)));
            start[static_cast<size_t>(g + 1)] = start[static_cast<size_t>(g)] + static_cast<index>(most);
        }
        return static_cast<size_t>(kGroup * start.back());
    };
    const size_t ring_entries = starts([&](size_t i) { return rings[i].other.size(); }, ring_start_);
    const size_t spring_entries = starts([&](size_t i) { return extra_springs[i].size(); }, spring_start_);
    const size_t face_entries = starts([&](size_t i) { return extra_faces[i].size(); }, face_start_);
    ring_other_.assign(ring_entries, 0);
    ring_rest_.assign(ring_entries, 0.0);
    ring_k_.assign(ring_entries, 0.0);
    ring_c_.assign(ring_entries, 0.0);
    ring_face_.assign(ring_entries, 0.0);
    spring_other_.assign(spring_entries, 0);
    spring_rest_.assign(spring_entries, 0.0);
    spring_k_.assign(spring_entries, 0.0);
    spring_c_.assign(spring_entries, 0.0);
    face_next_.assign(face_entries, 0);
    face_last_.assign(face_entries, 0);
    for (index g = 0; g < groups; ++g)
        for (index l = 0; l < kGroup; ++l) {
            const index i = kGroup * g + l;  // padding lanes (i >= N) list nothing
            const bool real = i < n;
            const size_t own = static_cast<size_t>(i);
            const index r0 = ring_start_[static_cast<size_t>(g)];
            for (index s = r0; s < ring_start_[static_cast<size_t>(g + 1)]; ++s) {
                const size_t e = static_cast<size_t>(kGroup * s + l), k = static_cast<size_t>(s - r0);
                const bool listed = real && k < rings[own].other.size();
                // padding repeats j_0 (no spring; its faces (j_0, j_0) have no area), or
                // the particle itself when it has no ring
                const bool has_ring = real && !rings[own].other.empty();
                ring_other_[e] = listed ? rings[own].other[k] : has_ring ? rings[own].other[0] : i;
                if (!listed) {
                    // a closed ring padded with j_0: its first padding slot closes it
                    const bool closes = has_ring && k == rings[own].other.size() &&
                                        rings[own].face[0] == 1.0;
                    ring_face_[e] = closes ? 1.0 : 0.0;
                    continue;
                }
                ring_face_[e] = rings[own].face[k];
                const index spring = rings[own].spring[k];
                if (spring >= 0) {
                    ring_rest_[e] = m.springs.rest_length[spring];
                    ring_k_[e] = m.springs.stiffness[spring];
                    ring_c_[e] = m.springs.damping[spring];
                }
            }
            const index s0 = spring_start_[static_cast<size_t>(g)];
            for (index s = s0; s < spring_start_[static_cast<size_t>(g + 1)]; ++s) {
                const size_t e = static_cast<size_t>(kGroup * s + l), k = static_cast<size_t>(s - s0);
                spring_other_[e] = i;  // padding: itself, no stiffness
                if (real && k < extra_springs[own].size()) {
                    const auto [other, spring] = extra_springs[own][k];
                    spring_other_[e] = other;
                    spring_rest_[e] = m.springs.rest_length[spring];
                    spring_k_[e] = m.springs.stiffness[spring];
                    spring_c_[e] = m.springs.damping[spring];
                }
            }
            const index f0 = face_start_[static_cast<size_t>(g)];
            for (index s = f0; s < face_start_[static_cast<size_t>(g + 1)]; ++s) {
                const size_t e = static_cast<size_t>(kGroup * s + l), k = static_cast<size_t>(s - f0);
                face_next_[e] = face_last_[e] = i;  // padding: a face of no area
                if (real && k < extra_faces[own].size()) {
                    face_next_[e] = extra_faces[own][k].first;
                    face_last_[e] = extra_faces[own][k].second;
                }
            }
        }
    m.slots.ring_start = ring_start_.data();
    m.slots.ring_other = ring_other_.data();
    m.slots.ring_rest_length = ring_rest_.data();
    m.slots.ring_stiffness = ring_k_.data();
    m.slots.ring_damping = ring_c_.data();
    m.slots.ring_face = ring_face_.data();
    m.slots.spring_start = spring_start_.data();
    m.slots.spring_other = spring_other_.data();
    m.slots.spring_rest_length = spring_rest_.data();
    m.slots.spring_stiffness = spring_k_.data();
    m.slots.spring_damping = spring_c_.data();
    m.slots.face_start = face_start_.data();
    m.slots.face_next = face_next_.data();
    m.slots.face_last = face_last_.data();

    std::vector<std::vector<index>> ring_lists(static_cast<size_t>(n));
    std::vector<char> ring_closed(static_cast<size_t>(n), 0);
    for (size_t i = 0; i < rings.size(); ++i) {
        ring_lists[i] = rings[i].other;
        ring_closed[i] = !rings[i].face.empty() && rings[i].face[0] == 1.0;
    }
    build_membranes(m, ring_lists, ring_closed);
}

namespace {

/// Triangle t's coefficient row (Slots::membrane_rows): its stress dW/dC as
/// m1 (I - adj C / J^2) + m2 (adj C + I / J - tr C adj C / J^2) + s1 (C - I) +
/// s2 (tr C - 2) I + d1 dC/dt + d2 tr(dC/dt) I, the six times -2 H (so that the force on a
/// corner is A0 F S g_a): neo-Hookean m1 = mu / 2; Mooney-Rivlin m1 = c10, m2 = c01; StVK
/// s1 = k (1 - nu) / 2, s2 = k nu / 2 with k = E / (2 (1 - nu^2)); the damping d1 = beta
/// G_s / 2, d2 = beta lam_s / 4 (terms/membrane.hpp: stress, small_strain, viscous_half).
std::array<double, 6> membrane_row(const Model& m, index t) {
    const double p0 = m.membranes.params[2 * t], p1 = m.membranes.params[2 * t + 1];
    double m1 = 0.0, m2 = 0.0, s1 = 0.0, s2 = 0.0, shear = 0.0, lame = 0.0;
    switch (m.membranes.material[t]) {
        case MembraneMaterial::NEO_HOOKEAN:
            m1 = 0.5 * p0, shear = p0, lame = 2.0 * p0;
            break;
        case MembraneMaterial::MOONEY_RIVLIN:
            m1 = p0, m2 = p1, shear = 2.0 * (p0 + p1), lame = 4.0 * (p0 + p1);
            break;
        default: {
            const double k = p0 / (2.0 * (1.0 - p1 * p1));
            s1 = 0.5 * k * (1.0 - p1), s2 = 0.5 * k * p1;
            shear = p0 / (2.0 * (1.0 + p1)), lame = p0 * p1 / (1.0 - p1 * p1);
            break;
        }
    }
    const double beta = m.membranes.damping[t], w = -2.0 * m.membranes.thickness[t];
    return {w * m1, w * m2, w * s1, w * s2, w * 0.5 * beta * shear, w * 0.25 * beta * lame};
}

/// Triangle t seen from its corner c, with neighbours `prev` and `cur` (corners cp, cq):
/// u, w, v (the gradient vectors (u, w) of prev and (0, v) of cur in the rest frame whose
/// x axis runs from c to prev; the rest area is A0 = 1 / (2 u |v|)), into out[0],
/// out[stride], out[2 stride]
void membrane_view(const Model& m, index t, int c, int cp, int cq, double* out,
                   size_t stride) {
    const double* bm = m.membranes.rest_inverse + 4 * t;  // Dm^-1, row-major
    const double det = bm[0] * bm[3] - bm[1] * bm[2];
    // the rest corners in the triangle's 2D frame: 0, Dm's columns
    const double x[3][2] = {{0.0, 0.0}, {bm[3] / det, -bm[2] / det}, {-bm[1] / det, bm[0] / det}};
    const double e1[2] = {x[cp][0] - x[c][0], x[cp][1] - x[c][1]};
    const double e2[2] = {x[cq][0] - x[c][0], x[cq][1] - x[c][1]};
    const double len = std::hypot(e1[0], e1[1]);
    const double along = (e1[0] * e2[0] + e1[1] * e2[1]) / len;
    const double across = (e1[0] * e2[1] - e1[1] * e2[0]) / len;
    out[0] = 1.0 / len;
    out[stride] = -along / (len * across);
    out[2 * stride] = 1.0 / across;
}

}  // namespace

void VertexLayout::build_membranes(Model& m, const std::vector<std::vector<index>>& rings,
                                   const std::vector<char>& closed) {
    const index n = m.particles.count, groups = m.slots.group_count;
    const index tm = m.membranes.count;
    // the coefficient rows: row 0 zero (no membrane), equal rows shared
    membrane_rows_.assign(8, 0.0);
    std::map<std::array<double, 6>, index> row_of;
    std::vector<index> tri_row(static_cast<size_t>(tm), 0);
    bool damped = false;
    for (index t = 0; t < tm; ++t) {
        const std::array<double, 6> row = membrane_row(m, t);
        auto [it, fresh] = row_of.insert({row, static_cast<index>(membrane_rows_.size() / 8)});
        if (fresh) {
            membrane_rows_.insert(membrane_rows_.end(), row.begin(), row.end());
            membrane_rows_.insert(membrane_rows_.end(), {0.0, 0.0});
        }
        tri_row[static_cast<size_t>(t)] = it->second;
        damped = damped || row[4] != 0.0 || row[5] != 0.0;
    }
    // each particle's triangles (t, corner), in model order
    std::vector<std::vector<std::pair<index, int>>> corners(static_cast<size_t>(n));
    for (index t = 0; t < tm; ++t)
        for (int c = 0; c < 3; ++c)
            corners[static_cast<size_t>(m.membranes.indices[3 * t + c])].push_back({t, c});
    // a triangle on one of the ring's faces goes to that ring slot (once); the rest to
    // the particle's own membrane slots: (t, corner, corner of next, corner of last)
    struct View {
        index t;
        int c, cp, cq;
    };
    std::vector<std::vector<View>> extra(static_cast<size_t>(n));
    std::vector<std::vector<std::pair<size_t, View>>> on_ring(static_cast<size_t>(n));
    for (index i = 0; i < n; ++i) {
        const size_t own = static_cast<size_t>(i);
        const std::vector<index>& r = rings[own];
        std::vector<char> used(r.size(), 0);
        for (const auto& [t, c] : corners[own]) {
            const index* tri = m.membranes.indices + 3 * t;
            const int c1 = (c + 1) % 3, c2 = (c + 2) % 3;
            bool placed = false;
            for (size_t k = 0; k < r.size() && !placed; ++k) {
                if (used[k] || (k == 0 && !closed[own])) continue;
                const index prev = k > 0 ? r[k - 1] : r.back(), cur = r[k];
                int cp = -1, cq = -1;
                if (tri[c1] == prev && tri[c2] == cur) cp = c1, cq = c2;
                if (tri[c2] == prev && tri[c1] == cur) cp = c2, cq = c1;
                if (cp < 0) continue;
                used[k] = 1;
                on_ring[own].push_back({k, View{t, c, cp, cq}});
                placed = true;
            }
            if (!placed) extra[own].push_back(View{t, c, c1, c2});
        }
    }
    const size_t ring_entries = static_cast<size_t>(kGroup * ring_start_.back());
    ring_membrane_.assign(kMembraneGeometry * ring_entries, 0.0);
    ring_membrane_row_.assign(ring_entries, 0);
    membrane_start_.assign(static_cast<size_t>(groups + 1), 0);
    for (index g = 0; g < groups; ++g) {
        size_t most = 0;
        for (index i = kGroup * g; i < std::min(n, kGroup * (g + 1)); ++i)
            most = std::max(most, extra[static_cast<size_t>(i)].size());
        membrane_start_[static_cast<size_t>(g + 1)] =
            membrane_start_[static_cast<size_t>(g)] + static_cast<index>(most);
    }
    const size_t entries = static_cast<size_t>(kGroup * membrane_start_.back());
    membrane_next_.assign(entries, 0);
    membrane_last_.assign(entries, 0);
    membrane_geometry_.assign(kMembraneGeometry * entries, 0.0);
    membrane_row_.assign(entries, 0);
    for (index g = 0; g < groups; ++g)
        for (index l = 0; l < kGroup; ++l) {
            const index i = kGroup * g + l;
            const size_t own = static_cast<size_t>(i);
            if (i < n) {
                const index r0 = ring_start_[static_cast<size_t>(g)];
                const size_t slots =
                    static_cast<size_t>(ring_start_[static_cast<size_t>(g + 1)] - r0);
                for (const auto& [k, view] : on_ring[own]) {
                    // the closing face (k = 0) sits where the pass meets it: the first
                    // padding slot of a padded ring, else slot 0 (the end of the ring)
                    const size_t local =
                        k == 0 && rings[own].size() < slots ? rings[own].size() : k;
                    const size_t s = static_cast<size_t>(r0) + local;
                    membrane_view(m, view.t, view.c, view.cp, view.cq,
                                  ring_membrane_.data() + kMembraneGeometry * kGroup * s + l,
                                  kGroup);
                    ring_membrane_row_[kGroup * s + l] = tri_row[static_cast<size_t>(view.t)];
                }
            }
            const index s0 = membrane_start_[static_cast<size_t>(g)];
            for (index s = s0; s < membrane_start_[static_cast<size_t>(g + 1)]; ++s) {
                const size_t e = static_cast<size_t>(kGroup * s + l);
                const size_t k = static_cast<size_t>(s - s0);
                membrane_next_[e] = membrane_last_[e] = i;  // padding: no triangle
                if (i < n && k < extra[own].size()) {
                    const View& view = extra[own][k];
                    const index* tri = m.membranes.indices + 3 * view.t;
                    membrane_next_[e] = tri[view.cp];
                    membrane_last_[e] = tri[view.cq];
                    const size_t at = kMembraneGeometry * kGroup * static_cast<size_t>(s) + l;
                    membrane_view(m, view.t, view.c, view.cp, view.cq,
                                  membrane_geometry_.data() + at, kGroup);
                    membrane_row_[e] = tri_row[static_cast<size_t>(view.t)];
                }
            }
        }
    m.slots.ring_membrane = ring_membrane_.data();
    m.slots.ring_membrane_row = ring_membrane_row_.data();
    m.slots.membrane_start = membrane_start_.data();
    m.slots.membrane_next = membrane_next_.data();
    m.slots.membrane_last = membrane_last_.data();
    m.slots.membrane_geometry = membrane_geometry_.data();
    m.slots.membrane_row = membrane_row_.data();
    m.slots.membrane_rows = membrane_rows_.data();
    m.slots.membrane_damped = damped;
    m.slots.membrane_one_row = membrane_rows_.size() == 16 && tm > 0;  // one row past row 0
}

}  // namespace softbody
