"""Quadratic air drag on the faces of bodies (``core/terms/drag.hpp``).

Face t with corners i, j, k, vector area a_t = A_t n_t = (x_j - x_i) x (x_k - x_i) / 2
[m^2] and velocity v_t = (v_i + v_j + v_k) / 3, moving at v_rel = v_t - w relative to the
wind w [m/s] (``Control.wind`` when set, else the model's), in air of density rho
[kg/m^3], with its body's drag coefficient C_d [1]:

    F_t = -1/2 rho C_d A_t (v_rel . n_t) |v_rel . n_t| n_t
        = -1/2 rho C_d s |s| a_t / |a_t|^2,   s = v_rel . a_t              [N]

shared equally by the three corners. Dissipative: no energy; its power is
P = sum_t F_t . v_t [W] (<= 0 in still air). A face of zero area feels nothing; bodies
with C_d = 0 and air of density 0 none at all.
"""

from __future__ import annotations

import numpy as np

from softbody.reference._inputs import wind
from softbody.sim.control import ControlData
from softbody.sim.model import Model


def face_forces(model: Model, control: ControlData, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """F_t of every face [N], shape (T, 3) (zero on faces of bodies with C_d = 0)."""
    tri = model.tri_indices
    a = 0.5 * np.cross(q[tri[:, 1]] - q[tri[:, 0]], q[tri[:, 2]] - q[tri[:, 0]])
    a2 = np.einsum("tk,tk->t", a, a)
    v_rel = (qd[tri[:, 0]] + qd[tri[:, 1]] + qd[tri[:, 2]]) / 3.0 - wind(model, control)
    s = np.einsum("tk,tk->t", v_rel, a)  # A_t (v_rel . n_t) [m^3/s]
    half_rho_cd = 0.5 * model.air_density * model.body_drag_coefficient[model.tri_body]
    with np.errstate(divide="ignore", invalid="ignore"):
        mag = -half_rho_cd * s * np.abs(s) / a2
    return np.where(((a2 > 0.0) & (half_rho_cd > 0.0))[:, None], mag[:, None] * a, 0.0)


def force(model: Model, control: ControlData, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Drag on each particle [N], shape (N, 3): a third of each of its faces' F_t."""
    share = face_forces(model, control, q, qd) / 3.0
    f = np.zeros_like(q, dtype=np.float64)
    for corner in range(3):
        np.add.at(f, model.tri_indices[:, corner], share)
    return f


def power(model: Model, control: ControlData, q: np.ndarray, qd: np.ndarray) -> float:
    """The power drag delivers to the particles, sum_t F_t . v_t [W]."""
    tri = model.tri_indices
    v = (qd[tri[:, 0]] + qd[tri[:, 1]] + qd[tri[:, 2]]) / 3.0
    return float(np.einsum("tk,tk->", face_forces(model, control, q, qd), v))


#: This term's force for softbody.reference.forces (by its name in the core's registry).
TERMS = {"drag": lambda model, control, t, q, qd, gas: force(model, control, q, qd)}
