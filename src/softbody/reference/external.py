"""Forces given from outside each call through Control (``core/terms/external.hpp``).

Per-particle forces ``Control.particle_f`` (N, 3) [N], added as given, and the grab spring:
a zero-length spring of stiffness k [N/m] pulling the grabbed particle g toward the target
T [m], damped on its absolute velocity with c [N s/m]:

    f_g = k (T - x_g) - c v_g,   E = 1/2 k |T - x_g|^2,   K = -k I,   C = -c I (on g).
"""

from __future__ import annotations

import numpy as np

from softbody.sim.control import ControlData
from softbody.sim.model import Model


def force(model: Model, control: ControlData) -> np.ndarray:
    """The control's per-particle forces [N], shape (N, 3)."""
    return np.asarray(control.particle_f, dtype=np.float64).reshape(model.particle_count, 3).copy()


def grab_force(control: ControlData, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """The grab spring's force [N], shape (N, 3): k (T - x_g) - c v_g on the grabbed
    particle g, zero elsewhere and when nothing is grabbed (g = -1)."""
    f = np.zeros_like(q, dtype=np.float64)
    g = int(control.grab_particle)
    if g >= 0:
        target = np.asarray(control.grab_target, dtype=np.float64)
        f[g] = control.grab_stiffness * (target - q[g]) - control.grab_damping * qd[g]
    return f


def grab_energy(control: ControlData, q: np.ndarray) -> float:
    """Elastic energy 1/2 k |T - x_g|^2 of the grab spring [J] (0 when nothing is
    grabbed); -dE/dx is the elastic part of :func:`grab_force`."""
    g = int(control.grab_particle)
    if g < 0:
        return 0.0
    d = np.asarray(control.grab_target, dtype=np.float64) - q[g]
    return float(0.5 * control.grab_stiffness * (d @ d))


def grab_jacobian_product(
    control: ControlData, p: np.ndarray, alpha_c: float, alpha_k: float
) -> np.ndarray:
    """(alpha_c C + alpha_k K) p [N] of the grab spring, shape (N, 3):
    -(alpha_k k + alpha_c c) p_g on the grabbed particle."""
    out = np.zeros_like(p, dtype=np.float64)
    g = int(control.grab_particle)
    if g >= 0:
        out[g] = -(alpha_k * control.grab_stiffness + alpha_c * control.grab_damping) * p[g]
    return out


#: These terms' forces for softbody.reference.forces (by their names in the core's
#: registry): Control's per-particle forces and the grab spring.
TERMS = {
    "external": lambda model, control, t, q, qd, gas: force(model, control),
    "grab": lambda model, control, t, q, qd, gas: grab_force(control, q, qd),
}
