"""Material bending: the discrete-shell energy on the hinges (``core/terms/bending.hpp``).

A hinge (x0, x1, x2, x3) is the edge e = x1 - x0 shared by the faces (x0, x1, x2) and
(x1, x0, x3). With their normals n1 = e x (x2 - x0), n2 = (x3 - x0) x e its dihedral
angle and energy are

    theta = atan2((n1 x n2) . e / |e|, n1 . n2)                          [rad]
    E     = k (theta - theta0)^2,   theta - theta0 taken in [-pi, pi]     [J]

with k = D |e0|^2 / (2 A0) [N m] (``Model.bending_stiffness``). The gradient of theta is

    g2 = -|e| n1 / |n1|^2,   g3 = -|e| n2 / |n2|^2,
    g1 = -(s2 g2 + s3 g3),   g0 = -(g1 + g2 + g3),   s_k = (x_k - x0) . e / |e|^2,

and the force f_a = -2 k (theta - theta0) g_a [N]. The implicit solvers' stiffness is the
Gauss-Newton K = -2 k g g^T per hinge (g the four gradients as one 12-vector): the
Hessian without 2 k (theta - theta0) d2theta/dx2, negative semi-definite. A hinge whose
edge or either face is degenerate has no angle: no force and no stiffness (theta = 0 in
the energy).
"""

from __future__ import annotations

import numpy as np

from softbody.sim.model import Model


def angles_and_gradients(model: Model, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(theta (H,) [rad], g (H, 4, 3) [1/m], live (H,) bool) of every hinge at q (N, 3):
    the dihedral angle, its gradient with respect to the four corners, and whether the
    angle is defined (g and theta are 0 where not)."""
    x = q[model.bending_hinges]  # (H, 4, 3)
    e = x[:, 1] - x[:, 0]
    n1 = np.cross(e, x[:, 2] - x[:, 0])
    n2 = np.cross(x[:, 3] - x[:, 0], e)
    e2 = np.einsum("hk,hk->h", e, e)
    a1 = np.einsum("hk,hk->h", n1, n1)
    a2 = np.einsum("hk,hk->h", n2, n2)
    live = (e2 > 0) & (a1 > 0) & (a2 > 0)
    length = np.sqrt(np.where(live, e2, 1.0))
    a1, a2, e2 = (np.where(live, v, 1.0) for v in (a1, a2, e2))
    sine = np.einsum("hk,hk->h", np.cross(n1, n2), e) / length
    theta = np.where(live, np.arctan2(sine, np.einsum("hk,hk->h", n1, n2)), 0.0)
    g2 = -(length / a1)[:, None] * n1
    g3 = -(length / a2)[:, None] * n2
    s2 = np.einsum("hk,hk->h", x[:, 2] - x[:, 0], e) / e2
    s3 = np.einsum("hk,hk->h", x[:, 3] - x[:, 0], e) / e2
    g1 = -(s2[:, None] * g2 + s3[:, None] * g3)
    g0 = -(g1 + g2 + g3)
    g = np.where(live[:, None, None], np.stack([g0, g1, g2, g3], axis=1), 0.0)
    return theta, g, live


def excess(model: Model, theta: np.ndarray) -> np.ndarray:
    """theta - theta0 (H,) [rad], taken in [-pi, pi] (both lie in [-pi, pi], so one turn
    added or taken away suffices)."""
    d = theta - model.bending_rest_angle
    return np.where(d > np.pi, d - 2.0 * np.pi, np.where(d < -np.pi, d + 2.0 * np.pi, d))


def energies(model: Model, q: np.ndarray) -> np.ndarray:
    """Bending energy k (theta - theta0)^2 of every hinge [J], shape (H,), at q (N, 3)."""
    theta, _, _ = angles_and_gradients(model, q)
    return model.bending_stiffness * excess(model, theta) ** 2


def energy(model: Model, q: np.ndarray) -> float:
    """Total bending energy [J] at q (N, 3)."""
    return float(energies(model, q).sum())


def force(model: Model, q: np.ndarray) -> np.ndarray:
    """The bending force -dE/dx on each particle [N], shape (N, 3), at q (N, 3)."""
    theta, g, _ = angles_and_gradients(model, q)
    s = -2.0 * model.bending_stiffness * excess(model, theta)
    f = np.zeros_like(q, dtype=np.float64)
    np.add.at(f, model.bending_hinges.reshape(-1), (s[:, None, None] * g).reshape(-1, 3))
    return f


def jacobian_product(model: Model, q: np.ndarray, p: np.ndarray, alpha_k: float) -> np.ndarray:
    """alpha_k K p [N] (N, 3) for p (N, 3) with the Gauss-Newton K = -2 k g g^T per hinge
    at q (N, 3)."""
    _, g, _ = angles_and_gradients(model, q)
    gp = np.einsum("hak,hak->h", g, p[model.bending_hinges])
    s = -2.0 * alpha_k * model.bending_stiffness * gp
    out = np.zeros_like(p, dtype=np.float64)
    np.add.at(out, model.bending_hinges.reshape(-1), (s[:, None, None] * g).reshape(-1, 3))
    return out


#: This term's force for softbody.reference.forces (by its name in the core's registry).
TERMS = {"bending": lambda model, control, t, q, qd, gas: force(model, q)}
