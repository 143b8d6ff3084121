"""The implicit solvers' matrix-free product (``core/kernels.cpp: apply_jacobians``):

    out = alpha_m M p + alpha_c C p + alpha_k K p,    C = df/dv, K = df/dx,

with M the (diagonal) particle masses and C, K summed over the springs, the attachments
(optional), the grab spring, the gas, the bending hinges (their Gauss-Newton K,
:mod:`softbody.reference.bending`) and the membranes (their K clamped to negative
semi-definite: :mod:`softbody.reference.membrane`). K drops the
compressive geometric stiffness of springs and attachments (see
:mod:`softbody.reference.springs`), so it is df/dx exactly where every spring is at or
beyond its rest length. Gravity, external forces and terms without a Jacobian add
nothing (they are stepped explicitly).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from softbody.reference import attachments, bending, external, gas, membrane, springs
from softbody.reference.forces import gas_state
from softbody.sim.control import ControlData
from softbody.sim.model import Model


class JacobianInputs(NamedTuple):
    """What the product reads besides q and p: the springs' blocks, dV/dx and the pressure
    slopes (:meth:`core_arguments`: as ``softbody._core.apply_jacobians`` takes them)."""

    spring_u: np.ndarray  # (S, 3)
    spring_a: np.ndarray  # (S,) [N/m]
    spring_b: np.ndarray  # (S,) [N/m]
    volume_gradient: np.ndarray  # (N, 3) [m^2]
    body_dpdv: np.ndarray  # (B,) [Pa/m^3]
    body_pnet: np.ndarray  # (B,) [Pa]

    def core_arguments(self) -> dict:
        """``softbody._core.apply_jacobians``' keyword arguments that make the core's product
        read these: the springs' and the gas's linearisations in their layouts
        (``core/terms/springs.hpp``: u (S, 3), a, b; ``gas.hpp``: P'(V), P - P_a; flat)
        and dV/dx (N, 3)."""
        springs = np.concatenate([self.spring_u.ravel(), self.spring_a, self.spring_b])
        gas = np.concatenate([self.body_dpdv, self.body_pnet])
        return {
            "linearization": {"springs": springs, "gas": gas},
            "volume_gradient": self.volume_gradient,
        }


def prepare(model: Model, control: ControlData, t: float, q: np.ndarray) -> JacobianInputs:
    """The spring blocks, dV/dx and pressure slopes at time t [s] and q (N, 3), as the
    implicit solvers prepare them at a step's start."""
    volume, pressure, grad = gas_state(model, control, t, q)
    u, a, b = springs.stiffness_parts(model, q)
    dpdv, pnet = gas.pressure_slopes(model, volume, pressure)
    return JacobianInputs(u, a, b, grad, dpdv, pnet)


def apply_jacobians(
    model: Model,
    control: ControlData,
    q: np.ndarray,
    p: np.ndarray,
    alpha_m: float,
    alpha_c: float,
    alpha_k: float,
    inputs: JacobianInputs,
    *,
    with_attachments: bool = True,
    with_bending: bool = True,
) -> np.ndarray:
    """(alpha_m M + alpha_c C + alpha_k K) p [N] for p (N, 3) at q (N, 3), shape (N, 3)."""
    out = alpha_m * model.particle_mass[:, None] * p
    out = out + springs.jacobian_product(
        model, p, alpha_c, alpha_k, springs.StiffnessParts(*inputs[:3])
    )
    if with_attachments:
        out += attachments.jacobian_product(model, control, q, p, alpha_c, alpha_k)
    out += external.grab_jacobian_product(control, p, alpha_c, alpha_k)
    out += gas.jacobian_product(
        model, q, inputs.volume_gradient, gas.PressureSlopes(*inputs[4:]), alpha_k, p
    )
    if with_bending:
        out += bending.jacobian_product(model, q, p, alpha_k)
    out += membrane.jacobian_product(model, q, p, alpha_c, alpha_k)
    return out


def dense(
    model: Model,
    control: ControlData,
    q: np.ndarray,
    alpha_m: float,
    alpha_c: float,
    alpha_k: float,
    inputs: JacobianInputs,
) -> np.ndarray:
    """The matrix alpha_m M + alpha_c C + alpha_k K itself, shape (3N, 3N), column by
    column from :func:`apply_jacobians` (rows and columns x_0, y_0, z_0, x_1, ...): for
    small meshes only."""
    n3 = 3 * model.particle_count
    columns = []
    for k in range(n3):
        e = np.zeros(n3)
        e[k] = 1.0
        p = e.reshape(-1, 3)
        columns.append(apply_jacobians(model, control, q, p, alpha_m, alpha_c, alpha_k, inputs))
    return np.stack([c.ravel() for c in columns], axis=1)
