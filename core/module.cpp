// softbody._core: the Python face of the engine core. Python plans (builder, meshes, scenes,
// solver set-up); these objects hold views of its NumPy arrays, check them once, and step.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <thread>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <tuple>
#include <vector>

#include "kernels.hpp"
#include "model.hpp"
#include "plan/factor.hpp"
#include "render/raster.hpp"

namespace nb = nanobind;
using Index = softbody::index;

namespace {

using ConstF64 = nb::ndarray<const double, nb::c_contig, nb::device::cpu>;
using ConstI64 = nb::ndarray<const std::int64_t, nb::c_contig, nb::device::cpu>;
using F64 = nb::ndarray<double, nb::c_contig, nb::device::cpu>;

[[noreturn]] void fail(const std::string& what) { throw nb::value_error(what.c_str()); }

std::string shape_text(const std::vector<Index>& shape) {
    std::string s = "(";
    for (size_t k = 0; k < shape.size(); ++k) {
        if (k) s += ", ";
        s += std::to_string(shape[k]);
    }
    return s + (shape.size() == 1 ? ",)" : ")");
}

template <typename Array>
void check_shape(const Array& a, const std::string& name, const std::vector<Index>& shape) {
    bool ok = a.ndim() == shape.size();
    for (size_t k = 0; ok && k < shape.size(); ++k)
        ok = shape[k] < 0 || static_cast<Index>(a.shape(k)) == shape[k];
    if (!ok) {
        std::vector<Index> got;
        for (size_t k = 0; k < a.ndim(); ++k) got.push_back(static_cast<Index>(a.shape(k)));
        fail(name + " must have shape " + shape_text(shape) + ", got " + shape_text(got));
    }
}

/// A float64 (or int64) C-contiguous array attribute of a Python bundle, shape-checked.
template <typename Array>
Array attribute(nb::handle bundle, const char* name, const std::vector<Index>& shape) {
    nb::object value = bundle.attr(name);
    Array a;
    if (!nb::try_cast(value, a, false))
        fail(std::string(name) + " must be a C-contiguous " +
             (std::is_same_v<Array, ConstI64> ? "int64" : "float64") + " array");
    check_shape(a, name, shape);
    return a;
}

void check_indices(const Index* v, Index count, Index lo, Index hi, const std::string& name) {
    for (Index k = 0; k < count; ++k)
        if (v[k] < lo || v[k] >= hi)
            fail(name + " holds " + std::to_string(v[k]) + " at " + std::to_string(k) +
                 ", outside [" + std::to_string(lo) + ", " + std::to_string(hi) + ")");
}

void check_ranges(const Index* r, Index count, Index limit, const std::string& name) {
    for (Index b = 0; b < count; ++b)
        if (r[2 * b] < 0 || r[2 * b] > r[2 * b + 1] || r[2 * b + 1] > limit)
            fail(name + " row " + std::to_string(b) + " is not a range within [0, " +
                 std::to_string(limit) + "]");
}

/// softbody._core.Model: checked views of a softbody Model's arrays (kept alive here).
class CoreModel {
public:
    explicit CoreModel(nb::handle d) {
        softbody::Model& m = model_;
        auto f64 = [&](const char* name, std::vector<Index> shape) {
            ConstF64 a = attribute<ConstF64>(d, name, shape);
            keep_f_.push_back(a);
            return a.data();
        };
        auto i64 = [&](const char* name, std::vector<Index> shape) {
            ConstI64 a = attribute<ConstI64>(d, name, shape);
            keep_i_.push_back(a);
            return a.data();
        };
        ConstF64 mass = attribute<ConstF64>(d, "particle_mass", {-1});
        const Index n = static_cast<Index>(mass.shape(0));
        ConstI64 springs = attribute<ConstI64>(d, "spring_indices", {-1, 2});
        const Index s = static_cast<Index>(springs.shape(0));
        ConstI64 tris = attribute<ConstI64>(d, "tri_indices", {-1, 3});
        const Index t = static_cast<Index>(tris.shape(0));
        ConstI64 ranges = attribute<ConstI64>(d, "body_particle_range", {-1, 2});
        const Index b = static_cast<Index>(ranges.shape(0));
        ConstI64 att = attribute<ConstI64>(d, "attachment_particle", {-1});
        const Index a = static_cast<Index>(att.shape(0));
        ConstI64 kinds = attribute<ConstI64>(d, "collider_kind", {-1});
        const Index c = static_cast<Index>(kinds.shape(0));
        ConstI64 pins = attribute<ConstI64>(d, "pin_particle", {-1});
        ConstF64 samples = attribute<ConstF64>(d, "mc_samples", {-1, 2});
        ConstF64 times = attribute<ConstF64>(d, "schedule_time", {-1});
        keep_f_.insert(keep_f_.end(), {mass, samples, times});
        keep_i_.insert(keep_i_.end(), {springs, tris, ranges, att, kinds, pins});

        m.particle_count = n;
        m.spring_count = s;
        m.tri_count = t;
        m.body_count = b;
        m.attachment_count = a;
        m.collider_count = c;
        m.pin_count = static_cast<Index>(pins.shape(0));
        m.mc_count = static_cast<Index>(samples.shape(0));
        m.schedule_count = static_cast<Index>(times.shape(0));

        m.particle_mass = mass.data();
        m.particle_inv_mass = f64("particle_inv_mass", {n});
        m.particle_body = i64("particle_body", {n});
        const double* g = f64("gravity", {3});
        for (int k = 0; k < 3; ++k) m.gravity[k] = g[k];
        m.spring_indices = springs.data();
        m.spring_rest_length = f64("spring_rest_length", {s});
        m.spring_stiffness = f64("spring_stiffness", {s});
        m.spring_damping = f64("spring_damping", {s});
        m.attachment_particle = att.data();
        m.attachment_rest_length = f64("attachment_rest_length", {a});
        m.attachment_stiffness = f64("attachment_stiffness", {a});
        m.attachment_damping = f64("attachment_damping", {a});
        m.tri_indices = tris.data();
        m.tri_body = i64("tri_body", {t});
        m.body_particle_range = ranges.data();
        m.body_tri_range = i64("body_tri_range", {b, 2});
        m.body_volume_method = i64("body_volume_method", {b});
        m.body_mc_range = i64("body_mc_range", {b, 2});
        m.mc_samples = samples.data();
        m.body_gas_law = i64("body_gas_law", {b});
        m.body_gas_value = f64("body_gas_value", {b});
        m.body_gas_gamma = f64("body_gas_gamma", {b});
        m.body_gas_reference_volume = f64("body_gas_reference_volume", {b});
        m.body_ambient_pressure = f64("body_ambient_pressure", {b});
        m.body_schedule_range = i64("body_schedule_range", {b, 2});
        m.schedule_time = times.data();
        m.schedule_value = f64("schedule_value", {m.schedule_count});
        m.body_rest_volume = f64("body_rest_volume", {b});
        m.body_closed = i64("body_closed", {b});
        m.body_contact_shape = i64("body_contact_shape", {b});
        m.pin_particle = pins.data();
        m.body_drag_coefficient = f64("body_drag_coefficient", {b});
        m.air_density = nb::cast<double>(d.attr("air_density"));
        const double* wind = f64("wind", {3});
        for (int k = 0; k < 3; ++k) m.wind[k] = wind[k];
        m.soft_contact_mode = nb::cast<int>(d.attr("soft_contact_mode"));
        m.soft_contact_restitution = nb::cast<double>(d.attr("soft_contact_restitution"));
        m.soft_contact_friction = nb::cast<double>(d.attr("soft_contact_friction"));
        m.contact_margin = nb::cast<double>(d.attr("contact_margin"));
        m.contact_cell_size = nb::cast<double>(d.attr("contact_cell_size"));
        m.collider_kind = kinds.data();
        m.collider_center = f64("collider_center", {c, 3});
        m.collider_rotation = f64("collider_rotation", {c, 3, 3});
        m.collider_size = f64("collider_size", {c, 3});
        m.collider_restitution = f64("collider_restitution", {c});
        m.collider_friction = f64("collider_friction", {c});
        m.collider_motion = i64("collider_motion", {c});
        m.collider_motion_vector = f64("collider_motion_vector", {c, 3});
        m.collider_motion_pivot = f64("collider_motion_pivot", {c, 3});
        m.collider_motion_frequency = f64("collider_motion_frequency", {c});
        validate();
        build_lanes();
    }

    const softbody::Model& model() const { return model_; }

private:
    // Indices and enumerations in range, so no kernel reads outside an array.
    void validate() {
        const softbody::Model& m = model_;
        check_indices(m.spring_indices, 2 * m.spring_count, 0, m.particle_count, "spring_indices");
        check_indices(m.tri_indices, 3 * m.tri_count, 0, m.particle_count, "tri_indices");
        check_indices(m.tri_body, m.tri_count, 0, m.body_count, "tri_body");
        check_indices(m.particle_body, m.particle_count, -1, m.body_count, "particle_body");
        check_indices(m.attachment_particle, m.attachment_count, 0, m.particle_count,
                      "attachment_particle");
        check_indices(m.pin_particle, m.pin_count, 0, m.particle_count, "pin_particle");
        check_ranges(m.body_particle_range, m.body_count, m.particle_count, "body_particle_range");
        check_ranges(m.body_tri_range, m.body_count, m.tri_count, "body_tri_range");
        check_ranges(m.body_mc_range, m.body_count, m.mc_count, "body_mc_range");
        check_ranges(m.body_schedule_range, m.body_count, m.schedule_count, "body_schedule_range");
        for (Index b = 0; b < m.body_count; ++b) {
            // a body's triangles Index its own particles (the volume's reference point)
            const Index p0 = m.body_particle_range[2 * b], p1 = m.body_particle_range[2 * b + 1];
            if (m.body_tri_range[2 * b + 1] > m.body_tri_range[2 * b] && p1 == p0)
                fail("body " + std::to_string(b) + " has triangles but no particles");
        }
        check_indices(m.body_volume_method, m.body_count, 0, 5, "body_volume_method");
        check_indices(m.body_gas_law, m.body_count, 0, 3, "body_gas_law");
        check_indices(m.body_contact_shape, m.body_count, 0, 4, "body_contact_shape");
        check_indices(m.collider_kind, m.collider_count, 0, 4, "collider_kind");
        check_indices(m.collider_motion, m.collider_count, 0, 4, "collider_motion");
        if (m.soft_contact_mode < 0 || m.soft_contact_mode > 2)
            fail("soft_contact_mode must be 0, 1 or 2");
        if (m.soft_contact_mode == 2) {
            // the surface contacts' grid: cells of a positive, finite size
            if (!(std::isfinite(m.contact_cell_size) && m.contact_cell_size > 0.0))
                fail("contact_cell_size must be finite and > 0, got " +
                     std::to_string(m.contact_cell_size));
            if (!(std::isfinite(m.contact_margin) && m.contact_margin >= 0.0))
                fail("contact_margin must be finite and >= 0, got " +
                     std::to_string(m.contact_margin));
        }
        check_drag();
    }

