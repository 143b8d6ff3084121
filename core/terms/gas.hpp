// The gas inside each body and its pressure force (paper, section 2.2, and softbody.gas).
//
//   isothermal      P = nRT / V                  E = -nRT ln V
//   fixed pressure  P = P0                       E = -P0 V
//   adiabatic       P = nRT V_ref^(g-1) / V^g     E = nRT V_ref^(g-1) V^(1-g) / (g - 1)
//
// The force on particle i is (P - P_ambient) dV/dx_i: each face's (P - P_a) A n shared by its
// three corners. With the exact volume it is minus the gradient of E + P_a V, with zero net
// force and torque. The driving value (nRT or P0) follows a schedule or a Control override.
//
// Forms: value_at, pressure(s), evaluate (volumes by volume.hpp, then P); force and
// lane_face / lane_faces (dV/dx in the vertex-major pass); law_energy and energies (per
// body, at its volume by its own method; 0 for an open surface); pressure_slopes +
// jacobian_product (P'(V) g g^T + (P - P_a) d2V/dx2, the implicit solvers); bound_slopes,
// add_pressure_rows and rank_one_bound (the stability estimate: the local term's Gershgorin
// rows and the breathing mode's rank-one eigenvalue). No projection: projective dynamics
// takes the pressure explicitly within its iteration.
#pragma once

#include <algorithm>

#include "model.hpp"
#include "simd.hpp"
#include "terms/term.hpp"
#include "terms/volume.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::gas {

constexpr double kGasConstant = 8.314462618;  // R [J / (mol K)]

/// Body b's driving value (nRT [J] or P0 [Pa]) at time t [s] by the model: its
/// piecewise-linear schedule, else its value.
inline double model_value_at(const Model& m, index b, double t) {
    const index begin = m.gases.schedule_range[2 * b], end = m.gases.schedule_range[2 * b + 1];
    if (end == begin) return m.gases.value[b];
    const double* time = m.gases.schedule_time;
    const double* value = m.gases.schedule_value;
    if (t <= time[begin]) return value[begin];
    for (index s = begin + 1; s < end; ++s)
        if (t < time[s]) {
            const double w = (t - time[s - 1]) / (time[s] - time[s - 1]);
            return value[s - 1] + w * (value[s] - value[s - 1]);
        }
    return value[end - 1];
}

/// The driving value (nRT [J] or P0 [Pa]) of body b at time t [s]: a finite override wins,
/// else the model's (model_value_at).
inline double value_at(const Model& m, const Control& c, index b, double t) {
    if (std::isfinite(c.gas_override[b])) return c.gas_override[b];
    return model_value_at(m, b, t);
}

/// Absolute pressure [Pa] of a gas law at volume v [m^3] (NaN for v <= 0 unless fixed).
inline double pressure(index law, double value, double gamma, double reference_volume, double v) {
    if (law == GasLaw::FIXED_PRESSURE) return value;
    if (!(v > 0.0)) return std::numeric_limits<double>::quiet_NaN();
    if (law == GasLaw::ISOTHERMAL) return value / v;
    return value * std::pow(reference_volume, gamma - 1.0) / std::pow(v, gamma);
}

/// Whether body b's driving value is prescribed at time t (a fixed pressure, a schedule or
/// a Control override), not its gas state's.
inline bool prescribed(const Model& m, const Control& c, index b) {
    return m.gases.law[b] == GasLaw::FIXED_PRESSURE || std::isfinite(c.gas_override[b]) ||
           m.gases.schedule_range[2 * b + 1] > m.gases.schedule_range[2 * b];
}

/// The driving value of body b at time t with the gas state in gas: nRT = R n theta from
/// the state (terms/flows.hpp) unless prescribed or there is no state (value_at).
inline double driving_value(const Model& m, const Control& c, const BodyGas& gas, index b,
                            double t) {
    if (gas.moles == nullptr || prescribed(m, c, b)) return value_at(m, c, b, t);
    return kGasConstant * gas.moles[b] * gas.theta[b];
}

/// The pressure of every body at time t from the volumes in gas.
inline void pressures(const Model& m, const Control& c, double t, const BodyGas& gas) {
    for (index b = 0; b < m.bodies.count; ++b)
        gas.pressure[b] = pressure(m.gases.law[b], driving_value(m, c, gas, b, t),
                                   m.gases.gamma[b], m.gases.reference_volume[b], gas.volume[b]);
}

/// Volumes (with gas.volume_gradient set, their gradients too) and the pressures of every
/// body at time t, into gas.
inline void evaluate(const Model& m, const Control& c, double t, const double* q,
                     const BodyGas& gas) {
    volume::evaluate(m, q, gas);
    pressures(m, c, t, gas);
}

