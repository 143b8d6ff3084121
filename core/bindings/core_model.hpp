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
    /// Reads and checks every field of fields.hpp from the softbody.Model `d`.
    explicit CoreModel(nb::handle d) {
        softbody::Model& m = model_;
        // the counts, from their defining fields' first dimensions
#define SOFTBODY_READ_COUNT(symbol, part, member, python) \
    const Index symbol = leading(d, #python);              \
    m.part.member = symbol;
        SOFTBODY_MODEL_COUNTS(SOFTBODY_READ_COUNT)
#undef SOFTBODY_READ_COUNT
        // every field, shape-checked, then its own check (the counts are in scope)
#define SOFTBODY_SHAPE(...) std::vector<Index>{__VA_ARGS__}
#define SOFTBODY_READ_FIELD(part, member, python, type, shape, check, unit, doc) \
    {                                                                             \
        const char* name = #python;                                               \
        const std::vector<Index> dims = SOFTBODY_SHAPE shape;                     \
        const auto* ptr = read_##type(d, name, dims, m.part.member);              \
        const Index elems = element_count(dims);                                  \
        SOFTBODY_CHECK_##check                                                    \
    }
#define SOFTBODY_CHECK_none (void)ptr, (void)elems;
#define SOFTBODY_CHECK_index(lo, hi) check_indices(ptr, elems, lo, hi, name);
#define SOFTBODY_CHECK_range(limit) (void)elems, check_ranges(ptr, dims[0], limit, name);
#define SOFTBODY_CHECK_finite check_finite(ptr, elems, name, false);
#define SOFTBODY_CHECK_finite_nonneg check_finite(ptr, elems, name, true);
#define SOFTBODY_READ_PART(Type, part, fields, extra) fields(SOFTBODY_READ_FIELD)
        SOFTBODY_MODEL_PARTS(SOFTBODY_READ_PART)
#undef SOFTBODY_READ_PART
#undef SOFTBODY_READ_FIELD
        validate();
        layout_.build(model_);
    }

    const softbody::Model& model() const { return model_; }

private:
    // What a single field's check cannot say (each field's own checks ran as it was read).
    void validate() {
        const softbody::Model& m = model_;
        for (Index b = 0; b < m.bodies.count; ++b) {
            // a body's triangles index its own particles (the volume's reference point)
            const Index p0 = m.bodies.particle_range[2 * b], p1 = m.bodies.particle_range[2 * b + 1];
            if (m.bodies.tri_range[2 * b + 1] > m.bodies.tri_range[2 * b] && p1 == p0)
                fail("body " + std::to_string(b) + " has triangles but no particles");
        }
        // a mesh collider has a tree, whose inner nodes' children come after them (no cycle)
        for (Index k = 0; k < m.colliders.count; ++k)
            if (m.colliders.kind[k] == ColliderKind::MESH && m.colliders.mesh_root[k] < 0)
                fail("collider " + std::to_string(k) + " is a mesh collider without a tree " +
                     "(collider_mesh_root -1)");
        for (Index n = 0; n < m.collider_meshes.node_count; ++n) {
            const Index* tris = m.collider_meshes.node_tris + 2 * n;
            const Index* child = m.collider_meshes.node_children + 2 * n;
            if (tris[1] == tris[0] && (child[0] <= n || child[1] <= n))
                fail("collider_mesh_node_children row " + std::to_string(n) +
                     " must name rows after it");
        }
        if (m.soft_contacts.mode == SoftContactMode::SURFACE) {
            // the surface contacts' grid: cells of a positive, finite size
            if (!(std::isfinite(m.soft_contacts.cell_size) && m.soft_contacts.cell_size > 0.0))
                fail("contact_cell_size must be finite and > 0, got " +
                     std::to_string(m.soft_contacts.cell_size));
            if (!(std::isfinite(m.soft_contacts.margin) && m.soft_contacts.margin >= 0.0))
                fail("contact_margin must be finite and >= 0, got " +
                     std::to_string(m.soft_contacts.margin));
            // with a thickness h the broad phase grows boxes by the margin, which must
            // cover the h the response may move two sheets by (collision/thick.hpp)
            if (m.soft_contacts.thickness > 0.0 && !(m.soft_contacts.margin >= m.soft_contacts.thickness))
                fail("contact_margin must be >= contact_thickness, got " +
                     std::to_string(m.soft_contacts.margin) + " < " +
                     std::to_string(m.soft_contacts.thickness));
        }
    }

    // Reading one field of each type into the model (m.part.member), returning a pointer
    // to what its check reads. Arrays stay the Python Model's (kept alive here).
    static Index leading(nb::handle d, const char* name) {
        nb::object value = d.attr(name);
        if (!nb::hasattr(value, "shape")) fail(std::string(name) + " must be an array");
        nb::tuple shape = nb::cast<nb::tuple>(value.attr("shape"));
        if (shape.size() == 0) fail(std::string(name) + " must be an array");
        return nb::cast<Index>(shape[0]);
    }
    static Index element_count(const std::vector<Index>& dims) {
        Index count = 1;
        for (Index d : dims) count *= d;
        return count;
    }
    const double* read_f64(nb::handle d, const char* name, const std::vector<Index>& dims,
                           const double*& member) {
        ConstF64 a = attribute<ConstF64>(d, name, dims);
        keep_f_.push_back(a);
        return member = a.data();
    }
    const Index* read_i64(nb::handle d, const char* name, const std::vector<Index>& dims,
                          const Index*& member) {
        ConstI64 a = attribute<ConstI64>(d, name, dims);
        keep_i_.push_back(a);
        return member = a.data();
    }
    static const double* read_f64_value(nb::handle d, const char* name,
                                        const std::vector<Index>&, double& member) {
        member = number<double>(d, name);
        return &member;
    }
    static const Index* read_i64_value(nb::handle d, const char* name,
                                       const std::vector<Index>&, Index& member) {
        member = number<Index>(d, name);
        return &member;
    }
    const double* read_vec3(nb::handle d, const char* name, const std::vector<Index>& dims,
                            double (&member)[3]) {
        ConstF64 a = attribute<ConstF64>(d, name, dims);
        for (int k = 0; k < 3; ++k) member[k] = a.data()[k];
        return member;
    }
    template <class T>
    static T number(nb::handle d, const char* name) {
        T value;
        if (!nb::try_cast(d.attr(name), value))
            fail(std::string(name) + " must be a number");
        return value;
    }
    static void check_finite(const double* v, Index count, const char* name, bool nonneg) {
        for (Index k = 0; k < count; ++k)
            if (!(std::isfinite(v[k]) && (!nonneg || v[k] >= 0.0)))
                fail(std::string(name) + " holds " + std::to_string(v[k]) + " at " +
                     std::to_string(k) + "; it must be finite" + (nonneg ? " and >= 0" : ""));
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
        vent_area = attribute<ConstF64>(d, "vent_area", {m.vents.count});
        orifice_area = attribute<ConstF64>(d, "orifice_area", {m.orifices.count});
        inflator_flow = attribute<ConstF64>(d, "inflator_mass_flow", {m.inflators.count});
        view.vent_area = vent_area.data();
        view.orifice_area = orifice_area.data();
        view.inflator_flow = inflator_flow.data();
        const double* wind = attribute<ConstF64>(d, "wind", {3}).data();
        for (int k = 0; k < 3; ++k) {
            if (!std::isfinite(wind[k])) fail("Control wind must be 3 finite numbers [m/s]");
            view.wind[k] = wind[k];
        }
    }

    ConstF64 gas, particle_f, anchor, pin, target, vent_area, orifice_area, inflator_flow;
    softbody::Control view;
};

}  // namespace softbody::bindings
