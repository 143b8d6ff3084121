"""Membrane materials: a body's skin as a thin hyperelastic sheet instead of edge springs.

Each triangle of a body given a :class:`Membrane` is a constant-strain element
(``core/terms/membrane.hpp``). Its energy is A0 H W(C): rest area A0 [m^2] times thickness
H [m] times an energy density W [Pa = J/m^3] of the in-plane right Cauchy-Green tensor
C = F^T F (2 x 2), with I1 = tr C + 1 / det C and I2 = det C + tr C / det C:

=================== ===================================================== =================
model               W per unit rest volume                                parameters
=================== ===================================================== =================
neo_hookean         mu / 2 (I1 - 3)  (incompressible)                     mu [Pa]
mooney_rivlin       c10 (I1 - 3) + c01 (I2 - 3)  (incompressible)         c10, c01 [Pa]
stvk                E / (2 (1 - nu^2)) [(1 - nu) tr(G^2) + nu (tr G)^2]   E [Pa], nu
=================== ===================================================== =================

G = (C - I) / 2 is the Green strain (StVK in plane stress: the issue's energy per unit
area is this W times H). Small strains see the plane-stress shear modulus G_s and Lame
constant lam_s: neo-Hookean G_s = mu, lam_s = 2 mu (Young's modulus 3 mu, nu = 1/2);
Mooney-Rivlin the same with mu = 2 (c10 + c01); StVK G_s = E / (2 (1 + nu)),
lam_s = E nu / (1 - nu^2).

``damping`` beta [s] adds a viscous stress beta (2 G_s Gdot + lam_s tr(Gdot) I) on the
Green strain rate Gdot: Rayleigh stiffness-proportional damping that leaves rigid motion
alone and always dissipates.

A uniformly scaled closed membrane (every triangle stretched equibiaxially by s) is in
equilibrium at P(s) = A0 H W'(s) / (3 V0 s^2); for a neo-Hookean sphere of radius R,
P = 2 mu (H / R) (1 / s - 1 / s^7), the balloon curve, peaking at s = 7^(1/6)
(:func:`equibiaxial_pressure`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np


class MembraneMaterial(IntEnum):
    """The energy density of a membrane (``core/enums.hpp``)."""

    NEO_HOOKEAN = 0
    MOONEY_RIVLIN = 1
    STVK = 2


def _param(name: str, value, *, positive: bool = False) -> float:
    """A finite number >= 0 (> 0 with ``positive``), else a ValueError naming it."""
    if isinstance(value, bool):
        raise ValueError(f"{name} must be a number, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(x):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if x < 0 or (positive and x == 0):
        raise ValueError(f"{name} must be {'> 0' if positive else '>= 0'}, got {value!r}")
    return x


@dataclass(frozen=True)
class Membrane:
    """A membrane material and its thickness. Build one with a class method.

    Attributes
    ----------
    material : MembraneMaterial
    params : (float, float)
        (mu, 0) [Pa] neo-Hookean, (c10, c01) [Pa] Mooney-Rivlin, (E [Pa], nu) StVK.
    thickness : float
        Rest thickness H [m], > 0.
    damping : float
        Strain-rate damping time beta [s], >= 0 (module docstring).
    """

    material: MembraneMaterial
    params: tuple[float, float]
    thickness: float
    damping: float = 0.0

    @classmethod
    def neo_hookean(cls, shear_modulus: float, thickness: float, *, damping: float = 0.0):
        """Incompressible neo-Hookean sheet (rubber, latex, silicone): shear modulus
        mu [Pa] >= 0, thickness H [m] > 0, damping beta [s] >= 0."""
        mu = _param("shear_modulus", shear_modulus)
        return cls(MembraneMaterial.NEO_HOOKEAN, (mu, 0.0), _param("thickness", thickness,
                   positive=True), _param("damping", damping))  # fmt: skip

    @classmethod
    def mooney_rivlin(cls, c10: float, c01: float, thickness: float, *, damping: float = 0.0):
        """Incompressible Mooney-Rivlin sheet: c10, c01 [Pa] >= 0 (small-strain shear
        modulus 2 (c10 + c01)), thickness H [m] > 0, damping beta [s] >= 0."""
        return cls(
            MembraneMaterial.MOONEY_RIVLIN,
            (_param("c10", c10), _param("c01", c01)),
            _param("thickness", thickness, positive=True),
            _param("damping", damping),
        )

    @classmethod
    def stvk(
        cls, youngs_modulus: float, poisson_ratio: float, thickness: float, *,
        damping: float = 0.0,
    ):  # fmt: skip
        """St Venant-Kirchhoff sheet in plane stress (fabric, film): Young's modulus
        E [Pa] >= 0, Poisson ratio nu in (-1, 0.5), thickness H [m] > 0, damping
        beta [s] >= 0."""
        e = _param("youngs_modulus", youngs_modulus)
        try:
            nu = float(poisson_ratio)
        except (TypeError, ValueError):
            raise ValueError(f"poisson_ratio must be a number, got {poisson_ratio!r}") from None
        if isinstance(poisson_ratio, bool) or not -1.0 < nu < 0.5:
            raise ValueError(f"poisson_ratio must lie in (-1, 0.5), got {poisson_ratio!r}")
        return cls(
            MembraneMaterial.STVK,
            (e, nu),
            _param("thickness", thickness, positive=True),
            _param("damping", damping),
        )

    @property
    def model(self) -> str:
        """The material's name as the scene files write it: ``"neo_hookean"``,
        ``"mooney_rivlin"`` or ``"stvk"``."""
        return self.material.name.lower()

    def small_strain_moduli(self) -> tuple[float, float]:
        """(G_s, lam_s) [Pa]: the plane-stress shear modulus and Lame constant at small
        strain (module docstring)."""
        return small_strain_moduli(self.material, *self.params)

    def energy_density(self, c: np.ndarray) -> np.ndarray:
        """W(C) [Pa] for right Cauchy-Green tensors c (..., 2, 2)."""
        return energy_density(self.material, *self.params, c)


def small_strain_moduli(material: MembraneMaterial, p0: float, p1: float) -> tuple[float, float]:
    """(G_s, lam_s) [Pa] of a material with parameters (p0, p1) (:class:`Membrane`)."""
    material = MembraneMaterial(material)
    if material == MembraneMaterial.NEO_HOOKEAN:
        return p0, 2.0 * p0
    if material == MembraneMaterial.MOONEY_RIVLIN:
        mu = 2.0 * (p0 + p1)
        return mu, 2.0 * mu
    return p0 / (2.0 * (1.0 + p1)), p0 * p1 / (1.0 - p1 * p1)


PROJECTIVE_MARGIN = 3.0
"""How many times the small-strain stiffness bound 2 (G_s + lam_s) projective dynamics'
matrix holds per membrane triangle (``core/terms/membrane.hpp``: kProjectiveMargin, which
must equal it): its splitting contracts while the sheet's tangent stays below that weight,
and stretched sheets stiffen. With 1 a StVK balloon at stretch 1.8 and a neo-Hookean one at
2.5 diverged; with 3 both settle."""


def scalar_blocks(
    model, *, mean: bool = False, projective: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The membranes as weighted graph Laplacians, for the solvers' matrices: per membrane
    triangle and pair of corners (a, b) the entry W_t g_a . g_b, W_t = A0 H 2 (G_s + lam_s)
    [N/m] (the largest eigenvalue of the small-strain stiffness in F, so W_t G_t^T G_t
    bounds the triangle's stiffness at rest from above), times ``PROJECTIVE_MARGIN`` for
    projective dynamics (``projective``), or with
    ``mean`` A0 H (3 G_s + lam_s) / 2, the mean of its eigenvalues over the four in-plane
    deformations (2 (G_s + lam_s), 2 G_s twice, 0 for rotation: the multigrid hierarchy,
    where a typical stiffness coarsens better than the largest); and its damping beta W_t
    [N s/m]. Returns (rows, cols (9 Tm,) int64, stiffness, damping (9 Tm,)); every
    triangle's 3 x 3 block is positive semi-definite with zero row sums (sum g_a = 0)."""
    pairs = zip(model.membrane_material, model.membrane_params, strict=True)
    moduli = np.array([small_strain_moduli(m, p0, p1) for m, (p0, p1) in pairs]).reshape(-1, 2)
    shear, lame = moduli.T
    modulus = 0.5 * (3.0 * shear + lame) if mean else 2.0 * (shear + lame)
    if projective:
        modulus = PROJECTIVE_MARGIN * modulus
    weight = model.membrane_rest_area * model.membrane_thickness * modulus
    inv = model.membrane_rest_inverse  # rows g_1, g_2; g_0 = -(g_1 + g_2)
    g = np.stack([-(inv[:, 0] + inv[:, 1]), inv[:, 0], inv[:, 1]], axis=1)  # (Tm, 3, 2)
    block = weight[:, None, None] * np.einsum("tac,tbc->tab", g, g)  # (Tm, 3, 3)
    tri = model.membrane_indices
    rows = np.repeat(tri, 3, axis=1).ravel()
    cols = np.tile(tri, (1, 3)).ravel()
    damping = (model.membrane_damping[:, None, None] * block).ravel()
    return rows, cols, block.ravel(), damping


