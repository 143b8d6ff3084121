"""Gas that flows: the orifice law, vents, orifices, inflators and leaks
(``core/terms/flows.hpp``), in NumPy.

The orifice law, from the higher-pressure side u (P_u [Pa], T_u [K]) to the lower d,
r = P_d / P_u, gamma g, R_s = R / M [J/(kg K)], area A [m^2], discharge coefficient C_d:

    choked (r <= r_c = (2 / (g + 1))^(g / (g - 1))):
        mdot = C_d A P_u sqrt(g / (R_s T_u)) (2 / (g + 1))^((g + 1) / (2 (g - 1)))
    subsonic:
        mdot = C_d A P_u sqrt(2 g / ((g - 1) R_s T_u) (r^(2/g) - r^((g+1)/g)))
    above r = 0.9999: linear in (1 - r) from its value there to 0 at r = 1     [kg/s]

A fabric leak is mdot = c A_body |P - P_a|. The flows move gas, not particles: their force
is zero, and what they do is to the gas state (``softbody.body_gas_flows``).
"""

from __future__ import annotations

import numpy as np

from softbody.gas import GAS_CONSTANT

#: Above this pressure ratio the subsonic law tapers linearly to 0 at r = 1.
LINEAR = 0.9999


def orifice_mass_flow(cd, area, p_u, t_u, p_d, gamma, molar_mass):
    """Mass flow [kg/s] of the orifice law (module docstring), element-wise, for
    p_d <= p_u; 0 where p_u, t_u, area, cd or the molar mass is not positive."""
    cd, area, p_u, t_u, p_d, g, mm = np.broadcast_arrays(
        *(np.asarray(v, dtype=np.float64) for v in (cd, area, p_u, t_u, p_d, gamma, molar_mass))
    )
    ok = (p_u > 0) & (t_u > 0) & (area > 0) & (cd > 0) & (mm > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = GAS_CONSTANT / mm
        r = np.maximum(0.0, p_d / p_u)
        critical = (2.0 / (g + 1.0)) ** (g / (g - 1.0))
        scale = cd * area * p_u / np.sqrt(rs * t_u)
        choked = scale * np.sqrt(g) * (2.0 / (g + 1.0)) ** ((g + 1.0) / (2.0 * (g - 1.0)))

        def subsonic(x):
            core = np.maximum(0.0, x ** (2.0 / g) - x ** ((g + 1.0) / g))
            return scale * np.sqrt(2.0 * g / (g - 1.0) * core)

        tapered = subsonic(np.full_like(r, LINEAR)) * (1.0 - r) / (1.0 - LINEAR)
        flow = np.where(r <= critical, choked, np.where(r < LINEAR, subsonic(r), tapered))
    return np.where(ok, flow, 0.0)


def _no_force(model, control, t, q, qd, gas):
    return np.zeros_like(q)


TERMS = {name: _no_force for name in ("vents", "orifices", "inflators", "leaks")}

