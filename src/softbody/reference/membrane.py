"""Constant-strain triangle membranes (``core/terms/membrane.hpp``; :mod:`softbody.membrane`).

For a membrane triangle (x0, x1, x2) with inverse rest edge matrix Dm^-1 (2, 2), rest
area A0 and thickness H:

    F = [x1 - x0, x2 - x0] Dm^-1  (3, 2),   C = F^T F  (2, 2)
    E = A0 H W(C)                                                              [J]
    P = 2 F dW/dC,   f_a = -A0 H P g_a                                          [N]

with g_1, g_2 the rows of Dm^-1 and g_0 = -(g_1 + g_2). dW/dC, with J = det C:

    neo-Hookean    mu / 2 (I - C^-1 / J)
    Mooney-Rivlin  c10 (I - C^-1 / J) + c01 (J C^-1 + I / J - tr C C^-1 / J)
    StVK           E / (2 (1 - nu^2)) [(1 - nu) G + nu tr G I],  G = (C - I) / 2

The damping adds the viscous stress beta (2 G_s Gdot + lam_s tr Gdot I) to 2 dW/dC, with
Gdot = (Fdot^T F + F^T Fdot) / 2 and the small-strain moduli of
:func:`softbody.membrane.small_strain_moduli`.
"""

from __future__ import annotations

import numpy as np

from softbody.membrane import MembraneMaterial, energy_density, small_strain_moduli
from softbody.sim.model import Model


def gradients(model: Model) -> np.ndarray:
    """g_a (Tm, 3, 2) [1/m] of every membrane triangle: F = sum_a x_a g_a^T."""
    inv = model.membrane_rest_inverse
    g = np.empty((model.membrane_count, 3, 2))
    g[:, 1] = inv[:, 0]
    g[:, 2] = inv[:, 1]
    g[:, 0] = -(inv[:, 0] + inv[:, 1])
    return g


def deformation(model: Model, q: np.ndarray) -> np.ndarray:
    """F (Tm, 3, 2) of every membrane triangle at q (N, 3) (or Fdot for velocities)."""
    x = q[model.membrane_indices]  # (Tm, 3 corners, 3)
    return np.einsum("tak,tab->tkb", x, gradients(model))


def _moduli(model: Model) -> tuple[np.ndarray, np.ndarray]:
    rows = [small_strain_moduli(m, p0, p1) for m, (p0, p1)
            in zip(model.membrane_material, model.membrane_params, strict=True)]  # fmt: skip
    out = np.array(rows, dtype=np.float64).reshape(-1, 2)
    return out[:, 0], out[:, 1]


