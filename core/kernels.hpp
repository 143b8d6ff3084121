// The entry points of the step kernels, one table per instruction set (kernels.cpp is
// compiled once per set; dispatch.cpp chooses a table for the CPU at run time).
#pragma once

#include <string>
#include <vector>

#include "model.hpp"

namespace softbody {

struct KernelTable {
    const char* name;  // "scalar", "avx2", "avx512"
    /// Advance a state by an explicit scheme (RunParams.scheme 0-4).
    RunResult (*simulate_explicit)(const Model&, const Control&, const RunParams&,
                                   const StateView&, const ExplicitBuffers&);
    /// Advance a state by backward Euler or BDF2; mg is the multigrid hierarchy, or null
    /// for the Jacobi preconditioner.
    RunResult (*simulate_implicit)(const Model&, const Control&, const RunParams&,
                                   const ImplicitParams&, const StateView&,
                                   const ImplicitBuffers&, const MultigridView* mg);
    /// z = P^-1 r for r, z (N, 3): the implicit solve's preconditioner for step h with its
    /// blocks at w.q0 at time t (w.gas refreshed there); mg null: Jacobi.
    void (*apply_preconditioner)(const Model&, const Control&, double t, double h,
                                 const ImplicitBuffers& w, const MultigridView* mg,
                                 const double* r, double* z);
    /// z = V(r) for r, z (N, 3): one V-cycle of the Laplacian hierarchy from z = 0.
    void (*apply_multigrid)(const MultigridView& mg, const double* r, double* z);
    /// Advance a state by projective dynamics (p.iterations per step) on factor `a`,
    /// built for p.dt.
    RunResult (*simulate_projective)(const Model&, const Control&, const RunParams&,
                                     const StateView&, const Factor& a,
                                     const ProjectiveBuffers&);
    /// out = A^-1 b for b, out (N, 3): projective dynamics' two triangular solves on the
    /// factor a; x (N, 3) scratch.
    void (*projective_solve)(const Factor& a, const double* b, double* x, double* out);
    /// All forces f (N, 3) [N] at time t for q, qd (N, 3); refreshes gas.
    void (*eval_forces)(const Model&, const Control&, double t, const double* q,
                        const double* qd, const BodyGas& gas, const LaneBuffers& lanes,
                        double* f);
    /// Volumes (and, with gas.volume_gradient set, dV/dx) and pressures at time t.
    void (*eval_gas)(const Model&, const Control&, double t, const double* q,
                     const BodyGas& gas);
    /// Volumes alone into gas.volume (B,) (bounds into gas.lo/hi); reads only the model's
    /// topology, volume methods and Monte Carlo samples.
    void (*eval_volumes)(const Model&, const double* q, const BodyGas& gas);
    /// out = alpha_m M p + alpha_c C p + alpha_k K p for p (N, 3) at q (C = df/dv, K = df/dx):
    /// spring blocks from u (S, 3), a, b (S,); pressure from dV/dx (N, 3), dP/dV and
    /// P - P_ambient (B,); attachments only when `attachments`.
    void (*apply_jacobians)(const Model&, const Control&, const double* q, const double* p,
                            double alpha_m, double alpha_c, double alpha_k, const double* u,
                            const double* a, const double* b, const double* gradient,
                            const double* dpdv, const double* pnet, bool attachments,
                            double* out);
    /// One pass of the soft-soft contacts (the model's mode) on q, qd (N, 3) in place;
    /// returns the hash entries the surface contacts needed (0 if they fit, or none).
    index (*soft_contacts)(const Model&, double* q, double* qd, const ContactBuffers& w);
};

namespace isa_scalar {
const KernelTable& kernel_table();
}
namespace isa_avx2 {
const KernelTable& kernel_table();
}
namespace isa_avx512 {
const KernelTable& kernel_table();
}

/// The table in use (chosen at first use: SOFTBODY_SIMD, else the best the CPU runs).
const KernelTable& kernels();
/// The instruction sets this build has and this CPU runs, best last.
std::vector<std::string> available_simd();
/// Use the named set ("scalar", "avx2", "avx512", or "auto"); false if unavailable.
bool select_simd(const std::string& name);

}  // namespace softbody
