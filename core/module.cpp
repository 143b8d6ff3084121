// softbody._core: the nanobind module of the engine core. Each part lives in bindings/,
// beside the checks of what it takes from Python (bindings/arrays.hpp): the model, one
// file per solver, the terms at a state, the factor's set-up and the rasteriser.
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <string>

#include "bindings/bindings.hpp"
#include "kernels.hpp"

namespace nb = nanobind;

NB_MODULE(_core, mod) {
    mod.doc() = "softbody's compiled engine core (C++17): the step kernels.";
    mod.def("simd_paths", &softbody::available_simd,
            "Instruction sets this build has and this CPU runs, best last.");
    mod.def("simd_path", [] { return std::string(softbody::kernels().name); },
            "The instruction set the kernels use now.");
    mod.def("select_simd", &softbody::select_simd, nb::arg("name"),
            "Use the named instruction set ('scalar', 'avx2', 'avx512' or 'auto'); False "
            "if this build or CPU lacks it.");

    softbody::bindings::bind_model(mod);
    softbody::bindings::bind_explicit(mod);
    softbody::bindings::bind_projective(mod);
    softbody::bindings::bind_substep(mod);
    softbody::bindings::bind_implicit(mod);
    softbody::bindings::bind_terms(mod);
    softbody::bindings::bind_plan(mod);
    softbody::bindings::bind_render(mod);
}
