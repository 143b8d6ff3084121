// softbody._core.Model's binding (bindings/core_model.hpp holds the class).
#include "bindings/bindings.hpp"
#include "bindings/core_model.hpp"

namespace softbody::bindings {

void bind_model(nb::module_& mod) {
    nb::class_<CoreModel>(mod, "Model", "Checked views of a softbody.Model's fields (fields.hpp).")
        .def(nb::init<nb::handle>(), nb::arg("model"))
        .def_prop_ro("particle_count", [](const CoreModel& c) { return c.model().particles.count; })
        .def_prop_ro(
            "lane_slots",
            [](const CoreModel& c) {
                const softbody::Model& m = c.model();
                const Index g = m.slots.group_count;
                return std::make_tuple(m.slots.ring_start[g], m.slots.spring_start[g],
                                       m.slots.face_start[g]);
            },
            "Slots of the vertex-major tables, over all groups of 8 particles: (ring, springs "
            "off the rings, faces outside a fan).");
    mod.def("model_fields", [] {
        nb::list out;
#define SOFTBODY_FIELD_ENTRY(part, member, python, type, shape, check, unit, doc)           \
    {                                                                                        \
        nb::dict f;                                                                          \
        f["name"] = #python;                                                                 \
        f["part"] = #part;                                                                   \
        f["member"] = #member;                                                               \
        f["type"] = #type;                                                                   \
        f["shape"] = #shape;                                                                 \
        f["check"] = #check;                                                                 \
        f["unit"] = unit;                                                                    \
        f["doc"] = doc;                                                                      \
        out.append(f);                                                                       \
    }
#define SOFTBODY_FIELD_PART(Type, part, fields, extra) fields(SOFTBODY_FIELD_ENTRY)
        SOFTBODY_MODEL_PARTS(SOFTBODY_FIELD_PART)
#undef SOFTBODY_FIELD_PART
#undef SOFTBODY_FIELD_ENTRY
        return out;
    }, "Every field of a Model the core reads (core/fields.hpp): a list of dicts of its "
       "Python 'name', C++ 'part' and 'member', 'type' (f64, i64, f64_value, i64_value, "
       "vec3), 'shape' (in the counts N, S, A, T, B, M, K, P, C), 'check', 'unit', 'doc'.");
}

}  // namespace softbody::bindings