/// f_i += (P_b - P_ambient,b) dV/dx_i for the particles of every body.
inline void force(const Model& m, const BodyGas& gas, double* f) {
    for (index b = 0; b < m.bodies.count; ++b) {
        const double p = gas.pressure[b] - m.gases.ambient_pressure[b];
        for (index k = 3 * m.bodies.particle_range[2 * b]; k < 3 * m.bodies.particle_range[2 * b + 1];
             ++k)
            f[k] += p * gas.volume_gradient[k];
    }
}

/// Vertex-major: a face (i, j, k) at the kLanes particles i, from u = x_j - x_i and
/// w = x_k - x_i, times `weight` (1, or 0 for no face): its n / 6 = (u x w) / 6 added to
/// dV/dx (gx, gy, gz) [m^2], and its (x_i - r) . n to six_v, a third of the face's share of
/// 6 V seen from each corner (r: the body's reference point; sum over corners is exact).
/// V: lanes of doubles, or of floats for the float32 force pass.
template <class V>
inline void lane_face(V ux, V uy, V uz, V wx, V wy, V wz, V weight, V rx, V ry, V rz, V& gx,
                      V& gy, V& gz, V& six_v) {
    const V nx = weight * (uy * wz - uz * wy);
    const V ny = weight * (uz * wx - ux * wz);
    const V nz = weight * (ux * wy - uy * wx);
    const V sixth = lanes_of<V>(volume::kSixth);
    gx += sixth * nx;
    gy += sixth * ny;
    gz += sixth * nz;
    six_v += rx * nx + ry * ny + rz * nz;
}

/// Vertex-major: the faces of particles whose faces make no single fan (model.hpp), slots of
/// group g from lane0; r = x_i - reference per lane.
inline void lane_faces(const Model& m, const double* rows, index g, int lane0, const Rows& self,
                       vd rx, vd ry, vd rz, vd& gx, vd& gy, vd& gz, vd& six_v) {
    for (index s = m.slots.face_start[g]; s < m.slots.face_start[g + 1]; ++s) {
        const index e = kGroup * s + lane0;
        const Rows b = load_rows(rows, m.slots.face_next + e);
        const Rows c = load_rows(rows, m.slots.face_last + e);
        lane_face(b.x - self.x, b.y - self.y, b.z - self.z, c.x - self.x, c.y - self.y,
                  c.z - self.z, splat(1.0), rx, ry, rz, gx, gy, gz, six_v);
    }
}

/// dP/dV (B,) [Pa/m^3] of each body's gas law at its volume, and P - P_ambient (B,) [Pa].
inline void pressure_slopes(const Model& m, const BodyGas& gas, double* dpdv, double* pnet) {
    for (index b = 0; b < m.bodies.count; ++b) {
        const double v = gas.volume[b], p = gas.pressure[b];
        pnet[b] = p - m.gases.ambient_pressure[b];
        const index law = m.gases.law[b];
        if (law == GasLaw::FIXED_PRESSURE || m.bodies.closed[b] == 0 || !(v > 0.0))
            dpdv[b] = 0.0;  // fixed pressure (or an open surface)
        else if (law == GasLaw::ISOTHERMAL)
            dpdv[b] = -p / v;  // isothermal: P = nRT / V
        else
            dpdv[b] = -m.gases.gamma[b] * p / v;  // adiabatic: P V^gamma constant
    }
}

/// out += alpha_k K p for the pressure: per body P'(V) g (g . p) + (P - P_a) H p with g =
/// dV/dx (N, 3) and H = d2V/dx2, applied face by face: each corner's share of g is the
/// face's (e1 x e2) / 6, whose change under p is (d1 x e2 + e1 x d2) / 6 (d the same
/// differences of p), added to all three corners. Never a dense matrix.
inline void jacobian_product(const Model& m, const double* q, const double* gradient,
                             const double* dpdv, const double* pnet, double alpha_k,
                             const double* p, double* out) {
    if (alpha_k == 0.0) return;
    for (index body = 0; body < m.bodies.count; ++body) {
        const index p0 = m.bodies.particle_range[2 * body], p1 = m.bodies.particle_range[2 * body + 1];
        double gp = 0.0;
        for (index i = p0; i < p1; ++i) gp += dot(load(gradient, i), load(p, i));
        const double c1 = alpha_k * dpdv[body] * gp;
        if (c1 != 0.0)
            for (index i = p0; i < p1; ++i) add_to(out, i, c1 * load(gradient, i));
        const double coef = alpha_k * pnet[body] / 6.0;
        if (coef == 0.0) continue;
        for (index t = m.bodies.tri_range[2 * body]; t < m.bodies.tri_range[2 * body + 1]; ++t) {
            const index ia = m.triangles.indices[3 * t], ib = m.triangles.indices[3 * t + 1],
                        ic = m.triangles.indices[3 * t + 2];
            const V3 a = load(q, ia);
            const V3 e1 = load(q, ib) - a, e2 = load(q, ic) - a;
            const V3 pa = load(p, ia);
            const V3 d1 = load(p, ib) - pa, d2 = load(p, ic) - pa;
            const V3 h = coef * (cross(d1, e2) + cross(e1, d2));
            add_to(out, ia, h);
            add_to(out, ib, h);
            add_to(out, ic, h);
        }
    }
}

