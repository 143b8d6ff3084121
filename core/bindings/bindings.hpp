// The parts of softbody._core, one per file of this folder, each registering its names.
#pragma once

#include <nanobind/nanobind.h>

namespace softbody::bindings {

void bind_model(nanobind::module_& mod);       // Model (core_model.cpp)
void bind_explicit(nanobind::module_& mod);    // ExplicitSolver
void bind_projective(nanobind::module_& mod);  // ProjectiveSolver, solve_factor
void bind_substep(nanobind::module_& mod);     // SubstepSolver
void bind_implicit(nanobind::module_& mod);    // ImplicitSolver, apply_multigrid
void bind_terms(nanobind::module_& mod);       // eval_forces, eval_energies, stiffness_bounds, ...
void bind_plan(nanobind::module_& mod);        // plan_dissection_order, plan_strict_lower, ...
void bind_render(nanobind::module_& mod);      // raster_*

}  // namespace softbody::bindings
