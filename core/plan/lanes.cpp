// The vertex-major tables (plan/lanes.hpp).
#include "plan/lanes.hpp"

#include <algorithm>
#include <limits>

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
}

}  // namespace softbody