def energy_density(material, p0, p1, c: np.ndarray) -> np.ndarray:
    """W(C) [Pa] for C (..., 2, 2) and parameters p0, p1 (scalars or arrays that
    broadcast against C's leading shape); material one value or an array alike."""
    c = np.asarray(c, dtype=np.float64)
    tr = c[..., 0, 0] + c[..., 1, 1]
    det = c[..., 0, 0] * c[..., 1, 1] - c[..., 0, 1] * c[..., 1, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        i1 = tr + 1.0 / det
        i2 = det + tr / det
        neo = 0.5 * p0 * (i1 - 3.0)
        mr = p0 * (i1 - 3.0) + p1 * (i2 - 3.0)
        g = 0.5 * (c - np.eye(2))
        tr_g = g[..., 0, 0] + g[..., 1, 1]
        tr_g2 = np.einsum("...ij,...ji->...", g, g)
        stvk = p0 / (2.0 * (1.0 - p1 * p1)) * ((1.0 - p1) * tr_g2 + p1 * tr_g**2)
    material = np.asarray(material)
    out = np.where(material == MembraneMaterial.NEO_HOOKEAN, neo,
                   np.where(material == MembraneMaterial.MOONEY_RIVLIN, mr, stvk))  # fmt: skip
    collapsed = (det <= 0) & (material != MembraneMaterial.STVK)
    return np.where(collapsed, np.inf, out)


def equibiaxial_pressure(membrane: Membrane, s, area: float, volume: float) -> np.ndarray:
    """Equilibrium pressure P(s) [Pa] of a closed membrane of rest area A0 ``area``
    [m^2] and rest volume V0 ``volume`` [m^3] scaled uniformly by stretches ``s``:
    P = A0 H W'(s) / (3 V0 s^2), W(s) the energy density at C = s^2 I. For a sphere of
    radius R (A0 / (3 V0) = 1 / R) and a neo-Hookean membrane this is
    2 mu (H / R) (1 / s - 1 / s^7)."""
    s = np.asarray(s, dtype=np.float64)
    p0, p1 = membrane.params
    m = membrane.material
    if m == MembraneMaterial.NEO_HOOKEAN:
        dw = 2.0 * p0 * (s - s**-5)
    elif m == MembraneMaterial.MOONEY_RIVLIN:
        # W = c10 (2 s^2 + s^-4 - 3) + c01 (s^4 + 2 s^-2 - 3)
        dw = p0 * (4.0 * s - 4.0 * s**-5) + p1 * (4.0 * s**3 - 4.0 * s**-3)
    else:
        # G = g I, g = (s^2 - 1) / 2: W = E / (2 (1 - nu^2)) (2 + 2 nu) g^2 = E g^2 / (1 - nu)
        g = 0.5 * (s**2 - 1.0)
        dw = 2.0 * p0 / (1.0 - p1) * g * s
    return area * membrane.thickness * dw / (3.0 * volume * s**2)