def stress(model: Model, c: np.ndarray) -> np.ndarray:
    """dW/dC (Tm, 2, 2) [Pa] at right Cauchy-Green tensors c (Tm, 2, 2)."""
    p0 = model.membrane_params[:, 0, None, None]
    p1 = model.membrane_params[:, 1, None, None]
    eye = np.eye(2)
    det = (c[:, 0, 0] * c[:, 1, 1] - c[:, 0, 1] * c[:, 1, 0])[:, None, None]
    tr = (c[:, 0, 0] + c[:, 1, 1])[:, None, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        c_inv = np.linalg.inv(np.where(det > 0, c, eye))
        neo = 0.5 * p0 * (eye - c_inv / det)
        mr = p0 * (eye - c_inv / det) + p1 * (det * c_inv + eye / det - tr / det * c_inv)
    g = 0.5 * (c - eye)
    tr_g = (g[:, 0, 0] + g[:, 1, 1])[:, None, None]
    stvk = p0 / (2.0 * (1.0 - p1 * p1)) * ((1.0 - p1) * g + p1 * tr_g * eye)
    material = model.membrane_material[:, None, None]
    return np.where(material == MembraneMaterial.NEO_HOOKEAN, neo,
                    np.where(material == MembraneMaterial.MOONEY_RIVLIN, mr, stvk))  # fmt: skip


def energies(model: Model, q: np.ndarray) -> np.ndarray:
    """A0 H W(C) [J] of every membrane triangle, shape (Tm,), at q (N, 3)."""
    f = deformation(model, q)
    c = np.einsum("tkb,tkc->tbc", f, f)
    w = energy_density(model.membrane_material, model.membrane_params[:, 0],
                       model.membrane_params[:, 1], c)  # fmt: skip
    return model.membrane_rest_area * model.membrane_thickness * w


def energy(model: Model, q: np.ndarray) -> float:
    """Total elastic energy of the membranes [J]."""
    return float(energies(model, q).sum())


def force(model: Model, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Every membrane triangle's elastic and viscous force summed per particle [N],
    shape (N, 3), at q, qd (N, 3)."""
    f = deformation(model, q)
    c = np.einsum("tkb,tkc->tbc", f, f)
    second = 2.0 * stress(model, c)  # S = 2 dW/dC
    shear, lame = _moduli(model)
    fdot = deformation(model, qd)
    gdot = 0.5 * (np.einsum("tkb,tkc->tbc", fdot, f) + np.einsum("tkb,tkc->tbc", f, fdot))
    tr = gdot[:, 0, 0] + gdot[:, 1, 1]
    viscous = (2.0 * shear)[:, None, None] * gdot + (lame * tr)[:, None, None] * np.eye(2)
    second = second + model.membrane_damping[:, None, None] * viscous
    piola = np.einsum("tkb,tbc->tkc", f, second)  # (Tm, 3, 2)
    scale = -(model.membrane_rest_area * model.membrane_thickness)
    corner = scale[:, None, None] * np.einsum("tkc,tac->tak", piola, gradients(model))
    out = np.zeros_like(q, dtype=np.float64)
    np.add.at(out, model.membrane_indices.reshape(-1), corner.reshape(-1, 3))
    return out


#: This term's force for softbody.reference.forces (by its name in the core's registry).
TERMS = {"membrane": lambda model, control, t, q, qd, gas: force(model, q, qd)}


# -- the implicit solvers' product -------------------------------------------------------
def _piola(model: Model, f: np.ndarray) -> np.ndarray:
    """The elastic first Piola stress P = 2 F dW/dC (Tm, 3, 2) [Pa] at F (Tm, 3, 2)."""
    c = np.einsum("tkb,tkc->tbc", f, f)
    return 2.0 * np.einsum("tkb,tbc->tkc", f, stress(model, c))


def f_hessians(model: Model, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per membrane triangle at q (N, 3): the elastic Hessian A0 H d2W/dF2 (Tm, 6, 6) in
    vec(F) = [column 0; column 1], by central differences of the Piola stress (step 1e-6
    of |F|: error about 1e-10 of the stress's scale), symmetrised; and the damping block
    A0 H beta L^T C0 L (Tm, 6, 6), L: Fdot -> sym(F^T Fdot), exactly."""
    f = deformation(model, q)
    scale = (model.membrane_rest_area * model.membrane_thickness)[:, None, None]
    step = 1e-6 * np.abs(f).max(axis=(1, 2))[:, None, None]
    shear, lame = _moduli(model)
    count = model.membrane_count
    hf, hd = np.zeros((count, 6, 6)), np.zeros((count, 6, 6))
    for col in range(6):
        unit = np.zeros((3, 2))
        unit[col % 3, col // 3] = 1.0
        dp = (_piola(model, f + step * unit) - _piola(model, f - step * unit)) / (2.0 * step)
        hf[:, :, col] = (scale * dp).transpose(0, 2, 1).reshape(count, 6)
        gdot = 0.5 * (np.einsum("kb,tkc->tbc", unit, f) + np.einsum("tkb,kc->tbc", f, unit))
        tr = gdot[:, 0, 0] + gdot[:, 1, 1]
        s = (2.0 * shear)[:, None, None] * gdot + (lame * tr)[:, None, None] * np.eye(2)
        dv = model.membrane_damping[:, None, None] * np.einsum("tkb,tbc->tkc", f, s)
        hd[:, :, col] = (scale * dv).transpose(0, 2, 1).reshape(count, 6)
    return 0.5 * (hf + hf.transpose(0, 2, 1)), 0.5 * (hd + hd.transpose(0, 2, 1))


def clamped(h: np.ndarray) -> np.ndarray:
    """Symmetric matrices h (..., 6, 6) with their negative eigenvalues set to 0."""
    w, v = np.linalg.eigh(h)
    return np.einsum("...ik,...k,...jk->...ij", v, np.maximum(w, 0.0), v)


def jacobian_product(
    model: Model, q: np.ndarray, p: np.ndarray, alpha_c: float, alpha_k: float
) -> np.ndarray:
    """(alpha_c C + alpha_k K) p [N] of the membranes, shape (N, 3), at q for p (N, 3):
    per triangle -G^T (alpha_k H_F+ + alpha_c D_F) G p, H_F+ the elastic F-Hessian with its
    negative eigenvalues clamped (so -K is positive semi-definite), G: corners -> vec(F)."""
    if not model.membrane_count:
        return np.zeros_like(p, dtype=np.float64)
    hf, hd = f_hessians(model, q)
    block = alpha_k * clamped(hf) + alpha_c * hd
    dfp = deformation(model, p)  # G p as (Tm, 3, 2)
    x = dfp.transpose(0, 2, 1).reshape(-1, 6)
    y = np.einsum("tij,tj->ti", block, x).reshape(-1, 2, 3).transpose(0, 2, 1)  # (Tm, 3, 2)
    corner = -np.einsum("tkc,tac->tak", y, gradients(model))
    out = np.zeros_like(p, dtype=np.float64)
    np.add.at(out, model.membrane_indices.reshape(-1), corner.reshape(-1, 3))
    return out
