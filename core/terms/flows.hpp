// Gas that flows: vents to the ambient air, orifices between two bodies (chambers),
// inflators and fabric leakage. Each is a registered term whose `flow` form adds molar
// flows [mol/s] into and out of the bodies' gas at an evaluation; solvers/gas_state.hpp
// turns them into the rates of the gas state (amount n, temperature) that every scheme
// integrates.
//
// The orifice law (isentropic flow from the higher-pressure side u to the lower d, ratio
// r = P_d / P_u, gamma g, specific gas constant R_s = R / M):
//   choked, r <= r_c = (2 / (g + 1))^(g / (g - 1)):
//     mdot = C_d A P_u sqrt(g / (R_s T_u)) (2 / (g + 1))^((g + 1) / (2 (g - 1)))
//   subsonic:
//     mdot = C_d A P_u sqrt(2 g / ((g - 1) R_s T_u) (r^(2/g) - r^((g+1)/g)))
// whose slope in P_d is infinite at r = 1; above r = kLinear = 0.9999 (a difference of
// 10 Pa at 1 bar) it tapers linearly to 0 at r = 1 (continuous, finite slope: the
// laminar flow of a small difference), so two chambers near equal pressure exchange gas
// smoothly, while differences of tens of pascals, a balloon's, follow the orifice law. A fabric leak is mdot = c A_body |P - P_a| (the usual porosity model), both ways.
//
// The limiter: a flow path never moves, in one step h, more than 1 / k of the gas that
// would bring its two sides to equal pressure (k the paths the upstream body's gas can
// leave by: body_flow_paths), at the current volumes and temperatures. So no amount goes
// negative however large an opening, pressures never cross in a step (no chattering), and
// a flow adds to one side exactly what it takes from the other (mass is conserved to
// round-off). It binds only where the step is too long to resolve the flow (the flow
// would equalise the sides within k steps).
#pragma once

#include "model.hpp"
#include "terms/gas.hpp"
#include "terms/term.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::flows {

using gas::kGasConstant;
constexpr double kLinear = 0.9999;            // the subsonic law tapers linearly above this r

/// Mass flow [kg/s] of the orifice law from upstream (p_u [Pa], t_u [K]) to downstream
/// p_d <= p_u through area [m^2] with discharge coefficient cd; gamma, molar mass [kg/mol].
inline double orifice_mass_flow(double cd, double area, double p_u, double t_u, double p_d,
                                double gamma, double molar_mass) {
    if (!(p_u > 0.0 && t_u > 0.0 && area > 0.0 && cd > 0.0 && molar_mass > 0.0)) return 0.0;
    const double g = gamma;
    const double rs = kGasConstant / molar_mass;
    const double r = std::max(0.0, p_d / p_u);
    const double critical = std::pow(2.0 / (g + 1.0), g / (g - 1.0));
    const double scale = cd * area * p_u / std::sqrt(rs * t_u);
    if (r <= critical)
        return scale * std::sqrt(g) * std::pow(2.0 / (g + 1.0), (g + 1.0) / (2.0 * (g - 1.0)));
    auto subsonic = [&](double x) {
        return scale * std::sqrt(2.0 * g / (g - 1.0) *
                                 std::max(0.0, std::pow(x, 2.0 / g) - std::pow(x, (g + 1.0) / g)));
    };
    if (r < kLinear) return subsonic(r);
    return subsonic(kLinear) * (1.0 - r) / (1.0 - kLinear);
}

/// Temperature [K] of body b's gas at the evaluation: theta for an isothermal gas,
/// theta (V_ref / V)^(g - 1) for an adiabatic one.
inline double temperature(const Model& m, const BodyGas& gas, index b) {
    const double theta = gas.theta[b];
    if (m.gases.law[b] != GasLaw::ADIABATIC) return theta;
    return theta * std::pow(m.gases.reference_volume[b] / gas.volume[b], m.gases.gamma[b] - 1.0);
}

/// Moles per pascal [mol/Pa] of body b's gas at its volume and temperature: V / (R T).
inline double moles_per_pascal(const Model& m, const BodyGas& gas, index b) {
    return gas.volume[b] / (kGasConstant * temperature(m, gas, b));
}

