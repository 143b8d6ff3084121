// The gas state every scheme integrates: per body the amount n [mol] (State.gas_moles) and
// the temperature T [K] (State.gas_temperature). Inside a run the core carries, instead of
// T, theta = T (V / V_ref)^(g - 1) (T itself for an isothermal gas): the temperature the
// gas would have at its reference volume after an isentropic change. Then the gas law
// keeps its closed form, P = R n theta V_ref^(g-1) / V^g, exact and conservative in the
// positions, and the first law of the open system,
//     d(n c_v T) = sum over inflows of c_p T_in dn_in - c_p T dn_out - P dV,
// becomes, with dtheta / theta = dT / T + (g - 1) dV / V (the P dV term cancels exactly),
//     dn / dt     = in - out
//     dtheta / dt = theta / n [g in_T / T - in - (g - 1) out]      (adiabatic; 0 isothermal)
// with in, out [mol/s] the molar flows and in_T the inflows times their temperatures: rates
// that depend on the flows alone. An isothermal gas keeps T (fast heat exchange).
//
// Each scheme integrates (n, theta) with its stages (explicit_solver: Euler and symplectic
// Euler first order, midpoint and RK4 with their stages, velocity Verlet by Heun's
// predictor-corrector, second order); the implicit schemes and projective dynamics take
// the flows explicitly (forward Euler, first order) with the rates at the step's start.
// The flow terms' limiter (terms/flows.hpp) keeps each amount non-negative; a negative or
// non-finite amount anyway stops the run (BAD_GAS).
#pragma once

#include <algorithm>
#include <limits>

#include "model.hpp"
#include "solvers/forms.hpp"
#include "terms/flows.hpp"
#include "terms/volume.hpp"

