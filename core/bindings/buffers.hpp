// A solver's scratch, allocated once, and a run's state arrays checked against the model.
#pragma once

#include "bindings/core_model.hpp"

namespace softbody::bindings {

/// Buckets of the surface contacts' spatial hash for T triangles: the smallest power of two
/// >= 2 T, at least 16.
inline Index hash_table_size(Index tris) {
    Index table = 16;
    while (table < 2 * std::max<Index>(tris, 1)) table <<= 1;
    return table;
}

/// The most entries per triangle the surface contacts' hash grows to: 512 grid cells (a
/// triangle 8 cells across; cells are as large as the longest edge at rest).
constexpr Index kMostEntriesPerTriangle = 512;

/// The most candidate pairs per triangle surface contacts with a thickness grow their list
/// to (collision/thick.hpp; a few tens where nothing has stretched).
constexpr Index kMostPairsPerTriangle = 4096;

/// A solver's scratch, allocated once: (N, 3) rows, per-body and per-collider arrays, and
/// for surface soft contacts (soft_contact_mode 2) the spatial hash with room for
/// `hash_capacity` entries.
class Buffers {
    static constexpr size_t gas_state_slots = softbody::kGasWorkSlots;

public:
    explicit Buffers(const softbody::Model& m, int rows, Index hash_capacity = 0) {
        const size_t n3 = static_cast<size_t>(3 * m.particles.count);
        const size_t b = static_cast<size_t>(m.bodies.count), c = static_cast<size_t>(m.colliders.count);
        rows_.assign(static_cast<size_t>(rows), std::vector<double>(n3, 0.0));
        per_body_.assign(11, std::vector<double>(3 * b, 0.0));
        per_collider_.assign(3, std::vector<double>(3 * c, 0.0));
        gradient_.assign(n3, 0.0);
        gas_work_.assign((gas_state_slots + 4) * b, 0.0);
        if (rows > 0) {  // the force pass's packed rows (a volume-only call needs none)
            const size_t lanes = static_cast<size_t>(8 * m.slots.group_count);
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
        gas.work = gas_work_.data();
        gas.flow_in = gas.work + gas_state_slots * b;
        gas.flow_in_t = gas.flow_in + b;
        gas.flow_out = gas.flow_in_t + b;
        gas.area = gas.flow_out + b;
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
        if (m.soft_contacts.mode == SoftContactMode::SURFACE) {
            const Index table = hash_table_size(m.triangles.count);
            hash_start_.assign(static_cast<size_t>(table + 1), 0);
            hash_count_.assign(static_cast<size_t>(table), 0);
            hash_entries_.assign(static_cast<size_t>(hash_capacity), 0);
            contact.hash_table = table;
            contact.hash_start = hash_start_.data();
            contact.hash_count = hash_count_.data();
            if (m.soft_contacts.thickness > 0.0) {  // collision/thick.hpp
                const size_t tris = static_cast<size_t>(m.triangles.count);
                thick_.assign(6 * n3 + 10 * (n3 / 3) + 6 * tris + 22, 0.0);
                contact.q_pre = thick_.data();
                contact.scale = contact.q_pre + n3;
                contact.tri_box = contact.scale + n3 / 3;
                contact.q_build = contact.tri_box + 6 * tris;
                contact.particle_box = contact.q_build + n3;
                contact.list_skin = contact.particle_box + 2 * n3;
                contact.q_collided = contact.list_skin + 22;
                contact.held_inv_mass = contact.q_collided + n3;
                contact.q_solved = contact.held_inv_mass + n3 / 3;
                contact.held = contact.q_solved + n3;
                thick_index_.assign(2 * tris + n3 / 3, 0);
                contact.tri_mark = thick_index_.data();
                contact.vertex_owner = contact.tri_mark + tris;
                contact.tri_owns = contact.vertex_owner + n3 / 3;
                pair_entries_.assign(static_cast<size_t>(softbody::ContactBuffers::kPairSlots) *
                                         (16 * tris + 16),
                                     0);
            }
        }
        contact.crossing = crossing_;
        contact.list = list_;
        pairs_.capacity = static_cast<Index>(pair_entries_.size());
        pairs_.data = pair_entries_.data();
        pairs_.owner = this;
        most_pairs_ = softbody::ContactBuffers::kPairSlots * kMostPairsPerTriangle *
                      std::max<Index>(m.triangles.count, 1);
        contact.pairs = &pairs_;
        entries_.capacity = static_cast<Index>(hash_entries_.size());
        entries_.data = hash_entries_.data();
        entries_.owner = this;
        most_entries_ = kMostEntriesPerTriangle * std::max<Index>(m.triangles.count, 1);
        contact.hash_entries = &entries_;
    }
    Buffers(const Buffers&) = delete;  // the contacts' entries point back at this object
    Buffers& operator=(const Buffers&) = delete;

    /// Let the surface contacts grow their hash inside a run (the solvers'; a one-off
    /// contact pass keeps the capacity it was given).
    void allow_growth() {
        entries_.grow = &Buffers::grow_entries;
        pairs_.grow = &Buffers::grow_pairs;
    }
    Index hash_capacity() const { return entries_.capacity; }
    double* row(int k) { return rows_[static_cast<size_t>(k)].data(); }
    softbody::LaneBuffers lanes_view;
    softbody::BodyGas gas;
    softbody::ContactBuffers contact;

private:
    std::vector<std::vector<double>> rows_, per_body_, per_collider_;
    std::vector<double> gradient_, rows_buffer_, lane_pnet_, gas_work_;
    std::vector<Index> hash_start_, hash_count_, hash_entries_, pair_entries_, thick_index_;
    std::vector<double> thick_;
    softbody::HashEntries entries_, pairs_;
    Index crossing_[2] = {-1, -1};
    Index list_[3] = {-1, 0, 0};  // the thickness contacts' pair list: none yet
    Index most_entries_ = 0, most_pairs_ = 0;

    /// Room for `needed` pair entries (as grow_entries), up to kMostPairsPerTriangle pairs a
    /// triangle.
    static bool grow_pairs(softbody::HashEntries& h, Index needed) {
        Buffers& self = *static_cast<Buffers*>(h.owner);
        if (needed > self.most_pairs_) return false;
        const Index size = std::min(self.most_pairs_, std::max(needed, 2 * h.capacity));
        try {
            self.pair_entries_.resize(static_cast<size_t>(size));
        } catch (const std::bad_alloc&) {
            return false;
        }
        h.data = self.pair_entries_.data();
        h.capacity = size;
        return true;
    }

    /// Room for `needed` entries (twice the capacity when that is more, up to the most), or
    /// false beyond kMostEntriesPerTriangle per triangle: a triangle spanning that many grid
    /// cells has stretched far past its rest size (a blow-up), and the run stops.
    static bool grow_entries(softbody::HashEntries& h, Index needed) {
        Buffers& self = *static_cast<Buffers*>(h.owner);
        if (needed > self.most_entries_) return false;
        const Index size = std::min(self.most_entries_, std::max(needed, 2 * h.capacity));
        try {
            self.hash_entries_.resize(static_cast<size_t>(size));
        } catch (const std::bad_alloc&) {
            return false;
        }
        h.data = self.hash_entries_.data();
        h.capacity = size;
        return true;
    }
};

/// Entries of the surface contacts' hash at first: as asked, by default 8 per triangle (room
/// for triangles up to a cell across); 0 without surface contacts. Solvers grow it as needed.
inline Index checked_capacity(const softbody::Model& m, std::optional<Index> asked) {
    if (asked && *asked < 0) fail("hash_capacity must be >= 0, got " + std::to_string(*asked));
    if (m.soft_contacts.mode != SoftContactMode::SURFACE) return 0;
    return asked ? *asked : 8 * m.triangles.count;
}

/// A run's state arrays and limits, checked against the model (views held for one call).
struct CheckedRun {
    F64 q, qd, collider_q, collider_rot, collider_impulse, gas_moles, gas_temperature, vent_open;
    softbody::StateView state;
    softbody::RunParams params;
};

/// The run's clock from the state: its time origin t0 and the steps step0 taken since. A
/// state a run of steps dt left (its _clock: the origin's time, the step count there, dt)
/// whose time is still origin + (step_count - origin's count) dt, to the bit, goes on
/// from that origin, so that its steps' times are those of one longer run; any other state
/// (new, its time set by hand, or a run of another step) starts an origin at its time.
inline void clock_from(nb::handle state, double dt, softbody::RunParams& p) {
    const double time = nb::cast<double>(state.attr("time"));
    p.t0 = time;
    p.step0 = 0.0;
    if (!nb::hasattr(state, "_clock")) return;
    const nb::object clock = state.attr("_clock");
    if (!nb::isinstance<nb::tuple>(clock) || nb::len(clock) != 3) return;
    const nb::tuple origin = nb::borrow<nb::tuple>(clock);
    const double t0 = nb::cast<double>(origin[0]), step_dt = nb::cast<double>(origin[2]);
    const Index since = nb::cast<Index>(state.attr("step_count")) - nb::cast<Index>(origin[1]);
    if (step_dt != dt || since < 0) return;
    const double step0 = static_cast<double>(since);
    if (t0 + step0 * dt != time) return;
    p.t0 = t0;
    p.step0 = step0;
}

/// A run's views of a softbody.State (its particle_q, particle_qd, collider_q,
/// collider_rotation and collider_impulse arrays, written in place; its time the run's
/// start, its clock's origin kept: clock_from) and of a RunLimits (max_speed, ratio_min,
/// ratio_max), checked against the model.
inline CheckedRun checked_run(const softbody::Model& m, Index steps, double dt, nb::handle state,
                              nb::handle limits) {
    if (steps < 0) fail("steps must be >= 0");
    if (!(std::isfinite(dt) && dt > 0.0)) fail("dt must be finite and > 0");
    CheckedRun run;
    run.q = writable(state.attr("particle_q"), "q", {m.particles.count, 3});
    run.qd = writable(state.attr("particle_qd"), "qd", {m.particles.count, 3});
    run.collider_q = writable(state.attr("collider_q"), "collider_q", {m.colliders.count, 3});
    run.collider_rot =
        writable(state.attr("collider_rotation"), "collider_rot", {m.colliders.count, 3, 3});
    run.collider_impulse =
        writable(state.attr("collider_impulse"), "collider_impulse", {m.colliders.count, 3});
    run.gas_moles = writable(state.attr("body_gas_moles"), "body_gas_moles", {m.bodies.count});
    run.gas_temperature =
        writable(state.attr("body_gas_temperature"), "body_gas_temperature", {m.bodies.count});
    run.vent_open = writable(state.attr("vent_open"), "vent_open", {m.vents.count});
    run.state = {run.q.data(),          run.qd.data(),        run.collider_q.data(),
                 run.collider_rot.data(), run.collider_impulse.data(), run.gas_moles.data(),
                 run.gas_temperature.data(), run.vent_open.data()};
    run.params.steps = steps;
    clock_from(state, dt, run.params);
    run.params.dt = dt;
    run.params.max_speed = nb::cast<double>(limits.attr("max_speed"));
    run.params.ratio_min = nb::cast<double>(limits.attr("ratio_min"));
    run.params.ratio_max = nb::cast<double>(limits.attr("ratio_max"));
    return run;
}

/// A solver's gas buffers pointed at a run's state (its amounts and vent latches) for steps
/// of dt [s] (the flows' limiter).
inline void attach_gas(softbody::BodyGas& gas, const CheckedRun& run) {
    gas.moles = run.state.gas_moles;
    gas.theta = gas.work;  // gas_state::kTheta
    gas.vent_open = run.state.vent_open;
    gas.flow_step = run.params.dt;
}

}  // namespace softbody::bindings
