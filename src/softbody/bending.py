"""Material bending of a surface: the discrete-shell bending energy (Grinspun et al. 2003).

A body's skin resists bending by its bending stiffness D [N m], per unit width the moment
that bends it to unit curvature. For a plate of Young's modulus E, Poisson ratio nu and
thickness H, D = E H^3 / (12 (1 - nu^2)). Every interior edge ("hinge") of the mesh gets
the energy k (theta - theta0)^2 with k = D |e0|^2 / (2 A0) (``core/terms/bending.hpp``;
the guide's bending page derives the factor and says what each solver does).

This is a material law, apart from the older ``bend_stiffness`` of ``add_soft_body`` and
``add_cloth``: those are Hooke springs [N/m] across each pair of adjacent triangles, whose
resistance to bending depends on the mesh and has no material meaning.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = ["Bending", "dihedral_angles", "hinge_stiffness"]

REST_SHAPES = ("mesh", "flat")


def _finite(name: str, value, *, positive: bool = False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(x):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if positive and not x > 0.0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return x


@dataclass(frozen=True)
class Bending:
    """Bending stiffness of a surface: ``Bending(stiffness)`` with D [N m] > 0 directly, or
    :meth:`from_material`.

    ``rest_shape`` says which dihedral angles cost no energy: ``"mesh"`` (default) the
    mesh's own, as it is given to ``add_soft_body`` / ``add_cloth`` (a ball keeps its
    round shape, a flat cloth wants to be flat); ``"flat"`` zero at every edge (a sheet
    made flat and then closed or curved: a sphere of it bends, with energy).
    """

    stiffness: float
    """Bending stiffness D [N m], > 0."""
    rest_shape: Literal["mesh", "flat"] = "mesh"
    """``"mesh"``: rest angles of the given mesh; ``"flat"``: rest angles 0."""

    def __post_init__(self):
        object.__setattr__(self, "stiffness", _finite("bending stiffness", self.stiffness,
                                                      positive=True))  # fmt: skip
        if self.rest_shape not in REST_SHAPES:
            raise ValueError(
                f"bending rest_shape must be 'mesh' or 'flat', got {self.rest_shape!r}"
            )

    @classmethod
    def from_material(
        cls,
        youngs_modulus: float,
        poisson_ratio: float,
        thickness: float,
        *,
        rest_shape: Literal["mesh", "flat"] = "mesh",
    ) -> Bending:
        """D = E H^3 / (12 (1 - nu^2)) from Young's modulus E [Pa] > 0, the Poisson ratio
        nu in (-1, 0.5] and the thickness H [m] > 0."""
        e = _finite("youngs_modulus", youngs_modulus, positive=True)
        nu = _finite("poisson_ratio", poisson_ratio)
        if not -1.0 < nu <= 0.5:
            raise ValueError(f"poisson_ratio must lie in (-1, 0.5], got {poisson_ratio!r}")
        h = _finite("thickness", thickness, positive=True)
        return cls(e * h**3 / (12.0 * (1.0 - nu * nu)), rest_shape)


def dihedral_angles(q: np.ndarray, hinges: np.ndarray) -> np.ndarray:
    """Signed dihedral angle theta [rad] (H,) of each hinge (H, 4) at positions q (N, 3):
    atan2((n1 x n2) . e / |e|, n1 . n2) with e = x1 - x0, n1 = e x (x2 - x0) and
    n2 = (x3 - x0) x e; 0 for a flat hinge, positive where the surface bends away from its
    normals."""
    x0, x1, x2, x3 = (q[hinges[:, k]] for k in range(4))
    e = x1 - x0
    n1 = np.cross(e, x2 - x0)
    n2 = np.cross(x3 - x0, e)
    length = np.linalg.norm(e, axis=1)
    sine = np.einsum("ij,ij->i", np.cross(n1, n2), e)
    sine = np.divide(sine, length, out=np.zeros_like(sine), where=length > 0)
    return np.arctan2(sine, np.einsum("ij,ij->i", n1, n2))


def hinge_stiffness(q: np.ndarray, hinges: np.ndarray, stiffness: float) -> np.ndarray:
    """k = D |e0|^2 / (2 A0) [N m] (H,) of each hinge (H, 4) at rest positions q (N, 3)
    [m], D = ``stiffness`` [N m], A0 the two triangles' areas summed (nan where that is 0)."""
    x0, x1, x2, x3 = (q[hinges[:, k]] for k in range(4))
    e = x1 - x0
    area = 0.5 * (np.linalg.norm(np.cross(e, x2 - x0), axis=1)
                  + np.linalg.norm(np.cross(x3 - x0, e), axis=1))  # fmt: skip
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(area > 0, stiffness * np.einsum("ij,ij->i", e, e) / (2.0 * area), np.nan)