/// Whether body b's gas exchanges with flows: closed, of an ideal-gas law, not prescribed
/// (no schedule, no Control override), with a state.
inline bool open_gas(const Model& m, const Control& c, const BodyGas& gas, index b) {
    return gas.moles != nullptr && m.bodies.closed[b] != 0 &&
           m.gases.law[b] != GasLaw::FIXED_PRESSURE &&
           m.gases.schedule_range[2 * b + 1] == m.gases.schedule_range[2 * b] &&
           !std::isfinite(c.gas_override[b]) && gas.volume[b] > 0.0;
}

/// A flow of `mdot` [kg/s] out of body `from` (or from the ambient air, -1) into body `to`
/// (or -1), capped by the limiter at `equalise` [mol] per step over the upstream paths
/// (infinite: no cap, an inflator); `body` the body whose species flows; t_in [K] the
/// temperature the gas arrives with.
inline void add_flow(const Model& m, const BodyGas& gas, index from, index to, index body,
                     double mdot, double equalise, double t_in) {
    double n = mdot / m.gases.molar_mass[body];
    if (gas.flow_step > 0.0) {
        const index paths = from >= 0 ? std::max<index>(1, m.gases.flow_paths[from]) : 1;
        n = std::min(n, std::max(0.0, equalise) / (static_cast<double>(paths) * gas.flow_step));
    }
    if (!(n > 0.0)) return;
    if (from >= 0) gas.flow_out[from] += n;
    if (to >= 0) {
        gas.flow_in[to] += n;
        gas.flow_in_t[to] += n * t_in;
    }
}

/// A body's exchange with its ambient air through an opening: out at the body's state
/// when P > P_a, in from the ambient (P_a, T_ambient) otherwise. mdot_of(p_u, t_u, p_d).
template <class Law>
inline void exchange_with_ambient(const Model& m, const BodyGas& gas, index b, Law mdot_of) {
    const double p = gas.pressure[b], pa = m.gases.ambient_pressure[b];
    const double t = temperature(m, gas, b), ta = m.gases.ambient_temperature[b];
    const double equalise = std::fabs(p - pa) * moles_per_pascal(m, gas, b);
    if (p > pa)
        add_flow(m, gas, b, -1, b, mdot_of(p, t, pa), equalise, t);
    else if (pa > p)
        add_flow(m, gas, -1, b, b, mdot_of(pa, ta, p), equalise, ta);
}

/// Whether vent k is open at e: latched open, past its opening time, or at its opening
/// gauge pressure now.
inline bool vent_is_open(const Eval& e, index k) {
    const Model& m = e.m;
    const index b = m.vents.body[k];
    if (e.gas.vent_open != nullptr && e.gas.vent_open[k] != 0.0) return true;
    if (e.t >= m.vents.open_time[k]) return true;
    return e.gas.pressure[b] - m.gases.ambient_pressure[b] >= m.vents.open_pressure[k];
}

/// Vents: orifices from a body to its ambient pressure (ModelBuilder.add_vent).
struct VentTerm : TermBase {
    static constexpr const char* kName = "vents";
    static constexpr bool kFlow = true;
    static bool active(const Model& m, const Control&) { return m.vents.count > 0; }
    static void flow(const Eval& e) {
        const Model& m = e.m;
        for (index k = 0; k < m.vents.count; ++k) {
            const index b = m.vents.body[k];
            if (!open_gas(m, e.c, e.gas, b) || !vent_is_open(e, k)) continue;
            const double area =
                std::isfinite(e.c.vent_area[k]) ? e.c.vent_area[k] : m.vents.area[k];
            const double cd = m.vents.discharge[k], g = m.gases.gamma[b];
            const double mm = m.gases.molar_mass[b];
            exchange_with_ambient(m, e.gas, b, [&](double pu, double tu, double pd) {
                return orifice_mass_flow(cd, area, pu, tu, pd, g, mm);
            });
        }
    }
};

