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
                          double* z, const ContactBuffers* contacts) {
    forms::update(Eval{m, c, t, w.q0, w.v0, w.gas});
    thick_system::System pairs;  // none: the terms' matrix alone
    if (contacts != nullptr) {
        std::vector<double> rest(static_cast<size_t>(3 * m.particles.count), 0.0);
        thick_system::begin(m, w.q0, rest.data(), h, *contacts, h, pairs);
    }
    implicit_solver::prepare(m, c, t, h, w, mg, pairs);
    if (mg == nullptr) implicit_solver::jacobi_diagonal(m, c, h, w, pairs);
    implicit_solver::precondition(m, mg, w.cg_diag, r, z, pairs);
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

index contact_pairs(const Model& m, double* q, double radius, double* q_end,
                    const ContactBuffers& w, double* q_later, double slack) {
    thick::Stage st{m, q, q, w, {0.0, 0.0, 0.0}, 1.0 / m.soft_contacts.cell_size, radius,
                    m.soft_contacts.self_contact != 0};
    if (q_end != nullptr) {  // a step's swept gather, after the step's common translation
        st.q = q_end;
        st.T = thick::motion(m, q, q_end, nullptr, false).T;
        if (q_later == nullptr) return thick::gather(st);
        st.slack = slack;
        const index earlier = thick::gather(st);
        if (earlier < 0) return earlier;
        st.q = q_later;  // the later pass, from the earlier's rows
        return thick::reuse_swept(st, q_end, slack, earlier);
    }
    st.swept = false;
    st.keep = radius;
    return thick::gather(st);
}

index contact_stage(const Model& m, const double* q0, double* q, double* qd,
                    const ContactBuffers& w) {
    return thick::contacts(m, q0, q, qd, w);
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

void prepare(const Model& m, const Control& c, double t, const BodyGas& gas,
             const Linearization& l) {
    const Eval e{m, c, t, l.q, l.q, gas};
    forms::update(e);
    forms::prepare(e, l);
}

void prepare_spectral(const Model& m, const Control& c, const BodyGas& gas,
                      const BoundScratch& w, const Linearization& l) {
    const Eval e{m, c, 0.0, l.q, l.q, gas};
    forms::update(e);
    forms::prepare_spectral(e, w, l);
}

void spectral_product(const Model& m, const Control& c, const Linearization& l,
                      StiffnessPart part, const double* p, double* out) {
    forms::spectral_product(m, c, l, part, p, out);
}

// The estimate's Gershgorin bounds, every registered term's `bound` form in registry order,
// after every kSharedRows term's row sums (terms/term.hpp: add_row_sums).
StiffnessBounds stiffness_bounds(const Model& m, const Control& c, const double* q,
                                 const BoundScratch& w) {
    StiffnessBounds out;
    std::fill(w.root_sum, w.root_sum + 4 * m.particles.count, 0.0);
    Terms::each([&](auto term, int) {
        using T = decltype(term);
        if (T::kBound && T::kSharedRows) T::add_row_sums(m, c, q, w);
    });
    Terms::each([&](auto term, int k) {
        using T = decltype(term);
        if (!T::kBound) return;
        TermBound& b = out.terms[k];
        T::bound(m, c, q, w, b);
        out.ratio_min = std::min(out.ratio_min, b.ratio_min);
        out.ratio_max = std::max(out.ratio_max, b.ratio_max);
        out.pure_dampers = out.pure_dampers || b.pure_dampers;
    });
    return out;
}

index linearization_size(int term, const Model& m) {
    index out = 0;
    Terms::each([&](auto t, int k) {
        if (k == term) out = decltype(t)::linearization_size(m);
    });
    return out;
}

const char* check_stencil(int term, const Model& m, const Stencil& s, index map_length) {
    const char* out = "is not a registered term with a stencil";
    Terms::each([&](auto t, int k) {
        using T = decltype(t);
        if (k == term && T::kStencil) out = T::check_stencil(m, s, map_length);
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
                                   eval_energies, eval_flows, active_terms, prepare,
                                   prepare_spectral, spectral_product,
                                   linearization_size, check_stencil, stiffness_bounds,
                                   contact_pairs, contact_stage};
    return table;
}

}  // namespace softbody::SOFTBODY_KERNELS
