// softbody._core.Model: the checked views of a Model's arrays every solver steps, with
// the vertex-major lane and ring tables built once (plan/lanes.hpp); and the views of a
// Control.
#pragma once

#include "bindings/arrays.hpp"
#include "plan/lanes.hpp"

namespace softbody::bindings {

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

        m.particles.count = n;
        m.springs.count = s;
        m.triangles.count = t;
        m.bodies.count = b;
        m.attachments.count = a;
        m.colliders.count = c;
        m.pins.count = static_cast<Index>(pins.shape(0));
        m.volumes.mc_count = static_cast<Index>(samples.shape(0));
        m.gases.schedule_count = static_cast<Index>(times.shape(0));

        m.particles.mass = mass.data();
        m.particles.inv_mass = f64("particle_inv_mass", {n});
        m.particles.body = i64("particle_body", {n});
        const double* g = f64("gravity", {3});
        for (int k = 0; k < 3; ++k) m.gravity[k] = g[k];
        m.springs.indices = springs.data();
        m.springs.rest_length = f64("spring_rest_length", {s});
        m.springs.stiffness = f64("spring_stiffness", {s});
        m.springs.damping = f64("spring_damping", {s});
        m.springs.body = i64("spring_body", {s});
        m.attachments.particle = att.data();
        m.attachments.rest_length = f64("attachment_rest_length", {a});
        m.attachments.stiffness = f64("attachment_stiffness", {a});
        m.attachments.damping = f64("attachment_damping", {a});
        m.triangles.indices = tris.data();
        m.triangles.body = i64("tri_body", {t});
        m.bodies.particle_range = ranges.data();
        m.bodies.tri_range = i64("body_tri_range", {b, 2});
        m.volumes.method = i64("body_volume_method", {b});
        m.volumes.mc_range = i64("body_mc_range", {b, 2});
        m.volumes.mc_samples = samples.data();
        m.gases.law = i64("body_gas_law", {b});
        m.gases.value = f64("body_gas_value", {b});
        m.gases.gamma = f64("body_gas_gamma", {b});
        m.gases.reference_volume = f64("body_gas_reference_volume", {b});
        m.gases.ambient_pressure = f64("body_ambient_pressure", {b});
        m.gases.schedule_range = i64("body_schedule_range", {b, 2});
        m.gases.schedule_time = times.data();
        m.gases.schedule_value = f64("schedule_value", {m.gases.schedule_count});
        m.bodies.rest_volume = f64("body_rest_volume", {b});
        m.bodies.closed = i64("body_closed", {b});
        m.bodies.contact_shape = i64("body_contact_shape", {b});
        m.pins.particle = pins.data();
        m.drag.coefficient = f64("body_drag_coefficient", {b});
        m.drag.air_density = nb::cast<double>(d.attr("air_density"));
        const double* wind = f64("wind", {3});
        for (int k = 0; k < 3; ++k) m.drag.wind[k] = wind[k];
        m.soft_contacts.mode = nb::cast<int>(d.attr("soft_contact_mode"));
        m.soft_contacts.restitution = nb::cast<double>(d.attr("soft_contact_restitution"));
        m.soft_contacts.friction = nb::cast<double>(d.attr("soft_contact_friction"));
        m.soft_contacts.margin = nb::cast<double>(d.attr("contact_margin"));
        m.soft_contacts.cell_size = nb::cast<double>(d.attr("contact_cell_size"));
        m.colliders.kind = kinds.data();
        m.colliders.center = f64("collider_center", {c, 3});
        m.colliders.rotation = f64("collider_rotation", {c, 3, 3});
        m.colliders.size = f64("collider_size", {c, 3});
        m.colliders.restitution = f64("collider_restitution", {c});
        m.colliders.friction = f64("collider_friction", {c});
        m.colliders.motion = i64("collider_motion", {c});
        m.colliders.motion_vector = f64("collider_motion_vector", {c, 3});
        m.colliders.motion_pivot = f64("collider_motion_pivot", {c, 3});
        m.colliders.motion_frequency = f64("collider_motion_frequency", {c});
        validate();
        layout_.build(model_);
    }

    const softbody::Model& model() const { return model_; }