/// Orifices: gas flows both ways between two bodies (ModelBuilder.add_orifice).
struct OrificeTerm : TermBase {
    static constexpr const char* kName = "orifices";
    static constexpr bool kFlow = true;
    static bool active(const Model& m, const Control&) { return m.orifices.count > 0; }
    static void flow(const Eval& e) {
        const Model& m = e.m;
        const BodyGas& gas = e.gas;
        for (index k = 0; k < m.orifices.count; ++k) {
            index u = m.orifices.bodies[2 * k], d = m.orifices.bodies[2 * k + 1];
            if (!open_gas(m, e.c, gas, u) || !open_gas(m, e.c, gas, d)) continue;
            if (gas.pressure[d] > gas.pressure[u]) std::swap(u, d);
            if (!(gas.pressure[u] > gas.pressure[d])) continue;
            const double area =
                std::isfinite(e.c.orifice_area[k]) ? e.c.orifice_area[k] : m.orifices.area[k];
            const double t_u = temperature(m, gas, u);
            const double mdot =
                orifice_mass_flow(m.orifices.discharge[k], area, gas.pressure[u], t_u,
                                  gas.pressure[d], m.gases.gamma[u], m.gases.molar_mass[u]);
            // moving x moles changes P_u by -x / c_u and P_d by x / c_d: equal after
            // x = (P_u - P_d) / (1 / c_u + 1 / c_d), c = V / (R T)
            const double equalise = (gas.pressure[u] - gas.pressure[d]) /
                                    (1.0 / moles_per_pascal(m, gas, u) +
                                     1.0 / moles_per_pascal(m, gas, d));
            add_flow(m, gas, u, d, u, mdot, equalise, t_u);
        }
    }
};

/// Inflator k's mass flow [kg/s] at time t: the Control's where finite, else its
/// piecewise-linear table (held before the first and after the last row).
inline double inflator_flow(const Model& m, const Control& c, index k, double t) {
    if (std::isfinite(c.inflator_flow[k])) return c.inflator_flow[k];
    const index begin = m.inflators.range[2 * k], end = m.inflators.range[2 * k + 1];
    if (end == begin) return 0.0;
    const double* time = m.inflators.time;
    const double* flow = m.inflators.mass_flow;
    if (t <= time[begin]) return flow[begin];
    for (index s = begin + 1; s < end; ++s)
        if (t < time[s]) {
            const double w = (t - time[s - 1]) / (time[s] - time[s - 1]);
            return flow[s - 1] + w * (flow[s] - flow[s - 1]);
        }
    return flow[end - 1];
}

/// Inflators: gas of the body's species delivered at a given mass flow and temperature
/// (ModelBuilder.add_inflator).
struct InflatorTerm : TermBase {
    static constexpr const char* kName = "inflators";
    static constexpr bool kFlow = true;
    static bool active(const Model& m, const Control&) { return m.inflators.count > 0; }
    static void flow(const Eval& e) {
        const Model& m = e.m;
        for (index k = 0; k < m.inflators.count; ++k) {
            const index b = m.inflators.body[k];
            if (!open_gas(m, e.c, e.gas, b)) continue;
            add_flow(m, e.gas, -1, b, b, inflator_flow(m, e.c, k, e.t),
                     std::numeric_limits<double>::infinity(), m.inflators.temperature[k]);
        }
    }
};

/// Surface area [m^2] of body b at q (N, 3).
inline double body_area(const Model& m, const double* q, index b) {
    double area = 0.0;
    for (index t = m.bodies.tri_range[2 * b]; t < m.bodies.tri_range[2 * b + 1]; ++t) {
        const V3 a = load(q, m.triangles.indices[3 * t]);
        const V3 n = cross(load(q, m.triangles.indices[3 * t + 1]) - a,
                           load(q, m.triangles.indices[3 * t + 2]) - a);
        area += 0.5 * std::sqrt(dot(n, n));
    }
    return area;
}

/// Fabric leakage: mdot = c A |P - P_a| through the body's current area A, out at the
/// body's state or in from the ambient air (ModelBuilder.add_leak).
struct LeakTerm : TermBase {
    static constexpr const char* kName = "leaks";
    static constexpr bool kFlow = true;
    static bool active(const Model& m, const Control&) {
        for (index b = 0; b < m.bodies.count; ++b)
            if (m.gases.leak[b] > 0.0) return true;
        return false;
    }
    static void flow(const Eval& e) {
        const Model& m = e.m;
        for (index b = 0; b < m.bodies.count; ++b) {
            const double coefficient = m.gases.leak[b];
            if (!(coefficient > 0.0) || !open_gas(m, e.c, e.gas, b)) continue;
            const double area = body_area(m, e.q, b);
            exchange_with_ambient(m, e.gas, b, [&](double pu, double, double pd) {
                return coefficient * area * (pu - pd);
            });
        }
    }
};

}  // namespace softbody::SOFTBODY_KERNELS::flows
