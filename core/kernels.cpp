// The step kernels of one instruction set (SOFTBODY_ISA: scalar, avx2 or avx512), gathered
// into its KernelTable. CMake compiles this file once per set with that set's flags.
#include "kernels.hpp"

#include <algorithm>
#include <vector>

#include "solvers/explicit.hpp"
#include "solvers/forms.hpp"
#include "solvers/implicit.hpp"
#include "solvers/multigrid.hpp"
#include "solvers/projective.hpp"
#include "solvers/substep.hpp"
#include "terms/registry.hpp"
#include "terms/volume.hpp"

#define SOFTBODY_STRING2(x) #x
#define SOFTBODY_STRING(x) SOFTBODY_STRING2(x)

namespace softbody::SOFTBODY_KERNELS {

namespace {

RunResult simulate_explicit(const Model& m, const Control& c, const RunParams& p,
                            const StateView& s, const ExplicitBuffers& w) {
    return explicit_solver::simulate(m, c, p, s, w);
}

RunResult simulate_implicit(const Model& m, const Control& c, const RunParams& p,
                            const ImplicitParams& ip, const StateView& s,
                            const ImplicitBuffers& w, const MultigridView* mg) {
    return implicit_solver::simulate(m, c, p, ip, s, w, mg);
}

void apply_preconditioner(const Model& m, const Control& c, double t, double h,
                          const ImplicitBuffers& w, const MultigridView* mg, const double* r,
                          double* z) {
    forms::update(Eval{m, c, t, w.q0, w.v0, w.gas});
    implicit_solver::prepare(m, c, t, h, w, mg);
    if (mg == nullptr) implicit_solver::jacobi_diagonal(m, h, w);
    implicit_solver::precondition(m, mg, w.cg_diag, r, z);
}

void apply_multigrid(const MultigridView& mg, const double* r, double* z) {
    multigrid::apply(mg, r, z);
}

RunResult simulate_projective(const Model& m, const Control& c, const RunParams& p,
                              const StateView& s, const Factor& a, const ProjectiveBuffers& w) {
    return projective::simulate(m, c, p, s, a, w);
}

RunResult simulate_substep(const Model& m, const Control& c, const RunParams& p,
                           const StateView& s, const SubstepBuffers& w) {
    return substep::simulate(m, c, p, s, w);
}

void projective_solve(const Factor& a, const double* b, double* x, double* out) {
    projective::solve(a, b, x, out);
}

void eval_forces(const Model& m, const Control& c, double t, const double* q, const double* qd,
                 const BodyGas& gas, const LaneBuffers& lanes, double* f) {
    forms::eval_forces(m, c, t, q, qd, gas, lanes, f);
}

void eval_gas(const Model& m, const Control& c, double t, const double* q, const BodyGas& gas) {
    forms::update(Eval{m, c, t, q, q, gas});  // the terms' state: volumes and pressures
}

void eval_volumes(const Model& m, const double* q, const BodyGas& gas) {
    volume::evaluate(m, q, gas);
}

void apply_jacobians(const Model& m, const Control& c, const Linearization& l, const double* p,
                     double alpha_m, double alpha_c, double alpha_k, unsigned skip, double* out) {
    forms::apply_jacobians(m, c, l, alpha_m, alpha_c, alpha_k, p, out, skip);
}

index soft_contacts(const Model& m, double* q, double* qd, const ContactBuffers& w) {
    if (m.soft_contacts.mode == SoftContactMode::BOUNDING) soft::contacts_bounding(m, q, qd, w);
    if (m.soft_contacts.mode == SoftContactMode::SURFACE && m.soft_contacts.thickness > 0.0) {
        const std::vector<double> q0(q, q + 3 * m.particles.count);  // a pass from rest
        return thick::contacts(m, q0.data(), q, qd, w);
    }
    if (m.soft_contacts.mode == SoftContactMode::SURFACE) return soft::contacts_surface(m, q, qd, w);
    return 0;
}

void eval_energies(const Model& m, const Control& c, double t, const double* q,
                   const BodyGas& gas, TermEnergies& out) {
    forms::energies(Eval{m, c, t, q, q, gas}, out.total, out.body);
}

void eval_flows(const Model& m, const Control& c, double t, const double* q, const double* moles,
                const double* temperature, const double* vent_open, const BodyGas& gas) {
    gas_state::flows_at(m, c, t, q, moles, temperature, vent_open, gas);
}

unsigned active_terms(const Model& m, const Control& c) {
    unsigned mask = 0;
    Terms::each([&](auto term, int k) {
        if (decltype(term)::active(m, c)) mask |= 1u << k;
    });
    return mask;
}

void membrane_blocks(const Model& m, const double* q, double* out) {
    membrane::prepare(m, q, out);
}

// The estimate's Gershgorin bounds, term by term: the spring-like terms' row sums first
// (a particle's row holds its springs and its attachments), the gas's rows and rank-one
// part, then every registered term's own `bound` form.
StiffnessBounds stiffness_bounds(const Model& m, const Control& c, const double* q,
                                 const BoundBuffers& w) {
    StiffnessBounds out;
    springs::bound_weights(m, q, w.spring_weight);
    attachments::bound_weights(m, c, q, w.attachment_weight);
    std::fill(w.root_sum, w.root_sum + springs::kBoundParts * m.particles.count, 0.0);
    springs::add_root_sums(m, w.spring_weight, w.root_sum);
    attachments::add_root_sums(m, w.attachment_weight, w.root_sum);
    springs::row_bounds(m, w.spring_weight, w.root_sum, out.springs);
    attachments::row_bounds(m, w.attachment_weight, w.root_sum, out.attachments);
    springs::damping_ratios(m, out.ratio_min, out.ratio_max, out.pure_dampers);
    attachments::damping_ratios(m, out.ratio_min, out.ratio_max, out.pure_dampers);
    std::fill(w.volume_gradient, w.volume_gradient + 3 * m.particles.count, 0.0);
    gas::bound_slopes(m, q, w.body_pnet, w.body_dpdv, w.volume_gradient);
    std::fill(w.pressure_row, w.pressure_row + m.particles.count, 0.0);
    gas::add_pressure_rows(m, q, w.body_pnet, w.pressure_row);
    for (index i = 0; i < m.particles.count; ++i)
        out.pressure_rows = std::max(out.pressure_rows, w.pressure_row[i]);
    out.gas_rank_one = gas::rank_one_bound(m, w.body_dpdv, w.volume_gradient);
    // every other term with a bound form, in registry order
    Terms::each([&](auto term, int k) {
        using T = decltype(term);
        if (!T::kBound) return;
        TermBound b;
        T::bound(m, c, q, w.term_rows, b);
        for (int part = 0; part < 4; ++part) out.terms[k][part] = b.parts[part];
        out.ratio_min = std::min(out.ratio_min, b.ratio_min);
        out.ratio_max = std::max(out.ratio_max, b.ratio_max);
    });
    return out;
}

}  // namespace

const KernelTable& kernel_table() {
    static_assert(Terms::count <= kMaxTerms, "more terms than kMaxTerms");
    static const KernelTable table{SOFTBODY_STRING(SOFTBODY_ISA), Terms::count, term_traits(),
                                   simulate_explicit,
                                   simulate_implicit, apply_preconditioner, apply_multigrid, simulate_projective,
                                   simulate_substep, projective_solve, eval_forces,
                                   eval_gas, eval_volumes,
                                   apply_jacobians, soft_contacts,
                                   eval_energies, eval_flows, active_terms, membrane_blocks,
                                   stiffness_bounds};
    return table;
}

}  // namespace softbody::SOFTBODY_KERNELS