/// Potential energy E(V) + P_a V [J] of a gas law (the table above) at volume v [m^3]
/// with driving value `value` (nRT [J] or P0 [Pa]); NaN or inf where the law has none
/// (V <= 0 for isothermal and adiabatic), as its pressure.
inline double law_energy(index law, double value, double gamma, double reference_volume,
                         double ambient_pressure, double v) {
    double e;
    if (law == GasLaw::ISOTHERMAL)
        e = -value * std::log(v);
    else if (law == GasLaw::FIXED_PRESSURE)
        e = -value * v;
    else
        e = value * std::pow(reference_volume, gamma - 1.0) * std::pow(v, 1.0 - gamma) /
            (gamma - 1.0);
    return e + ambient_pressure * v;
}

/// Gas energy E(V) + P_a V [J] of every body at time t from its volume gas.volume (B,)
/// [m^3] (its own method's), into body_energy (B,) (set, not added); 0 for an open surface,
/// which holds no gas (the work of its pressure is not counted). Returns the total [J].
inline double energies(const Model& m, const Control& c, double t, const BodyGas& gas,
                       double* body_energy) {
    double total = 0.0;
    for (index b = 0; b < m.bodies.count; ++b) {
        const double e =
            m.bodies.closed[b] == 1
                ? law_energy(m.gases.law[b], driving_value(m, c, gas, b, t), m.gases.gamma[b],
                             m.gases.reference_volume[b], m.gases.ambient_pressure[b],
                             gas.volume[b])
                : 0.0;
        body_energy[b] = e;
        total += e;
    }
    return total;
}

/// Stiffness bound, the gas's state: every body's exact volume at q and dV/dx into gradient
/// (N, 3) [m^2], P - P_a into pnet (B,) [Pa] and P'(V) into dpdv (B,) [Pa/m^3], with the gas
/// at its largest scheduled value (max of the value, its schedule's points and 0), so that
/// the bound holds for the whole run; open surfaces alike (a gust on a cloth).
inline void bound_slopes(const Model& m, const double* q, double* pnet, double* dpdv,
                         double* gradient) {
    for (index b = 0; b < m.bodies.count; ++b) {
        const double v = volume::exact(m, b, q, gradient);
        double value = std::max(m.gases.value[b], 0.0);
        for (index s = m.gases.schedule_range[2 * b]; s < m.gases.schedule_range[2 * b + 1]; ++s)
            value = std::max(value, m.gases.schedule_value[s]);
        double p, slope;
        if (m.gases.law[b] == GasLaw::FIXED_PRESSURE) {
            p = value, slope = 0.0;  // fixed pressure
        } else if (m.gases.law[b] == GasLaw::ISOTHERMAL) {
            p = value / v, slope = -value / (v * v);  // isothermal
        } else {
            const double gamma = m.gases.gamma[b];
            p = value * std::pow(m.gases.reference_volume[b], gamma - 1.0) / std::pow(v, gamma);
            slope = -gamma * p / v;  // adiabatic
        }
        pnet[b] = p - m.gases.ambient_pressure[b];
        dpdv[b] = slope;
    }
}

/// Stiffness bound, the local pressure term (P - P_a) d2V/dx2: for a face (i, j, l) its
/// block coupling i to j has norm |P - P_a| |x_l - x_i| / 6, so Gershgorin on
/// M^-1/2 K M^-1/2 adds |P - P_a| / 6 (|x_l - x_i| / sqrt(m_i m_j) + |x_j - x_i| /
/// sqrt(m_i m_l)) to row i, per corner of every face, into rows (N,) [1/s^2]. pnet from
/// bound_slopes.
inline void add_pressure_rows(const Model& m, const double* q, const double* pnet, double* rows) {
    const double* inv = m.particles.inv_mass;
    for (index b = 0; b < m.bodies.count; ++b) {
        const double coef = std::abs(pnet[b]) / 6.0;
        for (index t = m.bodies.tri_range[2 * b]; t < m.bodies.tri_range[2 * b + 1]; ++t) {
            const index* tri = m.triangles.indices + 3 * t;
            for (int corner = 0; corner < 3; ++corner) {
                const index i = tri[corner], j = tri[(corner + 1) % 3], l = tri[(corner + 2) % 3];
                const V3 xi = load(q, i);
                const V3 dj = load(q, j) - xi, dl = load(q, l) - xi;
                rows[i] += coef * (std::sqrt(dot(dl, dl)) * std::sqrt(inv[i] * inv[j]) +
                                   std::sqrt(dot(dj, dj)) * std::sqrt(inv[i] * inv[l]));
            }
        }
    }
}

