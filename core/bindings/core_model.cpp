// softbody._core.Model's binding (bindings/core_model.hpp holds the class).
#include "bindings/bindings.hpp"
#include "bindings/core_model.hpp"

namespace softbody::bindings {

void bind_model(nb::module_& mod) {
    nb::class_<CoreModel>(mod, "Model", "Checked views of a Model's arrays (ModelData).")
        .def(nb::init<nb::handle>(), nb::arg("data"))
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
}

}  // namespace softbody::bindings
