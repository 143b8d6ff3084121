"""Damped springs tying particles to anchor points (``core/terms/attachments.hpp``).

Attachment a ties particle i to the anchor A_a (``Control.attachment_anchor``, fixed over
a call). With d = A_a - x_i, L = |d| and u = d / L:

    f_i = [k (L - L0) - c v_i . u] u                                      [N]
    E   = 1/2 k (L - L0)^2                                                [J]
    K   = df_i/dx_i = -(k_iso I + (k - k_iso) u u^T),  k_iso = k max(0, 1 - L0/L)
    C   = df_i/dv_i = -c u u^T

(K drops the compressive geometric part, and the damper's turning with u, as the springs
do; a zero-length attachment has no force and K = -k I.) The anchor does not move with the
particle, so the signs are those of the first end of a spring whose other end is fixed.
"""

from __future__ import annotations

import numpy as np

from softbody.reference.springs import hooke_energy
from softbody.sim.control import ControlData
from softbody.sim.model import Model


def _geometry(model: Model, control: ControlData, q: np.ndarray):
    i = model.attachment_particle
    d = np.asarray(control.attachment_anchor, dtype=np.float64).reshape(-1, 3) - q[i]
    length = np.linalg.norm(d, axis=1)
    live = length > 0.0
    u = np.zeros_like(d)
    u[live] = d[live] / length[live, None]
    return i, length, live, u


def energies(model: Model, control: ControlData, q: np.ndarray) -> np.ndarray:
    """Elastic energy 1/2 k (L - L0)^2 of every attachment [J], shape (A,), at q (N, 3)
    with the anchors of ``control``."""
    _, length, _, _ = _geometry(model, control, q)
    return hooke_energy(length, model.attachment_rest_length, model.attachment_stiffness)


def energy(model: Model, control: ControlData, q: np.ndarray) -> float:
    """Total elastic energy of the attachments [J]."""
    return float(energies(model, control, q).sum())


def force(model: Model, control: ControlData, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Sum of the attachment forces on each particle [N], shape (N, 3)."""
    i, length, live, u = _geometry(model, control, q)
    rel = -np.einsum("ak,ak->a", qd[i], u)  # the anchor's speed toward i: -v_i . u [m/s]
    mag = (
        model.attachment_stiffness * (length - model.attachment_rest_length)
        + model.attachment_damping * rel
    )
    f = np.zeros_like(q, dtype=np.float64)
    np.add.at(f, i, np.where(live[:, None], mag[:, None] * u, 0.0))
    return f


def jacobian_product(
    model: Model,
    control: ControlData,
    q: np.ndarray,
    p: np.ndarray,
    alpha_c: float,
    alpha_k: float,
) -> np.ndarray:
    """(alpha_c C + alpha_k K) p [N] of the attachments at q, shape (N, 3), for p (N, 3):
    -(alpha_k k_iso p_i + [alpha_k (k - k_iso) + alpha_c c] (u . p_i) u) on particle i."""
    i, length, live, u = _geometry(model, control, q)
    k = model.attachment_stiffness
    with np.errstate(divide="ignore", invalid="ignore"):
        side = k * np.maximum(0.0, 1.0 - model.attachment_rest_length / length)
    iso = np.where(live, side, k)
    ud = np.einsum("ak,ak->a", u, p[i])
    axial = alpha_k * (k - iso) * ud + alpha_c * model.attachment_damping * ud
    out = np.zeros_like(p, dtype=np.float64)
    np.add.at(out, i, -((alpha_k * iso)[:, None] * p[i] + axial[:, None] * u))
    return out


#: This term's force for softbody.reference.forces (by its name in the core's registry).
TERMS = {"attachments": lambda model, control, t, q, qd, gas: force(model, control, q, qd)}
