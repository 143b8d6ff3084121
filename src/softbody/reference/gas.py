"""The gas in each body and its pressure force (``core/terms/gas.hpp``; paper, section 2.2).

Each body b has a gas law, a driving value (nRT [J], or P0 [Pa] for fixed pressure), an
adiabatic exponent gamma and reference volume V_ref [m^3], and an ambient pressure P_a:

    law               P(V)                          E(V), with -dE/dV = P
    0 isothermal      nRT / V                       -nRT ln V
    1 fixed pressure  P0                            -P0 V
    2 adiabatic       nRT V_ref^(g-1) / V^g          nRT V_ref^(g-1) V^(1-g) / (g - 1)

The force on particle i of body b is (P - P_a) dV/dx_i (each face's (P - P_a) n_t / 6 on
its corners). For a closed body of the exact volume it is -d/dx of E(V(x)) + P_a V(x), and
its net force and torque vanish. The driving value at time t is ``Control.gas_override``
where finite, else the body's piecewise-linear schedule (held before its first and after
its last point), else the model's value.

Jacobian: d/dx [(P - P_a) g] = P'(V) g g^T + (P - P_a) H with g = dV/dx and H = d2V/dx2;
P'(V) is -P / V (isothermal), -gamma P / V (adiabatic), 0 for fixed pressure or an open
surface. H applied to p adds each face's (d1 x e2 + e1 x d2) / 6 to its three corners
(e1, e2 its edges from its first corner, d1, d2 the same differences of p).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from softbody.sim.control import ControlData
from softbody.sim.model import Model

ISOTHERMAL, FIXED_PRESSURE, ADIABATIC = 0, 1, 2


def schedule_value(time: np.ndarray, value: np.ndarray, t: float) -> float:
    """A piecewise-linear schedule (times (K,) [s] increasing, values (K,)) at t [s]:
    held at its first value up to time[0] and its last from time[-1]; between points
    value[s-1] + w (value[s] - value[s-1]), w = (t - time[s-1]) / (time[s] - time[s-1])."""
    if t <= time[0]:
        return float(value[0])
    s = int(np.searchsorted(time, t, side="right"))  # first point later than t
    if s >= len(time):
        return float(value[-1])
    w = (t - time[s - 1]) / (time[s] - time[s - 1])
    return float(value[s - 1] + w * (value[s] - value[s - 1]))


def driving_values(model: Model, control: ControlData, t: float) -> np.ndarray:
    """Each body's driving value at time t [s] (nRT [J] or P0 [Pa]), shape (B,)."""
    out = np.array(model.body_gas_value, dtype=np.float64)
    for b, (k0, k1) in enumerate(model.body_schedule_range):
        if k1 > k0:
            out[b] = schedule_value(model.schedule_time[k0:k1], model.schedule_value[k0:k1], t)
    override = np.asarray(control.gas_override, dtype=np.float64)
    return np.where(np.isfinite(override), override, out)