private:
    // Indices and enumerations in range, so no kernel reads outside an array.
    void validate() {
        const softbody::Model& m = model_;
        check_indices(m.springs.indices, 2 * m.springs.count, 0, m.particles.count, "spring_indices");
        check_indices(m.triangles.indices, 3 * m.triangles.count, 0, m.particles.count, "tri_indices");
        check_indices(m.triangles.body, m.triangles.count, 0, m.bodies.count, "tri_body");
        check_indices(m.particles.body, m.particles.count, -1, m.bodies.count, "particle_body");
        check_indices(m.springs.body, m.springs.count, -1, m.bodies.count, "spring_body");
        check_indices(m.attachments.particle, m.attachments.count, 0, m.particles.count,
                      "attachment_particle");
        check_indices(m.pins.particle, m.pins.count, 0, m.particles.count, "pin_particle");
        check_ranges(m.bodies.particle_range, m.bodies.count, m.particles.count, "body_particle_range");
        check_ranges(m.bodies.tri_range, m.bodies.count, m.triangles.count, "body_tri_range");
        check_ranges(m.volumes.mc_range, m.bodies.count, m.volumes.mc_count, "body_mc_range");
        check_ranges(m.gases.schedule_range, m.bodies.count, m.gases.schedule_count, "body_schedule_range");
        for (Index b = 0; b < m.bodies.count; ++b) {
            // a body's triangles Index its own particles (the volume's reference point)
            const Index p0 = m.bodies.particle_range[2 * b], p1 = m.bodies.particle_range[2 * b + 1];
            if (m.bodies.tri_range[2 * b + 1] > m.bodies.tri_range[2 * b] && p1 == p0)
                fail("body " + std::to_string(b) + " has triangles but no particles");
        }
        check_indices(m.volumes.method, m.bodies.count, 0, VolumeMethod::kCount, "body_volume_method");
        check_indices(m.gases.law, m.bodies.count, 0, GasLaw::kCount, "body_gas_law");
        check_indices(m.bodies.contact_shape, m.bodies.count, 0, VolumeMethod::MONTE_CARLO,
                      "body_contact_shape");  // an exact or bounding method
        check_indices(m.colliders.kind, m.colliders.count, 0, ColliderKind::kCount, "collider_kind");
        check_indices(m.colliders.motion, m.colliders.count, 0, MotionKind::kCount, "collider_motion");
        if (m.soft_contacts.mode < 0 || m.soft_contacts.mode >= SoftContactMode::kCount)
            fail("soft_contact_mode must be 0, 1 or 2");
        if (m.soft_contacts.mode == SoftContactMode::SURFACE) {
            // the surface contacts' grid: cells of a positive, finite size
            if (!(std::isfinite(m.soft_contacts.cell_size) && m.soft_contacts.cell_size > 0.0))
                fail("contact_cell_size must be finite and > 0, got " +
                     std::to_string(m.soft_contacts.cell_size));
            if (!(std::isfinite(m.soft_contacts.margin) && m.soft_contacts.margin >= 0.0))
                fail("contact_margin must be finite and >= 0, got " +
                     std::to_string(m.soft_contacts.margin));
        }
        check_drag();
    }

    // Air and drag coefficients physical (finite, >= 0); the drag term runs only when some
    // body has drag in air of positive density.
    void check_drag() {
        softbody::Model& m = model_;
        if (!(std::isfinite(m.drag.air_density) && m.drag.air_density >= 0.0))
            fail("air_density must be finite and >= 0 kg/m^3, got " +
                 std::to_string(m.drag.air_density));
        for (int k = 0; k < 3; ++k)
            if (!std::isfinite(m.drag.wind[k])) fail("wind must be 3 finite numbers [m/s]");
        bool any = false;
        for (Index b = 0; b < m.bodies.count; ++b) {
            const double cd = m.drag.coefficient[b];
            if (!(std::isfinite(cd) && cd >= 0.0))
                fail("body_drag_coefficient holds " + std::to_string(cd) + " at " +
                     std::to_string(b) + "; it must be finite and >= 0");
            any = any || cd > 0.0;
        }
        m.drag.active = any && m.drag.air_density > 0.0;
    }

    softbody::Model model_;
    softbody::VertexLayout layout_;  // the vertex-major tables (plan/lanes.cpp)
    std::vector<ConstF64> keep_f_;
    std::vector<ConstI64> keep_i_;
};

/// Views of a ControlData bundle, checked against the model (held for one call).
struct CoreControl {
    CoreControl(const softbody::Model& m, nb::handle d) {
        gas = attribute<ConstF64>(d, "gas_override", {m.bodies.count});
        particle_f = attribute<ConstF64>(d, "particle_f", {m.particles.count, 3});
        anchor = attribute<ConstF64>(d, "attachment_anchor", {m.attachments.count, 3});
        pin = attribute<ConstF64>(d, "pin_target", {m.pins.count, 3});
        target = attribute<ConstF64>(d, "collider_target", {m.colliders.count, 3});
        ConstF64 grab = attribute<ConstF64>(d, "grab_target", {3});
        view.gas_override = gas.data();
        view.particle_f = particle_f.data();
        view.attachment_anchor = anchor.data();
        view.pin_target = pin.data();
        view.pin_active = nb::cast<bool>(d.attr("pin_active"));
        view.collider_target = target.data();
        view.grab_particle = nb::cast<Index>(d.attr("grab_particle"));
        if (view.grab_particle < -1 || view.grab_particle >= m.particles.count)
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
        for (int k = 0; k < 3; ++k) view.wind[k] = given ? w[k] : m.drag.wind[k];
    }
    ConstF64 gas, particle_f, anchor, pin, target;
    softbody::Control view;
};

}  // namespace softbody::bindings