/// Stiffness bound, the rank-one term P'(V) g g^T of each body (g = dV/dx: the breathing
/// mode, the gas's resistance to a change of volume): its one nonzero eigenvalue against
/// the masses, |P'(V)| sum_i |g_i|^2 / m_i [1/s^2], largest over bodies. dpdv and gradient
/// from bound_slopes.
inline double rank_one_bound(const Model& m, const double* dpdv, const double* gradient) {
    double bound = 0.0;
    for (index b = 0; b < m.bodies.count; ++b) {
        double sum = 0.0;
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1]; ++i) {
            const V3 g = load(gradient, i);
            sum += m.particles.inv_mass[i] * dot(g, g);
        }
        bound = std::max(bound, std::abs(dpdv[b]) * sum);
    }
    return bound;
}

/// The registered term (terms/registry.hpp). Its update refreshes the volumes (those the
/// vertex-major pass did not sum when it ran), dV/dx and the pressures every force reads.
struct Term : TermBase {
    static constexpr const char* kName = "gas";
    static constexpr bool kFused = true, kEnergy = true, kBound = true, kVolumeMode = true;
    static constexpr bool kSpectral = true;
    /// The stability estimate: the local pressure rows, and the volume mode (out.mode)
    /// added to them (undamped and whole parts), at the largest scheduled gas; the gas's
    /// state there into s.body_pnet, body_dpdv, volume_gradient.
    static void bound(const Model& m, const Control&, const double* q, const BoundScratch& s,
                      TermBound& out) {
        const index n = m.particles.count;
        std::fill(s.volume_gradient, s.volume_gradient + 3 * n, 0.0);
        bound_slopes(m, q, s.body_pnet, s.body_dpdv, s.volume_gradient);
        std::fill(s.rows, s.rows + n, 0.0);
        add_pressure_rows(m, q, s.body_pnet, s.rows);
        double rows = 0.0;
        for (index i = 0; i < n; ++i) rows = std::max(rows, s.rows[i]);
        out.mode = rank_one_bound(m, s.body_dpdv, s.volume_gradient);
        out.parts[1] = out.parts[2] = rows + out.mode;
    }
    static void update(const Eval& e, bool lanes_ran) {
        volume::evaluate(e.m, e.q, e.gas, lanes_ran);
        pressures(e.m, e.c, e.t, e.gas);
    }
    static void force(const Eval& e, double* f) { gas::force(e.m, e.gas, f); }
    /// Each body's gas energy at its volume by its own method (into e.gas.volume; no dV/dx
    /// when e.gas.volume_gradient is null).
    static double energy(const Eval& e, double* body) {
        volume::evaluate(e.m, e.q, e.gas);
        return energies(e.m, e.c, e.t, e.gas, body);
    }
    /// Linearisation: P'(V) (B,) [Pa/m^3], then P - P_a (B,) [Pa], from the gas state at
    /// the point (e.gas, refreshed there).
    static index linearization_size(const Model& m) { return 2 * m.bodies.count; }
    static void prepare(const Eval& e, const Linearization& l) {
        pressure_slopes(e.m, e.gas, l.own, l.own + e.m.bodies.count);
    }
    static void jacobian_product(const Model& m, const Control&, const Linearization& l,
                                 double, double alpha_k, const double* p, double* out) {
        gas::jacobian_product(m, l.q, l.volume_gradient, l.own, l.own + m.bodies.count, alpha_k,
                              p, out);
    }
    /// The stability estimate's linearisation: P'(V) and P - P_a at the largest scheduled
    /// gas, as its bound form left them in s (l.volume_gradient: the bound's dV/dx).
    static void prepare_spectral(const Eval& e, const BoundScratch& s, const Linearization& l) {
        const index bodies = e.m.bodies.count;
        std::copy(s.body_dpdv, s.body_dpdv + bodies, l.own);
        std::copy(s.body_pnet, s.body_pnet + bodies, l.own + bodies);
    }
    /// The split: the pressure rows and the volume mode are undamped stiffness (no damper
    /// acts on them): in the undamped and whole parts.
    static void spectral_product(const Model& m, const Control& c, const Linearization& l,
                                 StiffnessPart part, const double* p, double* out) {
        if (part == StiffnessPart::kUndamped || part == StiffnessPart::kWhole)
            jacobian_product(m, c, l, 0.0, 1.0, p, out);
    }
};

}  // namespace softbody::SOFTBODY_KERNELS::gas