def law_pressure(
    law: np.ndarray, value: np.ndarray, gamma: np.ndarray, reference_volume: np.ndarray,
    volume: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """Absolute pressure P(V) [Pa] of each gas law (table above), element-wise; NaN at
    V <= 0 except for fixed pressure."""
    law, value, gamma = np.asarray(law), np.asarray(value, float), np.asarray(gamma, float)
    v = np.asarray(volume, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        iso = value / v
        adi = value * reference_volume ** (gamma - 1.0) / v**gamma
    p = np.where(law == ISOTHERMAL, iso, adi)
    p = np.where(v > 0.0, p, np.nan)
    return np.where(law == FIXED_PRESSURE, value, p)


def law_energy(
    law: np.ndarray, value: np.ndarray, gamma: np.ndarray, reference_volume: np.ndarray,
    ambient_pressure: np.ndarray, volume: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """Potential energy E(V) + P_a V [J] of each body's gas (table above), element-wise:
    its -d/dV is the net pressure P - P_a."""
    law = np.asarray(law)
    v = np.asarray(volume, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        iso = -value * np.log(v)
        fixed = -value * v
        adi = value * reference_volume ** (gamma - 1.0) * v ** (1.0 - gamma) / (gamma - 1.0)
    e = np.where(law == ISOTHERMAL, iso, np.where(law == FIXED_PRESSURE, fixed, adi))
    return e + ambient_pressure * v


def pressures(model: Model, control: ControlData, t: float, volume: np.ndarray) -> np.ndarray:
    """Absolute pressure of every body [Pa], shape (B,), at its volumes (B,) [m^3]."""
    return law_pressure(
        model.body_gas_law,
        driving_values(model, control, t),
        model.body_gas_gamma,
        model.body_gas_reference_volume,
        volume,
    )


def energies(model: Model, control: ControlData, t: float, volume: np.ndarray) -> np.ndarray:
    """Gas energy E(V) + P_a V of every body [J], shape (B,), at its volumes (B,) [m^3];
    0 for an open surface, which holds no gas (the work of its pressure is not counted)."""
    e = law_energy(
        model.body_gas_law,
        driving_values(model, control, t),
        model.body_gas_gamma,
        model.body_gas_reference_volume,
        model.body_ambient_pressure,
        volume,
    )
    return np.where(model.body_closed == 1, e, 0.0)


def force(model: Model, pressure: np.ndarray, gradient: np.ndarray) -> np.ndarray:
    """(P_b - P_a,b) dV/dx_i on every particle i of body b [N], shape (N, 3), from the
    bodies' pressures (B,) [Pa] and dV/dx (N, 3) [m^2]; zero on free particles."""
    net = np.append(np.asarray(pressure) - model.body_ambient_pressure, 0.0)
    per_particle = net[model.particle_body]  # body -1 (a free particle) reads the 0 appended
    return per_particle[:, None] * gradient


class PressureSlopes(NamedTuple):
    """What the pressure Jacobian reads per body (``gas::pressure_slopes``)."""

    dpdv: np.ndarray  # (B,) P'(V) [Pa/m^3]
    pnet: np.ndarray  # (B,) P - P_a [Pa]


def pressure_slopes(model: Model, volume: np.ndarray, pressure: np.ndarray) -> PressureSlopes:
    """P'(V) and P - P_a of every body (module docstring); P' = 0 for fixed pressure, an
    open surface or V <= 0."""
    v, p = np.asarray(volume, float), np.asarray(pressure, float)
    law = model.body_gas_law
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(law == ISOTHERMAL, -p / v, -model.body_gas_gamma * p / v)
    none = (law == FIXED_PRESSURE) | (model.body_closed == 0) | ~(v > 0.0)
    return PressureSlopes(np.where(none, 0.0, slope), p - model.body_ambient_pressure)


def jacobian_product(
    model: Model,
    q: np.ndarray,
    gradient: np.ndarray,
    slopes: PressureSlopes,
    alpha_k: float,
    p: np.ndarray,
) -> np.ndarray:
    """alpha_k K p of the pressure force [N], shape (N, 3), at q (N, 3) for p (N, 3):
    per body alpha_k [P'(V) g (g . p) + (P - P_a) H p] over its particles and faces
    (module docstring), with g = ``gradient`` (N, 3) [m^2]."""
    out = np.zeros_like(p, dtype=np.float64)
    for b, ((p0, p1), (t0, t1)) in enumerate(
        zip(model.body_particle_range, model.body_tri_range, strict=True)
    ):
        g = gradient[p0:p1]
        out[p0:p1] += alpha_k * slopes.dpdv[b] * np.sum(g * p[p0:p1]) * g
        tri = model.tri_indices[t0:t1]
        a, pa = q[tri[:, 0]], p[tri[:, 0]]
        e1, e2 = q[tri[:, 1]] - a, q[tri[:, 2]] - a
        d1, d2 = p[tri[:, 1]] - pa, p[tri[:, 2]] - pa
        h = alpha_k * slopes.pnet[b] / 6.0 * (np.cross(d1, e2) + np.cross(e1, d2))
        for corner in range(3):
            np.add.at(out, tri[:, corner], h)
    return out


def potential_energy(model: Model, control: ControlData, t: float, q: np.ndarray) -> float:
    """Total gas energy [J] at q (N, 3) with every closed body at its exact volume: the
    potential whose -d/dx is :func:`force` at the exact volumes' pressures."""
    from softbody.reference.volume import exact_volumes

    return float(energies(model, control, t, exact_volumes(model, q)).sum())


#: This term's force for softbody.reference.forces (by its name in the core's registry);
#: gas is the state (volume (B,), pressure (B,), dV/dx (N, 3)) at the point.
TERMS = {"gas": lambda model, control, t, q, qd, gas: force(model, gas[1], gas[2])}