    // Air and drag coefficients physical (finite, >= 0); the drag term runs only when some
    // body has drag in air of positive density.
    void check_drag() {
        softbody::Model& m = model_;
        if (!(std::isfinite(m.air_density) && m.air_density >= 0.0))
            fail("air_density must be finite and >= 0 kg/m^3, got " +
                 std::to_string(m.air_density));
        for (int k = 0; k < 3; ++k)
            if (!std::isfinite(m.wind[k])) fail("wind must be 3 finite numbers [m/s]");
        bool any = false;
        for (Index b = 0; b < m.body_count; ++b) {
            const double cd = m.body_drag_coefficient[b];
            if (!(std::isfinite(cd) && cd >= 0.0))
                fail("body_drag_coefficient holds " + std::to_string(cd) + " at " +
                     std::to_string(b) + "; it must be finite and >= 0");
            any = any || cd > 0.0;
        }
        m.drag_active = any && m.air_density > 0.0;
    }

    // A particle's faces (i, j, k) as directed pairs j -> k, in fan order: a closed fan is
    // one cycle, a fan on an open surface's border one path (begun at its free end). False
    // when they make neither (two fans meeting at a vertex), and the particle's faces go to
    // the plain face slots instead. `ring` gets j_0, j_1, ...; `closed` says which.
    static bool fan_order(const std::vector<std::pair<Index, Index>>& pairs,
                          std::vector<Index>& ring, bool& closed) {
        ring.clear();
        closed = false;
        if (pairs.empty()) return true;
        // sorted by their first end (O(F log F) for a fan of F faces, however large)
        std::vector<std::pair<Index, Index>> by_first(pairs), by_second;
        std::sort(by_first.begin(), by_first.end());
        for (const auto& [j, k] : pairs) by_second.push_back({k, j});
        std::sort(by_second.begin(), by_second.end());
        for (size_t a = 0; a < by_first.size(); ++a) {
            if (by_first[a].first == by_first[a].second) return false;
            if (a > 0 && (by_first[a].first == by_first[a - 1].first ||
                          by_second[a].first == by_second[a - 1].first))
                return false;  // two faces leave (or reach) one neighbour: not one fan
        }
        auto next_of = [&](Index j) -> Index {
            auto it = std::lower_bound(by_first.begin(), by_first.end(),
                                       std::pair<Index, Index>{j, std::numeric_limits<Index>::min()});
            return it != by_first.end() && it->first == j ? it->second : -1;
        };
        auto has_incoming = [&](Index j) {
            auto it = std::lower_bound(by_second.begin(), by_second.end(),
                                       std::pair<Index, Index>{j, std::numeric_limits<Index>::min()});
            return it != by_second.end() && it->first == j;
        };
        Index start = pairs[0].first;  // a closed fan: from its first face
        for (const auto& [j, k] : pairs)
            if (!has_incoming(j)) {
                start = j;  // an open fan: from its free end
                break;
            }
        Index at = start;
        ring.push_back(at);
        for (size_t step = 0; step < pairs.size(); ++step) {
            const Index next = next_of(at);
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
    void build_lanes() {
        softbody::Model& m = model_;
        const Index n = m.particle_count, groups = (n + kGroup - 1) / kGroup;
        const size_t lanes = static_cast<size_t>(kGroup * groups);
        m.group_count = groups;
        lane_mass_.assign(lanes, 0.0);
        std::copy(m.particle_mass, m.particle_mass + n, lane_mass_.begin());
        lane_reference_.resize(lanes);
        for (size_t i = 0; i < lanes; ++i) lane_reference_[i] = static_cast<Index>(i);
        for (Index b = 0; b < m.body_count; ++b)
            for (Index i = m.body_particle_range[2 * b]; i < m.body_particle_range[2 * b + 1]; ++i)
                lane_reference_[static_cast<size_t>(i)] = m.body_particle_range[2 * b];
        m.lane_mass = lane_mass_.data();
        m.lane_reference = lane_reference_.data();

        // each particle's springs (other end, spring) and faces (j, k), in model order
        std::vector<std::vector<std::pair<Index, Index>>> springs(static_cast<size_t>(n)),
            faces(static_cast<size_t>(n));
        for (Index s = 0; s < m.spring_count; ++s) {
            const Index i = m.spring_indices[2 * s], j = m.spring_indices[2 * s + 1];
            springs[static_cast<size_t>(i)].push_back({j, s});
            springs[static_cast<size_t>(j)].push_back({i, s});
        }
        for (Index t = 0; t < m.tri_count; ++t)
            for (int c = 0; c < 3; ++c)
                faces[static_cast<size_t>(m.tri_indices[3 * t + c])].push_back(
                    {m.tri_indices[3 * t + (c + 1) % 3], m.tri_indices[3 * t + (c + 2) % 3]});

        // per particle: its ring (neighbour, spring or -1, face weight), its other springs
        // and the faces of a broken fan
        struct Ring {
            std::vector<Index> other, spring;
            std::vector<double> face;
        };
        std::vector<Ring> rings(static_cast<size_t>(n));
        std::vector<std::vector<std::pair<Index, Index>>> extra_springs(static_cast<size_t>(n)),
            extra_faces(static_cast<size_t>(n));
        std::vector<Index> order;
        for (Index i = 0; i < n; ++i) {
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
            std::vector<std::pair<Index, Index>>& mine = springs[own];
            std::sort(mine.begin(), mine.end());
            for (size_t s = 0; s < order.size(); ++s) {
                Index spring = -1;
                auto it = std::lower_bound(mine.begin(), mine.end(),
                                           std::pair<Index, Index>{order[s], std::numeric_limits<Index>::min()});
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

        auto starts = [&](auto count, std::vector<Index>& start) {
            start.assign(static_cast<size_t>(groups + 1), 0);
            for (Index g = 0; g < groups; ++g) {
                size_t most = 0;
                for (Index i = kGroup * g; i < std::min(n, kGroup * (g + 1)); ++i)
                    most = std::max(most, count(static_cast<size_t>(i)));
                start[static_cast<size_t>(g + 1)] = start[static_cast<size_t>(g)] + static_cast<Index>(most);
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
        for (Index g = 0; g < groups; ++g)
            for (Index l = 0; l < kGroup; ++l) {
                const Index i = kGroup * g + l;  // padding lanes (i >= N) list nothing
                const bool real = i < n;
                const size_t own = static_cast<size_t>(i);
                const Index r0 = ring_start_[static_cast<size_t>(g)];
                for (Index s = r0; s < ring_start_[static_cast<size_t>(g + 1)]; ++s) {
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
                    const Index spring = rings[own].spring[k];
                    if (spring >= 0) {
                        ring_rest_[e] = m.spring_rest_length[spring];
                        ring_k_[e] = m.spring_stiffness[spring];
                        ring_c_[e] = m.spring_damping[spring];
                    }
                }
                const Index s0 = spring_start_[static_cast<size_t>(g)];
                for (Index s = s0; s < spring_start_[static_cast<size_t>(g + 1)]; ++s) {
                    const size_t e = static_cast<size_t>(kGroup * s + l), k = static_cast<size_t>(s - s0);
                    spring_other_[e] = i;  // padding: itself, no stiffness
                    if (real && k < extra_springs[own].size()) {
                        const auto [other, spring] = extra_springs[own][k];
                        spring_other_[e] = other;
                        spring_rest_[e] = m.spring_rest_length[spring];
                        spring_k_[e] = m.spring_stiffness[spring];
                        spring_c_[e] = m.spring_damping[spring];
                    }
                }
                const Index f0 = face_start_[static_cast<size_t>(g)];
                for (Index s = f0; s < face_start_[static_cast<size_t>(g + 1)]; ++s) {
                    const size_t e = static_cast<size_t>(kGroup * s + l), k = static_cast<size_t>(s - f0);
                    face_next_[e] = face_last_[e] = i;  // padding: a face of no area
                    if (real && k < extra_faces[own].size()) {
                        face_next_[e] = extra_faces[own][k].first;
                        face_last_[e] = extra_faces[own][k].second;
                    }
                }
            }
        m.ring_slot_start = ring_start_.data();
        m.ring_slot_other = ring_other_.data();
        m.ring_slot_rest_length = ring_rest_.data();
        m.ring_slot_stiffness = ring_k_.data();
        m.ring_slot_damping = ring_c_.data();
        m.ring_slot_face = ring_face_.data();
        m.spring_slot_start = spring_start_.data();
        m.spring_slot_other = spring_other_.data();
        m.spring_slot_rest_length = spring_rest_.data();
        m.spring_slot_stiffness = spring_k_.data();
        m.spring_slot_damping = spring_c_.data();
        m.face_slot_start = face_start_.data();
        m.face_slot_next = face_next_.data();
        m.face_slot_last = face_last_.data();
    }

    static constexpr Index kGroup = 8;  // the kernels' lane group (simd.hpp)
    softbody::Model model_;
    std::vector<double> lane_mass_, ring_rest_, ring_k_, ring_c_, ring_face_;
    std::vector<double> spring_rest_, spring_k_, spring_c_;
    std::vector<Index> lane_reference_, ring_start_, ring_other_;
    std::vector<Index> spring_start_, spring_other_, face_start_, face_next_, face_last_;
    std::vector<ConstF64> keep_f_;
    std::vector<ConstI64> keep_i_;
};

/// Views of a ControlData bundle, checked against the model (held for one call).
struct CoreControl {
    CoreControl(const softbody::Model& m, nb::handle d) {
        gas = attribute<ConstF64>(d, "gas_override", {m.body_count});
        particle_f = attribute<ConstF64>(d, "particle_f", {m.particle_count, 3});
        anchor = attribute<ConstF64>(d, "attachment_anchor", {m.attachment_count, 3});
        pin = attribute<ConstF64>(d, "pin_target", {m.pin_count, 3});
        target = attribute<ConstF64>(d, "collider_target", {m.collider_count, 3});
        ConstF64 grab = attribute<ConstF64>(d, "grab_target", {3});
        view.gas_override = gas.data();
        view.particle_f = particle_f.data();
        view.attachment_anchor = anchor.data();
        view.pin_target = pin.data();
        view.pin_active = nb::cast<bool>(d.attr("pin_active"));
        view.collider_target = target.data();
        view.grab_particle = nb::cast<Index>(d.attr("grab_particle"));
        if (view.grab_particle < -1 || view.grab_particle >= m.particle_count)
            fail("grab_particle must be -1 or a particle Index");
        for (int k = 0; k < 3; ++k) view.grab_target[k] = grab.data()[k];
        view.grab_stiffness = nb::cast<double>(d.attr("grab_stiffness"));
        view.grab_damping = nb::cast<double>(d.attr("grab_damping"));
        wind_from(m, attribute<ConstF64>(d, "wind", {3}).data());
    }

    // Control.wind: 3 finite numbers [m/s], or all NaN for the model's wind.
    void wind_from(const softbody::Model& m, const double* w) {
        const bool given = std::isfinite(w[0]) && std::isfinite(w[1]) && std::isfinite(w[2]);
        const bool unset = std::isnan(w[0]) && std::isnan(w[1]) && std::isnan(w[2]);
        if (!given && !unset) fail("Control wind must be 3 finite numbers [m/s] or all NaN");
        for (int k = 0; k < 3; ++k) view.wind[k] = given ? w[k] : m.wind[k];
    }
    ConstF64 gas, particle_f, anchor, pin, target;
    softbody::Control view;
};

F64 writable(nb::handle h, const char* name, const std::vector<Index>& shape) {
    F64 a;
    if (!nb::try_cast(h, a, false))
        fail(std::string(name) + " must be a writable C-contiguous float64 array");
    check_shape(a, name, shape);
    return a;
}

/// Buckets of the surface contacts' spatial hash for T triangles: the smallest power of two
/// >= 2 T, at least 16 (as softbody.integrators.workspace.Workspace.for_model sizes it).
Index hash_table_size(Index tris) {
    Index table = 16;
    while (table < 2 * std::max<Index>(tris, 1)) table <<= 1;
    return table;
}

/// A solver's scratch, allocated once: (N, 3) rows, per-body and per-collider arrays, and
/// for surface soft contacts (soft_contact_mode 2) the spatial hash with room for
/// `hash_capacity` entries.
class Buffers {
public:
    explicit Buffers(const softbody::Model& m, int rows, Index hash_capacity = 0) {
        const size_t n3 = static_cast<size_t>(3 * m.particle_count);
        const size_t b = static_cast<size_t>(m.body_count), c = static_cast<size_t>(m.collider_count);
        rows_.assign(static_cast<size_t>(rows), std::vector<double>(n3, 0.0));
        per_body_.assign(11, std::vector<double>(3 * b, 0.0));
        per_collider_.assign(3, std::vector<double>(3 * c, 0.0));
        gradient_.assign(n3, 0.0);
        if (rows > 0) {  // the force pass's packed rows (a volume-only call needs none)
            const size_t lanes = static_cast<size_t>(8 * m.group_count);
            rows_buffer_.assign(8 * lanes, 0.0);  // padding rows stay zero
            lane_pnet_.assign(lanes, 0.0);
            lanes_view.rows = rows_buffer_.data();
            lanes_view.lane_pnet = lane_pnet_.data();
        }
        gas.volume = per_body_[0].data();
        gas.pressure = per_body_[1].data();
        gas.lo = per_body_[2].data();
        gas.hi = per_body_[3].data();
        gas.volume_gradient = gradient_.data();
        contact.body_lo = per_body_[4].data();
        contact.body_hi = per_body_[5].data();
        contact.body_velocity = per_body_[6].data();
        contact.body_mass = per_body_[7].data();
        contact.body_center = per_body_[8].data();
        contact.body_axes = per_body_[9].data();
        contact.body_dv = per_body_[10].data();
        contact.collider_q_start = per_collider_[0].data();
        contact.collider_v = per_collider_[1].data();
        contact.collider_w = per_collider_[2].data();
        if (m.soft_contact_mode == 2) {
            const Index table = hash_table_size(m.tri_count);
            hash_start_.assign(static_cast<size_t>(table + 1), 0);
            hash_count_.assign(static_cast<size_t>(table), 0);
            hash_entries_.assign(static_cast<size_t>(hash_capacity), 0);
            contact.hash_table = table;
            contact.hash_capacity = hash_capacity;
            contact.hash_start = hash_start_.data();
            contact.hash_count = hash_count_.data();
            contact.hash_entries = hash_entries_.data();
        }
    }
    double* row(int k) { return rows_[static_cast<size_t>(k)].data(); }
    softbody::LaneBuffers lanes_view;
    softbody::BodyGas gas;
    softbody::ContactBuffers contact;

private:
    std::vector<std::vector<double>> rows_, per_body_, per_collider_;
    std::vector<double> gradient_, rows_buffer_, lane_pnet_;
    std::vector<Index> hash_start_, hash_count_, hash_entries_;
};

/// Entries of the surface contacts' hash: as asked, by default 8 per triangle (room for
/// triangles up to a cell across); 0 without surface contacts.
Index checked_capacity(const softbody::Model& m, std::optional<Index> asked) {
    if (asked && *asked < 0) fail("hash_capacity must be >= 0, got " + std::to_string(*asked));
    if (m.soft_contact_mode != 2) return 0;
    return asked ? *asked : 8 * m.tri_count;
}

/// A run's state arrays and limits, checked against the model (views held for one call).
struct CheckedRun {
    F64 q, qd, collider_q, collider_rot, collider_impulse;
    softbody::StateView state;
    softbody::RunParams params;
};

CheckedRun checked_run(const softbody::Model& m, Index steps, double t0, double dt,
                       nb::handle q, nb::handle qd, nb::handle collider_q,
                       nb::handle collider_rot, nb::handle collider_impulse, double max_speed,
                       double ratio_min, double ratio_max) {
    if (steps < 0) fail("steps must be >= 0");
    if (!(std::isfinite(dt) && dt > 0.0)) fail("dt must be finite and > 0");
    CheckedRun run;
    run.q = writable(q, "q", {m.particle_count, 3});
    run.qd = writable(qd, "qd", {m.particle_count, 3});
    run.collider_q = writable(collider_q, "collider_q", {m.collider_count, 3});
    run.collider_rot = writable(collider_rot, "collider_rot", {m.collider_count, 3, 3});
    run.collider_impulse = writable(collider_impulse, "collider_impulse", {m.collider_count, 3});
    run.state = {run.q.data(), run.qd.data(), run.collider_q.data(), run.collider_rot.data(),
                 run.collider_impulse.data()};
    run.params.steps = steps;
    run.params.t0 = t0;
    run.params.dt = dt;
    run.params.max_speed = max_speed;
    run.params.ratio_min = ratio_min;
    run.params.ratio_max = ratio_max;
    return run;
}

/// A fixed set of worker threads for softbody::Parallel: run() hands chunk 0 to the caller
/// and chunk w to worker w, and returns when every chunk is done. Workers wait on a
/// condition variable between calls, so an idle pool costs nothing.
class ThreadPool {
public:
    static constexpr int kMostThreads = 256;

    explicit ThreadPool(int threads) : threads_(threads) {
        for (int w = 1; w < threads; ++w) workers_.emplace_back([this, w] { work(w); });
    }
    ~ThreadPool() {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            stop_ = true;
        }
        start_.notify_all();
        for (std::thread& t : workers_) t.join();
    }
    ThreadPool(const ThreadPool&) = delete;
    ThreadPool& operator=(const ThreadPool&) = delete;

    softbody::Parallel interface() {
        softbody::Parallel p;
        p.chunks = threads_;
        p.pool = this;
        p.run = [](const softbody::Parallel& self, void (*task)(void*, int), void* context) {
            static_cast<ThreadPool*>(self.pool)->run(task, context);
        };
        return p;
    }

private:
    void run(void (*task)(void*, int), void* context) {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            task_ = task;
            context_ = context;
            pending_ = threads_ - 1;
            ++generation_;
        }
        start_.notify_all();
        task(context, 0);
        std::unique_lock<std::mutex> lock(mutex_);
        done_.wait(lock, [this] { return pending_ == 0; });
    }

    void work(int chunk) {
        std::uint64_t seen = 0;
        for (;;) {
            void (*task)(void*, int);
            void* context;
            {
                std::unique_lock<std::mutex> lock(mutex_);
                start_.wait(lock, [&] { return stop_ || generation_ != seen; });
                if (stop_) return;
                seen = generation_;
                task = task_;
                context = context_;
            }
            task(context, chunk);
            {
                std::lock_guard<std::mutex> lock(mutex_);
                --pending_;
            }
            done_.notify_one();
        }
    }

    int threads_;
    std::vector<std::thread> workers_;
    std::mutex mutex_;
    std::condition_variable start_, done_;
    std::uint64_t generation_ = 0;
    int pending_ = 0;
    bool stop_ = false;
    void (*task_)(void*, int) = nullptr;
    void* context_ = nullptr;
};

/// A solver's opt-in threads: a pool, its Parallel interface and the per-chunk volume
/// sums, attached to the solver's force pass (1 thread: nothing, the serial kernels).
/// Lives inside its solver and never moves, since the lanes point at it.
class SolverThreads {
public:
    SolverThreads(int threads, Index body_count) {
        if (threads < 1 || threads > ThreadPool::kMostThreads)
            fail("threads must be from 1 to " + std::to_string(ThreadPool::kMostThreads));
        if (threads > 1) {
            pool_ = std::make_unique<ThreadPool>(threads);
            parallel_ = pool_->interface();
            chunk_volume_.assign(static_cast<size_t>(threads * body_count), 0.0);
        }
    }
    SolverThreads(const SolverThreads&) = delete;
    SolverThreads& operator=(const SolverThreads&) = delete;

    void attach(softbody::LaneBuffers& lanes) {
        if (!pool_) return;
        lanes.parallel = &parallel_;
        lanes.chunk_volume = chunk_volume_.data();
    }
    int count() const { return parallel_.chunks; }

private:
    std::unique_ptr<ThreadPool> pool_;
    softbody::Parallel parallel_;
    std::vector<double> chunk_volume_;
};

/// softbody._core.ExplicitSolver: the explicit schemes' time loop and its scratch.
class ExplicitSolver {
public:
    ExplicitSolver(nb::object model, std::optional<Index> hash_capacity, int threads)
        : handle_(model),
          model_(nb::cast<const CoreModel&>(model)),
          buffers_(model_.model(), 7, checked_capacity(model_.model(), hash_capacity)),
          threads_(threads, model_.model().body_count) {
        threads_.attach(buffers_.lanes_view);
        w_.f = buffers_.row(0);
        w_.q0 = buffers_.row(1);
        w_.v0 = buffers_.row(2);
        w_.qs = buffers_.row(3);
        w_.vs = buffers_.row(4);
        w_.acc_q = buffers_.row(5);
        w_.acc_v = buffers_.row(6);
        w_.gas = buffers_.gas;
        w_.lanes = buffers_.lanes_view;
        w_.contact = buffers_.contact;
    }

    std::tuple<int, Index, Index, double> simulate(int scheme, Index steps, double t0, double dt,
                                                   nb::handle control, nb::handle q,
                                                   nb::handle qd, nb::handle collider_q,
                                                   nb::handle collider_rot,
                                                   nb::handle collider_impulse, double max_speed,
                                                   double ratio_min, double ratio_max) {
        const softbody::Model& m = model_.model();
        if (scheme < 0 || scheme > 4) fail("scheme must be an explicit Integrator (0-4)");
        CheckedRun run = checked_run(m, steps, t0, dt, q, qd, collider_q, collider_rot,
                                     collider_impulse, max_speed, ratio_min, ratio_max);
        run.params.scheme = scheme;
        CoreControl c(m, control);
        softbody::RunResult r;
        {
            nb::gil_scoped_release release;
            r = softbody::kernels().simulate_explicit(m, c.view, run.params, run.state, w_);
        }
        return {r.status, r.steps_done, r.where, r.value};
    }

    Index hash_capacity() const { return buffers_.contact.hash_capacity; }
    int threads() const { return threads_.count(); }

private:
    nb::object handle_;  // keeps the CoreModel (and so the model's arrays) alive
    const CoreModel& model_;
    Buffers buffers_;
    SolverThreads threads_;
    softbody::ExplicitBuffers w_;
};

/// A Projective bundle's factor (softbody.integrators.projective.Projective), checked once
/// against a model of N particles: shapes, the supernodes' column, row and value ranges
/// nested and in bounds, each node's rows its own columns then rows below them, and perm a
/// permutation, so the triangular solves read and write only inside the arrays.
class CoreFactor {
public:
    CoreFactor(nb::handle d, Index n) : handle_(nb::borrow(d)) {
        softbody::Factor& a = factor_;
        const Index size = nb::cast<Index>(d.attr("size"));
        if (size != n)
            fail("the projective factor has size " + std::to_string(size) + " for a model of " +
                 std::to_string(n) + " particles");
        a.size = n;
        a.dt = nb::cast<double>(d.attr("dt"));
        if (!(std::isfinite(a.dt) && a.dt > 0.0)) fail("the projective factor's dt must be > 0");
        perm_ = attribute<ConstI64>(d, "perm", {n});
        inv_diag_ = attribute<ConstF64>(d, "inv_diag", {n});
        col_ = attribute<ConstI64>(d, "node_col", {-1});
        const Index count = static_cast<Index>(col_.shape(0)) - 1;
        if (count < 0) fail("node_col must hold at least one entry");
        row_ptr_ = attribute<ConstI64>(d, "node_row_ptr", {count + 1});
        rows_ = attribute<ConstI64>(d, "node_row", {-1});
        value_ptr_ = attribute<ConstI64>(d, "node_value_ptr", {count + 1});
        values_ = attribute<ConstF64>(d, "node_value", {-1});
        a.node_count = count;
        a.perm = perm_.data();
        a.inv_diag = inv_diag_.data();
        a.node_col = col_.data();
        a.node_row_ptr = row_ptr_.data();
        a.node_row = rows_.data();
        a.node_value_ptr = value_ptr_.data();
        a.node_value = values_.data();
        validate(static_cast<Index>(rows_.shape(0)), static_cast<Index>(values_.shape(0)));
    }

    const softbody::Factor& factor() const { return factor_; }
    nb::object handle() const { return handle_; }

private:
    void validate(Index row_count, Index value_count) {
        const softbody::Factor& a = factor_;
        const Index n = a.size;
        check_indices(a.perm, n, 0, n, "perm");
        std::vector<char> seen(static_cast<size_t>(n), 0);
        for (Index r = 0; r < n; ++r) {
            if (seen[static_cast<size_t>(a.perm[r])]) fail("perm is not a permutation");
            seen[static_cast<size_t>(a.perm[r])] = 1;
        }
        if (a.node_col[0] != 0 || a.node_col[a.node_count] != n)
            fail("node_col must run from 0 to " + std::to_string(n));
        if (a.node_row_ptr[0] != 0 || a.node_row_ptr[a.node_count] != row_count)
            fail("node_row_ptr must run from 0 to the length of node_row");
        if (a.node_value_ptr[0] != 0 || a.node_value_ptr[a.node_count] > value_count)
            fail("node_value_ptr must run from 0 to at most the length of node_value");
        for (Index s = 0; s < a.node_count; ++s) {
            const Index c0 = a.node_col[s], c1 = a.node_col[s + 1];
            const Index r0 = a.node_row_ptr[s], r1 = a.node_row_ptr[s + 1];
            const Index width = c1 - c0, height = r1 - r0;
            const std::string node = "supernode " + std::to_string(s);
            if (width < 1) fail("node_col must increase: " + node + " has no columns");
            if (height < width) fail(node + " has fewer rows than columns");
            // height <= len(node_row) and width <= N, arrays in memory: the product fits
            if (a.node_value_ptr[s] < 0 || a.node_value_ptr[s + 1] - a.node_value_ptr[s] != height * width)
                fail(node + "'s values are not a (rows, columns) block");
            for (Index p = 0; p < height; ++p) {
                const Index r = a.node_row[r0 + p];
                const bool ok = p < width ? r == c0 + p : r >= c1 && r < n;
                if (!ok) fail(node + "'s rows must be its columns, then rows below them in [" +
                              std::to_string(c1) + ", " + std::to_string(n) + ")");
            }
        }
    }

    nb::object handle_;  // keeps the Projective bundle (and so its arrays) alive
    softbody::Factor factor_;
    ConstI64 perm_, col_, row_ptr_, rows_, value_ptr_;
    ConstF64 inv_diag_, values_;
};

/// softbody._core.ProjectiveSolver: projective dynamics' time loop, its scratch, and the
/// factor it solves with (set for each step size by the caller, which builds it).
class ProjectiveSolver {
public:
    ProjectiveSolver(nb::object model, std::optional<Index> hash_capacity, int threads)
        : handle_(model),
          model_(nb::cast<const CoreModel&>(model)),
          buffers_(model_.model(), 6, checked_capacity(model_.model(), hash_capacity)),
          threads_(threads, model_.model().body_count) {
        threads_.attach(buffers_.lanes_view);
        w_.lanes = buffers_.lanes_view;
        w_.f = buffers_.row(0);
        w_.q0 = buffers_.row(1);
        w_.v0 = buffers_.row(2);
        w_.y = buffers_.row(3);
        w_.rhs = buffers_.row(4);
        w_.x = buffers_.row(5);
        w_.gas = buffers_.gas;
        w_.contact = buffers_.contact;
    }

    /// Checked first: a refused factor leaves the one set before.
    void set_factor(nb::handle factor) {
        CoreFactor checked(factor, model_.model().particle_count);
        factor_.reset();
        factor_.emplace(std::move(checked));
    }

    nb::object factor() const { return factor_ ? factor_->handle() : nb::none(); }

    std::tuple<int, Index, Index, double> simulate(Index steps, double t0, double dt,
                                                   Index iterations, nb::handle control,
                                                   nb::handle q, nb::handle qd,
                                                   nb::handle collider_q, nb::handle collider_rot,
                                                   nb::handle collider_impulse, double max_speed,
                                                   double ratio_min, double ratio_max) {
        const softbody::Model& m = model_.model();
        if (iterations < 1) fail("iterations must be >= 1");
        if (!factor_) fail("no projective factor set (set_factor)");
        if (factor_->factor().dt != dt)
            fail("the projective factor was built for dt = " + std::to_string(factor_->factor().dt) +
                 " s, not " + std::to_string(dt) + " s");
        CheckedRun run = checked_run(m, steps, t0, dt, q, qd, collider_q, collider_rot,
                                     collider_impulse, max_speed, ratio_min, ratio_max);
        run.params.iterations = iterations;
        CoreControl c(m, control);
        softbody::RunResult r;
        {
            nb::gil_scoped_release release;
            r = softbody::kernels().simulate_projective(m, c.view, run.params, run.state,
                                                        factor_->factor(), w_);
        }
        return {r.status, r.steps_done, r.where, r.value};
    }

    Index hash_capacity() const { return buffers_.contact.hash_capacity; }
    int threads() const { return threads_.count(); }

private:
    nb::object handle_;  // keeps the CoreModel (and so the model's arrays) alive
    const CoreModel& model_;
    Buffers buffers_;
    SolverThreads threads_;
    softbody::ProjectiveBuffers w_;
    std::optional<CoreFactor> factor_;
};

/// Checked views of a multigrid hierarchy (softbody.integrators.multigrid.Multigrid) for a
/// model, and the V-cycle's scratch: every offset, CSR row range and column checked once,
/// so that no kernel reads or writes outside an array.
class CheckedMultigrid {
public:
    CheckedMultigrid(const softbody::Model& m, nb::handle mg) {
        softbody::MultigridView& v = view;
        const Index n = m.particle_count;
        v.level_count = nb::cast<Index>(mg.attr("level_count"));
        const Index levels = v.level_count;
        if (levels < 0) fail("multigrid level_count must be >= 0");
        v.coarse_dense = nb::cast<Index>(mg.attr("coarse_dense")) != 0;
        v.level_size = i64(mg, "level_size", {levels + 1});
        v.vec_offset = i64(mg, "vec_offset", {levels + 2});
        if (v.level_size[0] != n)
            fail("multigrid level_size[0] must be the particle count " + std::to_string(n) +
                 ", got " + std::to_string(v.level_size[0]));
        if (v.vec_offset[0] != 0) fail("multigrid vec_offset[0] must be 0");
        for (Index l = 0; l <= levels; ++l) {
            if (v.level_size[l] < 0) fail("multigrid level_size must be >= 0");
            if (v.vec_offset[l + 1] != v.vec_offset[l] + v.level_size[l])
                fail("multigrid vec_offset must be the running sum of level_size");
        }
        total_ = v.vec_offset[levels + 1];
        v.a_row_offset = i64(mg, "a_row_offset", {levels + 1});
        v.a_nz_offset = i64(mg, "a_nz_offset", {levels + 1});
        const ConstI64 a_indptr = keep(attribute<ConstI64>(mg, "a_indptr", {-1}));
        const ConstI64 a_indices = keep(attribute<ConstI64>(mg, "a_indices", {-1}));
        v.a_indptr = a_indptr.data();
        v.a_indices = a_indices.data();
        const Index a_nnz = static_cast<Index>(a_indices.shape(0));
        v.a_data = f64(mg, "a_data", {a_nnz});
        v.a_diag = f64(mg, "a_diag", {total_});
        for (Index l = 0; l <= levels; ++l)
            check_csr(v.a_indptr, static_cast<Index>(a_indptr.shape(0)), v.a_row_offset[l],
                      v.a_nz_offset[l], v.a_indices, a_nnz, v.level_size[l], v.level_size[l],
                      "multigrid A level " + std::to_string(l));
        const Index p_levels = std::max<Index>(levels, 1);
        v.p_row_offset = i64(mg, "p_row_offset", {p_levels});
        v.p_nz_offset = i64(mg, "p_nz_offset", {p_levels});
        const ConstI64 p_indptr = keep(attribute<ConstI64>(mg, "p_indptr", {-1}));
        const ConstI64 p_indices = keep(attribute<ConstI64>(mg, "p_indices", {-1}));
        v.p_indptr = p_indptr.data();
        v.p_indices = p_indices.data();
        const Index p_nnz = static_cast<Index>(p_indices.shape(0));
        v.p_data = f64(mg, "p_data", {p_nnz});
        for (Index l = 0; l < levels; ++l)
            check_csr(v.p_indptr, static_cast<Index>(p_indptr.shape(0)), v.p_row_offset[l],
                      v.p_nz_offset[l], v.p_indices, p_nnz, v.level_size[l], v.level_size[l + 1],
                      "multigrid P level " + std::to_string(l));
        const Index coarse = v.level_size[levels];
        v.coarse_cholesky = v.coarse_dense ? f64(mg, "coarse_cholesky", {coarse, coarse}) : nullptr;
        const Index entries = 2 * m.spring_count;
        v.vertex_spring_ptr = i64(mg, "vertex_spring_ptr", {n + 1});
        if (v.vertex_spring_ptr[0] != 0 || v.vertex_spring_ptr[n] != entries)
            fail("multigrid vertex_spring_ptr must run from 0 to twice the spring count");
        for (Index i = 0; i < n; ++i)
            if (v.vertex_spring_ptr[i] > v.vertex_spring_ptr[i + 1])
                fail("multigrid vertex_spring_ptr must not decrease");
        v.vertex_spring = i64(mg, "vertex_spring", {entries});
        v.vertex_neighbor = i64(mg, "vertex_neighbor", {entries});
        check_indices(v.vertex_spring, entries, 0, m.spring_count, "multigrid vertex_spring");
        check_indices(v.vertex_neighbor, entries, 0, n, "multigrid vertex_neighbor");
        const size_t n9 = static_cast<size_t>(9 * n), t3 = static_cast<size_t>(3 * total_);
        scratch_ = {std::vector<double>(n9), std::vector<double>(n9),
                    std::vector<double>(static_cast<size_t>(5 * entries)), std::vector<double>(t3),
                    std::vector<double>(t3), std::vector<double>(t3)};
        v.block = scratch_[0].data();
        v.block_inv = scratch_[1].data();
        v.entry_coef = scratch_[2].data();
        v.x = scratch_[3].data();
        v.b = scratch_[4].data();
        v.r = scratch_[5].data();
    }

    softbody::MultigridView view;

private:
    // Rows [r0, r0 + rows] of indptr within it, non-decreasing, their entries (offset z0)
    // within the column array, and every column in [0, cols).
    static void check_csr(const Index* indptr, Index indptr_size, Index r0, Index z0,
                          const Index* cols, Index nnz, Index rows, Index col_count,
                          const std::string& name) {
        if (r0 < 0 || r0 + rows + 1 > indptr_size || z0 < 0)
            fail(name + ": row or entry offset outside its arrays");
        for (Index i = 0; i < rows; ++i)
            if (indptr[r0 + i] > indptr[r0 + i + 1]) fail(name + ": indptr decreases");
        const Index first = indptr[r0], last = indptr[r0 + rows];
        if (first < 0 || z0 + last > nnz) fail(name + ": entries outside its arrays");
        check_indices(cols + z0 + first, last - first, 0, col_count, name + " columns");
    }
    template <typename Array>
    Array keep(Array a) {
        if constexpr (std::is_same_v<Array, ConstI64>)
            keep_i_.push_back(a);
        else
            keep_f_.push_back(a);
        return a;
    }
    const Index* i64(nb::handle mg, const char* name, std::vector<Index> shape) {
        return keep(attribute<ConstI64>(mg, name, shape)).data();
    }
    const double* f64(nb::handle mg, const char* name, std::vector<Index> shape) {
        return keep(attribute<ConstF64>(mg, name, shape)).data();
    }

    Index total_ = 0;
    std::vector<std::vector<double>> scratch_;
    std::vector<ConstF64> keep_f_;
    std::vector<ConstI64> keep_i_;
};

/// softbody._core.ImplicitSolver: backward Euler and BDF2, their time loop, scratch and
/// history (BDF2's previous step, CG's last dv and its statistics).
class ImplicitSolver {
public:
    ImplicitSolver(nb::object model, nb::object multigrid, std::optional<Index> hash_capacity,
                   int threads)
        : handle_(model),
          model_(nb::cast<const CoreModel&>(model)),
          buffers_(model_.model(), 13, checked_capacity(model_.model(), hash_capacity)),
          threads_(threads, model_.model().body_count) {
        const softbody::Model& m = model_.model();
        threads_.attach(buffers_.lanes_view);
        if (!multigrid.is_none()) multigrid_.emplace(m, multigrid);
        mg_handle_ = multigrid;
        double** rows[] = {&w_.f, &w_.q0, &w_.v0, &w_.qs, &w_.vs, &w_.ky, &w_.cg_r,
                           &w_.cg_z, &w_.cg_p, &w_.cg_ap, &w_.cg_x, &w_.q_prev, &w_.v_prev};
        for (int k = 0; k < 13; ++k) *rows[k] = buffers_.row(k);
        const size_t s = static_cast<size_t>(m.spring_count), b = static_cast<size_t>(m.body_count);
        per_spring_ = {std::vector<double>(3 * s), std::vector<double>(s), std::vector<double>(s)};
        per_body_ = {std::vector<double>(b), std::vector<double>(b)};
        diag_.assign(static_cast<size_t>(m.particle_count), 0.0);
        w_.spring_u = per_spring_[0].data();
        w_.spring_a = per_spring_[1].data();
        w_.spring_b = per_spring_[2].data();
        w_.body_dpdv = per_body_[0].data();
        w_.body_pnet = per_body_[1].data();
        w_.cg_diag = diag_.data();
        w_.contacts_acted = &flags_[0];
        w_.cg_stats = &flags_[1];
        w_.gas = buffers_.gas;
        w_.lanes = buffers_.lanes_view;
        w_.contact = buffers_.contact;
    }

    std::tuple<int, Index, Index, double> simulate(
        bool bdf2, Index steps, double t0, double dt, nb::handle control, nb::handle q,
        nb::handle qd, nb::handle collider_q, nb::handle collider_rot, nb::handle collider_impulse,
        double max_speed, double ratio_min, double ratio_max, double tolerance,
        Index max_iterations, bool history) {
        const softbody::Model& m = model_.model();
        if (!(std::isfinite(tolerance) && tolerance > 0.0 && tolerance < 1.0))
            fail("tolerance must lie in (0, 1)");
        if (max_iterations < 1) fail("max_iterations must be >= 1");
        CheckedRun run = checked_run(m, steps, t0, dt, q, qd, collider_q, collider_rot,
                                     collider_impulse, max_speed, ratio_min, ratio_max);
        CoreControl c(m, control);
        softbody::ImplicitParams ip;
        ip.bdf2 = bdf2;
        ip.tolerance = tolerance;
        ip.max_iterations = max_iterations;
        ip.history = history;
        const softbody::MultigridView* mg = multigrid_ ? &multigrid_->view : nullptr;
        softbody::RunResult r;
        {
            nb::gil_scoped_release release;
            r = softbody::kernels().simulate_implicit(m, c.view, run.params, ip, run.state, w_,
                                                      mg);
        }
        return {r.status, r.steps_done, r.where, r.value};
    }

    /// z (N, 3) = P^-1 r: the preconditioner for step h [s] with its blocks at q (N, 3) at
    /// time t [s] (the multigrid hierarchy's values must be set for h). For tests.
    nb::ndarray<nb::numpy, double> apply_preconditioner(nb::handle control, double t, double h,
                                                        ConstF64 q, ConstF64 r) {
        const softbody::Model& m = model_.model();
        check_shape(q, "q", {m.particle_count, 3});
        check_shape(r, "r", {m.particle_count, 3});
        if (!(std::isfinite(h) && h > 0.0)) fail("h must be finite and > 0");
        CoreControl c(m, control);
        const size_t n3 = static_cast<size_t>(3 * m.particle_count);
        std::copy(q.data(), q.data() + n3, w_.q0);
        double* z = new double[n3 > 0 ? n3 : 1];
        nb::capsule owner(z, [](void* p) noexcept { delete[] static_cast<double*>(p); });
        {
            nb::gil_scoped_release release;
            softbody::kernels().apply_preconditioner(
                m, c.view, t, h, w_, multigrid_ ? &multigrid_->view : nullptr, r.data(), z);
        }
        size_t shape[2] = {static_cast<size_t>(m.particle_count), 3};
        return nb::ndarray<nb::numpy, double>(z, 2, shape, owner);
    }

    /// (steps, CG iterations in all, most in one step) since the last clear_stats.
    std::tuple<Index, Index, Index> cg_stats() const { return {flags_[1], flags_[2], flags_[3]}; }
    void clear_stats() { flags_[1] = flags_[2] = flags_[3] = 0; }
    Index hash_capacity() const { return buffers_.contact.hash_capacity; }
    bool uses_multigrid() const { return multigrid_.has_value(); }
    int threads() const { return threads_.count(); }

private:
    nb::object handle_;  // keeps the CoreModel (and so the model's arrays) alive
    const CoreModel& model_;
    nb::object mg_handle_;  // keeps the hierarchy's arrays alive
    std::optional<CheckedMultigrid> multigrid_;
    Buffers buffers_;
    SolverThreads threads_;
    std::vector<std::vector<double>> per_spring_, per_body_;
    std::vector<double> diag_;
    Index flags_[4] = {0, 0, 0, 0};  // contacts acted, then the CG statistics
    softbody::ImplicitBuffers w_;
};

/// x (N, 3) = A^-1 b by a projective factor's two triangular solves: for tests of the
/// factor.
nb::ndarray<nb::numpy, double> solve_factor(const CoreModel& core, nb::handle factor,
                                            ConstF64 b) {
    const softbody::Model& m = core.model();
    check_shape(b, "b", {m.particle_count, 3});
    CoreFactor checked(factor, m.particle_count);
    const size_t n3 = static_cast<size_t>(3 * m.particle_count);
    std::vector<double> scratch(n3 > 0 ? n3 : 1);
    double* x = new double[n3 > 0 ? n3 : 1];
    nb::capsule owner(x, [](void* p) noexcept { delete[] static_cast<double*>(p); });
    {
        nb::gil_scoped_release release;
        softbody::kernels().projective_solve(checked.factor(), b.data(), scratch.data(), x);
    }
    size_t shape[2] = {static_cast<size_t>(m.particle_count), 3};
    return nb::ndarray<nb::numpy, double>(x, 2, shape, owner);
}

/// One V-cycle z = V(r) of a hierarchy for r (N, 3): for tests of the preconditioner.
nb::ndarray<nb::numpy, double> apply_multigrid(const CoreModel& core, nb::handle mg, ConstF64 r) {
    const softbody::Model& m = core.model();
    check_shape(r, "r", {m.particle_count, 3});
    CheckedMultigrid checked(m, mg);
    const size_t n3 = static_cast<size_t>(3 * m.particle_count);
    double* z = new double[n3 > 0 ? n3 : 1];
    nb::capsule owner(z, [](void* p) noexcept { delete[] static_cast<double*>(p); });
    {
        nb::gil_scoped_release release;
        softbody::kernels().apply_multigrid(checked.view, r.data(), z);
    }
    size_t shape[2] = {static_cast<size_t>(m.particle_count), 3};
    return nb::ndarray<nb::numpy, double>(z, 2, shape, owner);
}

/// Forces, volumes, dV/dx and pressures at (q, qd, t): for diagnostics and tests.
nb::tuple eval_forces(const CoreModel& core, nb::handle control, double t, ConstF64 q,
                      ConstF64 qd) {
    const softbody::Model& m = core.model();
    check_shape(q, "q", {m.particle_count, 3});
    check_shape(qd, "qd", {m.particle_count, 3});
    CoreControl c(m, control);
    Buffers b(m, 1);
    {
        nb::gil_scoped_release release;
        softbody::kernels().eval_forces(m, c.view, t, q.data(), qd.data(), b.gas,
                                        b.lanes_view, b.row(0));
    }
    auto out = [](const double* data, std::vector<size_t> shape) {
        size_t count = 1;
        for (size_t s : shape) count *= s;
        double* copy = new double[count];
        std::copy(data, data + count, copy);
        nb::capsule owner(copy, [](void* p) noexcept { delete[] static_cast<double*>(p); });
        return nb::ndarray<nb::numpy, double>(copy, shape.size(), shape.data(), owner);
    };
    const size_t n = static_cast<size_t>(m.particle_count), nb_ = static_cast<size_t>(m.body_count);
    return nb::make_tuple(out(b.row(0), {n, 3}), out(b.gas.volume, {nb_}),
                          out(b.gas.pressure, {nb_}), out(b.gas.volume_gradient, {n, 3}));
}

/// Every body's volume by its own method at q, with dV/dx when asked.
nb::tuple eval_volumes(const CoreModel& core, nb::handle control, double t, ConstF64 q) {
    const softbody::Model& m = core.model();
    check_shape(q, "q", {m.particle_count, 3});
    CoreControl c(m, control);
    Buffers b(m, 0);
    {
        nb::gil_scoped_release release;
        softbody::kernels().eval_gas(m, c.view, t, q.data(), b.gas);
    }
    auto out = [](const double* data, std::vector<size_t> shape) {
        size_t count = 1;
        for (size_t s : shape) count *= s;
        double* copy = new double[count];
        std::copy(data, data + count, copy);
        nb::capsule owner(copy, [](void* p) noexcept { delete[] static_cast<double*>(p); });
        return nb::ndarray<nb::numpy, double>(copy, shape.size(), shape.data(), owner);
    };
    const size_t n = static_cast<size_t>(m.particle_count), nb_ = static_cast<size_t>(m.body_count);
    return nb::make_tuple(out(b.gas.volume, {nb_}), out(b.gas.pressure, {nb_}),
                          out(b.gas.volume_gradient, {n, 3}));
}

/// One pass of the soft-soft contacts on q, qd in place (for tests of the response);
/// returns the hash entries the surface contacts needed beyond hash_capacity, or 0.
Index soft_contacts(const CoreModel& core, F64 q, F64 qd, std::optional<Index> hash_capacity) {
    const softbody::Model& m = core.model();
    check_shape(q, "q", {m.particle_count, 3});
    check_shape(qd, "qd", {m.particle_count, 3});
    Buffers b(m, 0, checked_capacity(m, hash_capacity));
    nb::gil_scoped_release release;
    return softbody::kernels().soft_contacts(m, q.data(), qd.data(), b.contact);
}

/// The implicit schemes' matrix-free product, also behind the stability estimate.
void apply_jacobians(const CoreModel& core, nb::handle control, ConstF64 q, ConstF64 p,
                     double alpha_m, double alpha_c, double alpha_k, ConstF64 u, ConstF64 a,
                     ConstF64 b, ConstF64 gradient, ConstF64 dpdv, ConstF64 pnet, F64 out,
                     bool attachments) {
    const softbody::Model& m = core.model();
    const Index n = m.particle_count, s = m.spring_count, nb_ = m.body_count;
    check_shape(q, "q", {n, 3});
    check_shape(p, "p", {n, 3});
    check_shape(u, "spring_u", {s, 3});
    check_shape(a, "spring_a", {s});
    check_shape(b, "spring_b", {s});
    check_shape(gradient, "volume_gradient", {n, 3});
    check_shape(dpdv, "body_dpdv", {nb_});
    check_shape(pnet, "body_pnet", {nb_});
    check_shape(out, "out", {n, 3});
    CoreControl c(m, control);
    nb::gil_scoped_release release;
    softbody::kernels().apply_jacobians(m, c.view, q.data(), p.data(), alpha_m, alpha_c, alpha_k,
                                        u.data(), a.data(), b.data(), gradient.data(),
                                        dpdv.data(), pnet.data(), attachments, out.data());
}

/// Volumes of bodies given by plain arrays (before a Model exists, or by another method).
nb::ndarray<nb::numpy, double> body_volumes(ConstF64 q, ConstI64 tri_indices,
                                            ConstI64 body_particle_range, ConstI64 body_tri_range,
                                            ConstI64 body_volume_method, ConstI64 body_mc_range,
                                            ConstF64 mc_samples) {
    softbody::Model m;
    check_shape(q, "q", {-1, 3});
    check_shape(tri_indices, "tri_indices", {-1, 3});
    check_shape(body_particle_range, "body_particle_range", {-1, 2});
    m.particle_count = static_cast<Index>(q.shape(0));
    m.tri_count = static_cast<Index>(tri_indices.shape(0));
    m.body_count = static_cast<Index>(body_particle_range.shape(0));
    check_shape(body_tri_range, "body_tri_range", {m.body_count, 2});
    check_shape(body_volume_method, "body_volume_method", {m.body_count});
    check_shape(body_mc_range, "body_mc_range", {m.body_count, 2});
    check_shape(mc_samples, "mc_samples", {-1, 2});
    m.mc_count = static_cast<Index>(mc_samples.shape(0));
    m.tri_indices = tri_indices.data();
    m.body_particle_range = body_particle_range.data();
    m.body_tri_range = body_tri_range.data();
    m.body_volume_method = body_volume_method.data();
    m.body_mc_range = body_mc_range.data();
    m.mc_samples = mc_samples.data();
    check_indices(m.tri_indices, 3 * m.tri_count, 0, m.particle_count, "tri_indices");
    check_ranges(m.body_particle_range, m.body_count, m.particle_count, "body_particle_range");
    check_ranges(m.body_tri_range, m.body_count, m.tri_count, "body_tri_range");
    check_ranges(m.body_mc_range, m.body_count, m.mc_count, "body_mc_range");
    check_indices(m.body_volume_method, m.body_count, 0, 5, "body_volume_method");
    for (Index b = 0; b < m.body_count; ++b)
        if (m.body_tri_range[2 * b + 1] > m.body_tri_range[2 * b] &&
            m.body_particle_range[2 * b + 1] == m.body_particle_range[2 * b])
            fail("body " + std::to_string(b) + " has triangles but no particles");
    const size_t count = static_cast<size_t>(m.body_count);
    double* volume = new double[count > 0 ? count : 1];
    nb::capsule owner(volume, [](void* p) noexcept { delete[] static_cast<double*>(p); });
    std::vector<double> lo(3 * count), hi(3 * count);
    softbody::BodyGas gas;
    gas.volume = volume;
    gas.lo = lo.data();
    gas.hi = hi.data();
    {
        nb::gil_scoped_release release;
        softbody::kernels().eval_volumes(m, q.data(), gas);
    }
    size_t shape[1] = {count};
    return nb::ndarray<nb::numpy, double>(volume, 1, shape, owner);
}

/// The image and depth buffer of a frame, checked: (H, W, 3) and (H, W) float64.
softbody::render::Image frame_image(F64 image, F64 zbuffer) {
    check_shape(image, "image", {-1, -1, 3});
    const Index h = static_cast<Index>(image.shape(0)), w = static_cast<Index>(image.shape(1));
    check_shape(zbuffer, "zbuffer", {h, w});
    return {image.data(), zbuffer.data(), h, w};
}

void raster_clear(F64 image, F64 zbuffer, ConstF64 top, ConstF64 bottom) {
    const auto im = frame_image(image, zbuffer);
    check_shape(top, "top", {3});
    check_shape(bottom, "bottom", {3});
    nb::gil_scoped_release release;
    softbody::render::clear(im, top.data(), bottom.data());
}

void raster_triangles(ConstF64 screen, ConstI64 faces, ConstF64 colors, double near, F64 image,
                      F64 zbuffer) {
    const auto im = frame_image(image, zbuffer);
    check_shape(screen, "screen", {-1, 3});
    const Index v = static_cast<Index>(screen.shape(0));
    check_shape(faces, "faces", {-1, 3});
    check_shape(colors, "colors", {v, 3});
    const Index f = static_cast<Index>(faces.shape(0));
    check_indices(faces.data(), 3 * f, 0, v, "faces");
    nb::gil_scoped_release release;
    softbody::render::triangles(im, screen.data(), faces.data(), f, colors.data(), near);
}

void raster_lines(ConstF64 screen_a, ConstF64 screen_b, ConstF64 colors, Index width, double near,
                  double depth_bias, F64 image, F64 zbuffer) {
    const auto im = frame_image(image, zbuffer);
    check_shape(screen_a, "screen_a", {-1, 3});
    const Index count = static_cast<Index>(screen_a.shape(0));
    check_shape(screen_b, "screen_b", {count, 3});
    check_shape(colors, "colors", {count, 3});
    if (width < 1 || width > 64) fail("line width must be from 1 to 64 pixels");
    nb::gil_scoped_release release;
    softbody::render::lines(im, screen_a.data(), screen_b.data(), count, colors.data(), width,
                            near, depth_bias);
}

void raster_downsample(F64 image, Index factor, nb::ndarray<std::uint8_t, nb::c_contig,
                       nb::device::cpu> out) {
    check_shape(image, "image", {-1, -1, 3});
    check_shape(out, "out", {-1, -1, 3});
    const Index h = static_cast<Index>(out.shape(0)), w = static_cast<Index>(out.shape(1));
    if (factor < 1 || h * factor > static_cast<Index>(image.shape(0)) ||
        w * factor > static_cast<Index>(image.shape(1)))
        fail("downsample: out times factor must fit in the image");
    const softbody::render::Image im{image.data(), nullptr, static_cast<Index>(image.shape(0)),
                                     static_cast<Index>(image.shape(1))};
    nb::gil_scoped_release release;
    softbody::render::downsample(im, factor, out.data(), h, w);
}

/// A vector handed to NumPy without a copy: the array owns it.
template <typename T>
nb::ndarray<nb::numpy, T> to_numpy(std::vector<T>&& v) {
    auto* owned = new std::vector<T>(std::move(v));
    nb::capsule owner(owned, [](void* p) noexcept { delete static_cast<std::vector<T>*>(p); });
    size_t shape[1] = {owned->size()};
    return nb::ndarray<nb::numpy, T>(owned->data(), 1, shape, owner);
}

/// A CSR or CSC index structure of an (n, n) matrix: indptr (n + 1,) from 0, not
/// decreasing, to len(indices); every index in [0, n).
Index checked_pattern(ConstI64 indptr, ConstI64 indices, const char* what) {
    check_shape(indptr, std::string(what) + " indptr", {-1});
    check_shape(indices, std::string(what) + " indices", {-1});
    const Index n = static_cast<Index>(indptr.shape(0)) - 1;
    if (n < 1) fail(std::string(what) + ": the matrix is empty");
    const Index* p = indptr.data();
    if (p[0] != 0 || p[n] != static_cast<Index>(indices.shape(0)))
        fail(std::string(what) + " indptr must run from 0 to the number of entries");
    for (Index k = 0; k < n; ++k)
        if (p[k + 1] < p[k]) fail(std::string(what) + " indptr decreases");
    check_indices(indices.data(), p[n], 0, n, std::string(what) + " indices");
    return n;
}

nb::ndarray<nb::numpy, Index> plan_dissection_order(ConstI64 indptr, ConstI64 indices,
                                                    ConstF64 points, Index leaf) {
    const Index n = checked_pattern(indptr, indices, "pattern");
    check_shape(points, "points", {n, 3});
    if (leaf < 1) fail("leaf must be >= 1");
    std::vector<Index> order;
    {
        nb::gil_scoped_release release;
        order = softbody::plan::dissection_order(n, indptr.data(), indices.data(),
                                                 points.data(), leaf);
    }
    return to_numpy(std::move(order));
}

nb::tuple plan_strict_lower(ConstI64 indptr, ConstI64 indices, ConstF64 data) {
    const Index n = checked_pattern(indptr, indices, "factor");
    check_shape(data, "factor data", {static_cast<Index>(indices.shape(0))});
    softbody::plan::Csc out;
    {
        nb::gil_scoped_release release;
        out = softbody::plan::strict_lower(n, indptr.data(), indices.data(), data.data());
    }
    return nb::make_tuple(to_numpy(std::move(out.indptr)), to_numpy(std::move(out.indices)),
                          to_numpy(std::move(out.data)));
}

nb::tuple plan_supernodes(ConstI64 indptr, ConstI64 indices, ConstF64 data) {
    const Index n = checked_pattern(indptr, indices, "factor");
    check_shape(data, "factor data", {static_cast<Index>(indices.shape(0))});
    for (Index j = 0; j < n; ++j)
        for (Index e = indptr.data()[j]; e < indptr.data()[j + 1]; ++e)
            if (indices.data()[e] <= j) fail("the factor must be strictly lower triangular");
    softbody::plan::Supernodes s;
    {
        nb::gil_scoped_release release;
        s = softbody::plan::supernodes(n, indptr.data(), indices.data(), data.data());
    }
    return nb::make_tuple(to_numpy(std::move(s.col)), to_numpy(std::move(s.row_ptr)),
                          to_numpy(std::move(s.rows)), to_numpy(std::move(s.value_ptr)),
                          to_numpy(std::move(s.values)));
}

}  // namespace

NB_MODULE(_core, mod) {
    mod.doc() = "softbody's compiled engine core (C++17): the step kernels.";
    mod.def("simd_paths", &softbody::available_simd,
            "Instruction sets this build has and this CPU runs, best last.");
    mod.def("simd_path", [] { return std::string(softbody::kernels().name); },
            "The instruction set the kernels use now.");
    mod.def("select_simd", &softbody::select_simd, nb::arg("name"),
            "Use the named instruction set ('scalar', 'avx2', 'avx512' or 'auto'); False "
            "if this build or CPU lacks it.");

    nb::class_<CoreModel>(mod, "Model", "Checked views of a Model's arrays (ModelData).")
        .def(nb::init<nb::handle>(), nb::arg("data"))
        .def_prop_ro("particle_count", [](const CoreModel& c) { return c.model().particle_count; })
        .def_prop_ro(
            "lane_slots",
            [](const CoreModel& c) {
                const softbody::Model& m = c.model();
                const Index g = m.group_count;
                return std::make_tuple(m.ring_slot_start[g], m.spring_slot_start[g],
                                       m.face_slot_start[g]);
            },
            "Slots of the vertex-major tables, over all groups of 8 particles: (ring, springs "
            "off the rings, faces outside a fan).");

    nb::class_<ExplicitSolver>(mod, "ExplicitSolver",
                               "The explicit schemes' time loop with its scratch buffers.")
        .def(nb::init<nb::object, std::optional<Index>, int>(), nb::arg("model"),
             nb::arg("hash_capacity") = nb::none(), nb::arg("threads") = 1,
             "hash_capacity: entries of the surface contacts' spatial hash (default 8 per "
             "triangle); a run that needs more returns NEED_HASH with the count needed. "
             "threads: > 1 runs the force pass on that many threads, deterministically.")
        .def_prop_ro("threads", &ExplicitSolver::threads, "Threads of the force pass.")
        .def_prop_ro("hash_capacity", &ExplicitSolver::hash_capacity,
                     "Entries the surface contacts' spatial hash holds (0 without them).")
        .def("simulate", &ExplicitSolver::simulate, nb::arg("scheme"), nb::arg("steps"),
             nb::arg("t0"), nb::arg("dt"), nb::arg("control"), nb::arg("q"), nb::arg("qd"),
             nb::arg("collider_q"), nb::arg("collider_rot"), nb::arg("collider_impulse"),
             nb::arg("max_speed"), nb::arg("ratio_min"), nb::arg("ratio_max"),
             "Advance q, qd in place; returns (status, steps_done, index, value).");

    nb::class_<ProjectiveSolver>(mod, "ProjectiveSolver",
                                 "Projective dynamics' time loop with its scratch buffers and "
                                 "the factored matrix it solves with.")
        .def(nb::init<nb::object, std::optional<Index>, int>(), nb::arg("model"),
             nb::arg("hash_capacity") = nb::none(), nb::arg("threads") = 1,
             "hash_capacity, threads: as for ExplicitSolver (threads run the pass that "
             "measures the volumes and dV/dx).")
        .def_prop_ro("threads", &ProjectiveSolver::threads, "Threads of the force pass.")
        .def("set_factor", &ProjectiveSolver::set_factor, nb::arg("factor"),
             "Solve with this Projective factor (integrators.projective.build_projective for "
             "the model and the step); checked once here and kept alive.")
        .def_prop_ro("factor", &ProjectiveSolver::factor, "The factor set, or None.")
        .def_prop_ro("hash_capacity", &ProjectiveSolver::hash_capacity,
                     "Entries the surface contacts' spatial hash holds (0 without them).")
        .def("simulate", &ProjectiveSolver::simulate, nb::arg("steps"), nb::arg("t0"),
             nb::arg("dt"), nb::arg("iterations"), nb::arg("control"), nb::arg("q"),
             nb::arg("qd"), nb::arg("collider_q"), nb::arg("collider_rot"),
             nb::arg("collider_impulse"), nb::arg("max_speed"), nb::arg("ratio_min"),
             nb::arg("ratio_max"),
             "Advance q, qd in place by steps steps of dt (the factor's), iterations "
             "local-global iterations each; returns (status, steps_done, index, value).");

    nb::class_<ImplicitSolver>(mod, "ImplicitSolver",
                               "Backward Euler and BDF2 with their scratch, BDF2's previous "
                               "step and CG's statistics.")
        .def(nb::init<nb::object, nb::object, std::optional<Index>, int>(), nb::arg("model"),
             nb::arg("multigrid").none() = nb::none(), nb::arg("hash_capacity") = nb::none(),
             nb::arg("threads") = 1,
             "multigrid: a softbody.integrators.multigrid.Multigrid for this model (checked "
             "once; its values are read at each step, so set_multigrid_step on it takes "
             "effect), or None for the Jacobi preconditioner. threads: as for ExplicitSolver "
             "(threads run the force pass at each step's start).")
        .def_prop_ro("threads", &ImplicitSolver::threads, "Threads of the force pass.")
        .def_prop_ro("hash_capacity", &ImplicitSolver::hash_capacity)
        .def_prop_ro("uses_multigrid", &ImplicitSolver::uses_multigrid)
        .def_prop_ro("cg_stats", &ImplicitSolver::cg_stats,
                     "(implicit steps, CG iterations in all, most in one step) since the last "
                     "clear_stats().")
        .def("clear_stats", &ImplicitSolver::clear_stats)
        .def("apply_preconditioner", &ImplicitSolver::apply_preconditioner,
             nb::arg("control"), nb::arg("t"), nb::arg("h"), nb::arg("q").noconvert(),
             nb::arg("r").noconvert(),
             "z (N, 3) = P^-1 r, the solve's preconditioner for step h with its blocks at q "
             "(N, 3); its hierarchy's values must be set for h.")
        .def("simulate", &ImplicitSolver::simulate, nb::arg("bdf2"), nb::arg("steps"),
             nb::arg("t0"), nb::arg("dt"), nb::arg("control"), nb::arg("q"), nb::arg("qd"),
             nb::arg("collider_q"), nb::arg("collider_rot"), nb::arg("collider_impulse"),
             nb::arg("max_speed"), nb::arg("ratio_min"), nb::arg("ratio_max"),
             nb::arg("tolerance"), nb::arg("max_iterations"), nb::arg("history"),
             "Advance q, qd in place by backward Euler (or BDF2); history: the solver holds "
             "the step before q, qd. Returns (status, steps_done, index, value).");
    mod.def("solve_factor", &solve_factor, nb::arg("model"), nb::arg("factor"),
            nb::arg("b").noconvert(),
            "x (N, 3) = A^-1 b by a projective factor's two triangular solves.");
    mod.def("apply_multigrid", &apply_multigrid, nb::arg("model"), nb::arg("multigrid"),
            nb::arg("r").noconvert(), "z (N, 3) = one V-cycle of the hierarchy for r (N, 3).");

    mod.def("eval_forces", &eval_forces, nb::arg("model"), nb::arg("control"), nb::arg("t"),
            nb::arg("q").noconvert(), nb::arg("qd").noconvert(),
            "(f (N, 3) [N], volume (B,) [m^3], pressure (B,) [Pa], dV/dx (N, 3) [m^2]).");
    mod.def("apply_jacobians", &apply_jacobians, nb::arg("model"), nb::arg("control"),
            nb::arg("q").noconvert(), nb::arg("p").noconvert(), nb::arg("alpha_m"),
            nb::arg("alpha_c"), nb::arg("alpha_k"), nb::arg("spring_u").noconvert(),
            nb::arg("spring_a").noconvert(), nb::arg("spring_b").noconvert(),
            nb::arg("volume_gradient").noconvert(), nb::arg("body_dpdv").noconvert(),
            nb::arg("body_pnet").noconvert(), nb::arg("out").noconvert(),
            nb::arg("attachments") = true,
            "out (N, 3) = alpha_m M p + alpha_c C p + alpha_k K p (C = df/dv, K = df/dx).");
    mod.def("soft_contacts", &soft_contacts, nb::arg("model"), nb::arg("q").noconvert(),
            nb::arg("qd").noconvert(), nb::arg("hash_capacity") = nb::none(),
            "One pass of the model's soft-soft contacts on q, qd (N, 3) in place; returns "
            "the hash entries the surface contacts needed when they did not fit, else 0.");
    mod.def("body_volumes", &body_volumes, nb::arg("q").noconvert(),
            nb::arg("tri_indices").noconvert(), nb::arg("body_particle_range").noconvert(),
            nb::arg("body_tri_range").noconvert(), nb::arg("body_volume_method").noconvert(),
            nb::arg("body_mc_range").noconvert(), nb::arg("mc_samples").noconvert(),
            "Volume (B,) [m^3] of each body by its method, from plain arrays.");
    mod.def("plan_dissection_order", &plan_dissection_order, nb::arg("indptr").noconvert(),
            nb::arg("indices").noconvert(), nb::arg("points").noconvert(), nb::arg("leaf"),
            "Nested-dissection order (n,) of the CSR pattern of an (n, n) matrix, from "
            "points (n, 3).");
    mod.def("plan_strict_lower", &plan_strict_lower, nb::arg("indptr").noconvert(),
            nb::arg("indices").noconvert(), nb::arg("data").noconvert(),
            "(indptr, indices, data): the strictly lower part of a lower triangular CSC "
            "matrix, rows sorted in each column.");
    mod.def("plan_supernodes", &plan_supernodes, nb::arg("indptr").noconvert(),
            nb::arg("indices").noconvert(), nb::arg("data").noconvert(),
            "(col, row_ptr, rows, value_ptr, values): the supernodes of a strictly lower "
            "CSC factor with sorted rows.");
    mod.def("raster_clear", &raster_clear, nb::arg("image").noconvert(),
            nb::arg("zbuffer").noconvert(), nb::arg("top"), nb::arg("bottom"),
            "Fill image (H, W, 3) with a vertical gradient and reset zbuffer (H, W).");
    mod.def("raster_triangles", &raster_triangles, nb::arg("screen").noconvert(),
            nb::arg("faces").noconvert(), nb::arg("colors").noconvert(), nb::arg("near"),
            nb::arg("image").noconvert(), nb::arg("zbuffer").noconvert(),
            "Depth-tested, Gouraud-shaded triangles into image and zbuffer.");
    mod.def("raster_lines", &raster_lines, nb::arg("screen_a").noconvert(),
            nb::arg("screen_b").noconvert(), nb::arg("colors").noconvert(), nb::arg("width"),
            nb::arg("near"), nb::arg("depth_bias"), nb::arg("image").noconvert(),
            nb::arg("zbuffer").noconvert(), "Depth-tested line segments into image and zbuffer.");
    mod.def("raster_downsample", &raster_downsample, nb::arg("image").noconvert(),
            nb::arg("factor"), nb::arg("out").noconvert(),
            "Average factor x factor blocks of image into out (uint8).");
    mod.def("eval_volumes", &eval_volumes, nb::arg("model"), nb::arg("control"), nb::arg("t"),
            nb::arg("q").noconvert(),
            "(volume (B,) [m^3], pressure (B,) [Pa], dV/dx (N, 3) [m^2]) at time t [s].");
}