namespace softbody::SOFTBODY_KERNELS::gas_state {

/// The per-body rows of BodyGas::work.
enum Slot { kTheta, kN0, kT0, kNs, kTs, kAccN, kAccT, kDn, kDt, kGasWork };
static_assert(kGasWork == kGasWorkSlots, "BodyGas::work holds every slot");

inline double* slot(const Model& m, const BodyGas& g, int k) {
    return g.work + static_cast<index>(k) * m.bodies.count;
}

/// Whether a flow term acts in this call (then the gas state changes within the run).
inline bool flowing(const Model& m, const Control& c) {
    bool any = false;
    Terms::each([&](auto term, int) {
        using T = decltype(term);
        if (T::kFlow && T::active(m, c)) any = true;
    });
    return any;
}

/// Whether body b's temperature depends on its volume (an adiabatic gas in a closed body).
inline bool adiabatic(const Model& m, index b) {
    return m.gases.law[b] == GasLaw::ADIABATIC && m.bodies.closed[b] != 0;
}

/// Every body's volume at q into g.volume, when some body's temperature needs it.
inline bool volumes_for_temperature(const Model& m, const double* q, const BodyGas& g) {
    bool any = false;
    for (index b = 0; b < m.bodies.count; ++b) any |= adiabatic(m, b);
    if (!any) return false;
    BodyGas only_volumes = g;
    only_volumes.volume_gradient = nullptr;
    volume::evaluate(m, q, only_volumes);
    return true;
}

/// At a run's start: theta from the state's temperature at the positions q (N, 3).
inline void begin(const Model& m, const double* q, const StateView& s, const BodyGas& g) {
    double* theta = slot(m, g, kTheta);
    volumes_for_temperature(m, q, g);
    for (index b = 0; b < m.bodies.count; ++b) {
        theta[b] = s.gas_temperature[b];
        if (adiabatic(m, b) && g.volume[b] > 0.0)
            theta[b] *= std::pow(g.volume[b] / m.gases.reference_volume[b], m.gases.gamma[b] - 1.0);
    }
}

/// At a run's end (time t [s], positions q): the state's temperature from theta, and the
/// amount of a body whose gas follows a schedule from its value there (nRT = value), so
/// the state reports it. A Control's value holds for its call only: the body's own amount
/// stays in the state (flows leave a body the Control prescribes alone).
inline void finish(const Model& m, double t, const double* q, const StateView& s,
                   const BodyGas& g) {
    const double* theta = slot(m, g, kTheta);
    volumes_for_temperature(m, q, g);
    for (index b = 0; b < m.bodies.count; ++b) {
        double temperature = theta[b];
        if (adiabatic(m, b) && g.volume[b] > 0.0)
            temperature *=
                std::pow(m.gases.reference_volume[b] / g.volume[b], m.gases.gamma[b] - 1.0);
        s.gas_temperature[b] = temperature;
        const bool scheduled = m.gases.schedule_range[2 * b + 1] > m.gases.schedule_range[2 * b];
        if (m.bodies.closed[b] != 0 && m.gases.law[b] != GasLaw::FIXED_PRESSURE && scheduled &&
            theta[b] > 0.0)
            s.gas_moles[b] = gas::model_value_at(m, b, t) / (gas::kGasConstant * theta[b]);
    }
}

/// The gas state's rates dn (B,) [mol/s] and dtheta (B,) [K/s] at an evaluation whose
/// forces (and so volumes and pressures in g) were just computed: every flow term's flow.
inline void rates(const Model& m, const Control& c, double t, const double* q, const double* qd,
                  const BodyGas& g, double* dn, double* dtheta) {
    const index bodies = m.bodies.count;
    std::fill(g.flow_in, g.flow_in + bodies, 0.0);
    std::fill(g.flow_in_t, g.flow_in_t + bodies, 0.0);
    std::fill(g.flow_out, g.flow_out + bodies, 0.0);
    const Eval e{m, c, t, q, qd, g};
    Terms::each([&](auto term, int) {
        using T = decltype(term);
        if (T::kFlow) T::flow(e);
    });
    for (index b = 0; b < bodies; ++b) {
        const double in = g.flow_in[b], out = g.flow_out[b];
        dn[b] = in - out;
        dtheta[b] = 0.0;
        const double n = g.moles[b];
        if (adiabatic(m, b) && n > 0.0 && (in > 0.0 || out > 0.0)) {
            const double gamma = m.gases.gamma[b];
            const double temperature = flows::temperature(m, g, b);
            dtheta[b] = g.theta[b] / n *
                        (gamma * g.flow_in_t[b] / temperature - in - (gamma - 1.0) * out);
        }
    }
}

/// Vents that open at a pressure stay open: latch those open at this evaluation.
inline void latch(const Model& m, const Control& c, double t, const double* q, const BodyGas& g,
                  double* vent_open) {
    const Eval e{m, c, t, q, q, g};
    for (index k = 0; k < m.vents.count; ++k)
        if (vent_open[k] == 0.0 && flows::vent_is_open(e, k)) vent_open[k] = 1.0;
}

/// out = from + h rate for the amounts and thetas (B,) each.
inline void advance(const Model& m, double h, const double* n_from, const double* t_from,
                    const double* dn, const double* dtheta, double* n_out, double* t_out) {
    for (index b = 0; b < m.bodies.count; ++b) {
        n_out[b] = n_from[b] + h * dn[b];
        t_out[b] = t_from[b] + h * dtheta[b];
    }
}

/// The step's start gas state (kN0, kT0) from the run's (state amounts, kTheta).
inline void save_start(const Model& m, const StateView& s, const BodyGas& g) {
    const index bodies = m.bodies.count;
    std::copy(s.gas_moles, s.gas_moles + bodies, slot(m, g, kN0));
    const double* theta = slot(m, g, kTheta);
    std::copy(theta, theta + bodies, slot(m, g, kT0));
}

/// Back to the step's start gas state (a failed step is undone).
inline void restore_start(const Model& m, const StateView& s, const BodyGas& g) {
    const index bodies = m.bodies.count;
    const double* n0 = slot(m, g, kN0);
    const double* t0 = slot(m, g, kT0);
    std::copy(n0, n0 + bodies, s.gas_moles);
    std::copy(t0, t0 + bodies, slot(m, g, kTheta));
}

/// A body whose amount or theta is negative or not finite: BAD_GAS (value: the amount).
inline RunResult check(const Model& m, const StateView& s, const BodyGas& g) {
    const double* theta = slot(m, g, kTheta);
    for (index b = 0; b < m.bodies.count; ++b) {
        const double n = s.gas_moles[b];
        if (!(std::isfinite(n) && n >= 0.0 && std::isfinite(theta[b]) && theta[b] >= 0.0))
            return {BAD_GAS, 0, b, n};
    }
    return {};
}

/// The gas view of a stage: the same buffers with the stage's amounts and thetas.
inline BodyGas at(const BodyGas& g, const double* n, const double* theta) {
    BodyGas stage = g;
    stage.moles = n;
    stage.theta = theta;
    return stage;
}

/// Forward Euler for the gas over a step h with the rates at its start (the implicit
/// schemes and projective dynamics): state amounts and theta from kN0, kT0 and kDn, kDt.
inline void euler(const Model& m, double h, const StateView& s, const BodyGas& g) {
    advance(m, h, slot(m, g, kN0), slot(m, g, kT0), slot(m, g, kDn), slot(m, g, kDt),
            s.gas_moles, slot(m, g, kTheta));
}

/// The molar flows at a state (time t, positions q (N, 3), amounts moles (B,) [mol],
/// temperatures (B,) [K], vent latches (V,)) without the step limiter: the orifice laws
/// themselves, into g.flow_in, flow_in_t and flow_out (B,); volumes and pressures into g.
inline void flows_at(const Model& m, const Control& c, double t, const double* q,
                     const double* moles, const double* temperature, const double* vent_open,
                     BodyGas g) {
    double* theta = slot(m, g, kTheta);
    g.volume_gradient = nullptr;
    volume::evaluate(m, q, g);
    for (index b = 0; b < m.bodies.count; ++b) {
        theta[b] = temperature[b];
        if (adiabatic(m, b) && g.volume[b] > 0.0)
            theta[b] *= std::pow(g.volume[b] / m.gases.reference_volume[b], m.gases.gamma[b] - 1.0);
    }
    g.moles = moles;
    g.theta = theta;
    g.vent_open = vent_open;
    g.flow_step = 0.0;
    gas::pressures(m, c, t, g);
    rates(m, c, t, q, q, g, slot(m, g, kDn), slot(m, g, kDt));
}

/// The gas over a step h of the implicit schemes and projective dynamics, whose forces
/// (and so volumes and pressures in g) at the step's start, time t, positions q, were just
/// computed: the start saved, vents latched, the rates there, forward Euler.
inline void forward_euler(const Model& m, const Control& c, double t, double h, const double* q,
                          const double* qd, const StateView& s, const BodyGas& g) {
    save_start(m, s, g);
    latch(m, c, t, q, g, s.vent_open);
    rates(m, c, t, q, qd, g, slot(m, g, kDn), slot(m, g, kDt));
    advance(m, h, slot(m, g, kN0), slot(m, g, kT0), slot(m, g, kDn), slot(m, g, kDt),
            s.gas_moles, slot(m, g, kTheta));
}

/// After a step's end checks: BAD_GAS (the state back to the step's start, q0, v0 (N, 3))
/// when an amount went wrong; a failure of r undoes the gas too.
inline RunResult end_step(const Model& m, const StateView& s, const BodyGas& g, RunResult r,
                          index step, const double* q0, const double* v0) {
    if (r.status == OK) {
        r = check(m, s, g);
        if (r.status != OK) {
            const index n3 = 3 * m.particles.count;
            std::copy(q0, q0 + n3, s.q);
            std::copy(v0, v0 + n3, s.qd);
            r.steps_done = step;
        }
    }
    if (r.status != OK) restore_start(m, s, g);
    return r;
}

}  // namespace softbody::SOFTBODY_KERNELS::gas_state
