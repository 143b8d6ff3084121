"""Damped Hooke springs between particles (``core/terms/springs.hpp``).

Every row of the model's spring arrays is one spring: the mesh edges, the bending springs
across adjacent triangles and the user's springs (``ModelBuilder.add_spring``) alike. For
a spring from i to j, with d = x_j - x_i, L = |d| and u = d / L:

    f_i = [k (L - L0) + c (v_j - v_i) . u] u,   f_j = -f_i                [N]
    E   = 1/2 k (L - L0)^2                                                [J]

The elastic part of f is -dE/dx. The stiffness K = df/dx acting on p_j - p_i is

    K_s = k u u^T + k max(0, 1 - L0/L) (I - u u^T)                      [N/m]

(the compressive part of the geometric stiffness, L < L0, is dropped so that -K stays
positive semi-definite: K is exact only for springs at or beyond their rest length), and
the damping C = df/dv is C_s = c u u^T [N s/m]. K is the elastic force's: the damping
force's change with x (its direction u turning) is left out, as the implicit solvers
linearise. A zero-length spring has no direction: no force, K_s = k I.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from softbody.sim.model import Model


def _ends(model: Model) -> tuple[np.ndarray, np.ndarray]:
    idx = model.spring_indices.reshape(-1, 2)
    return idx[:, 0], idx[:, 1]


def hooke_energy(length: np.ndarray, rest_length: np.ndarray, stiffness: np.ndarray) -> np.ndarray:
    """1/2 k (L - L0)^2 [J] for lengths L, rest lengths L0 [m] and stiffnesses k [N/m],
    all of one shape."""
    return 0.5 * stiffness * (length - rest_length) ** 2


def lengths(model: Model, q: np.ndarray) -> np.ndarray:
    """Length L = |x_j - x_i| of every spring [m], shape (S,), at q (N, 3)."""
    i, j = _ends(model)
    return np.linalg.norm(q[j] - q[i], axis=1)


def energies(model: Model, q: np.ndarray) -> np.ndarray:
    """Elastic energy 1/2 k (L - L0)^2 of every spring [J], shape (S,), at q (N, 3)."""
    return hooke_energy(lengths(model, q), model.spring_rest_length, model.spring_stiffness)


def energy(model: Model, q: np.ndarray) -> float:
    """Total elastic energy of the springs [J]."""
    return float(energies(model, q).sum())


def spring_forces(model: Model, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """The force f_i on the first end of every spring [N], shape (S, 3) (f_j = -f_i), at
    q, qd (N, 3); zero for a spring of zero length."""
    i, j = _ends(model)
    d = q[j] - q[i]
    length = np.linalg.norm(d, axis=1)
    live = length > 0.0
    u = np.zeros_like(d)
    u[live] = d[live] / length[live, None]
    rel = np.einsum("sk,sk->s", qd[j] - qd[i], u)  # (v_j - v_i) . u [m/s]
    mag = model.spring_stiffness * (length - model.spring_rest_length) + model.spring_damping * rel
    return np.where(live[:, None], mag[:, None] * u, 0.0)


def force(model: Model, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Sum of every spring's damped force on each particle [N], shape (N, 3)."""
    i, j = _ends(model)
    fi = spring_forces(model, q, qd)
    f = np.zeros_like(q, dtype=np.float64)
    np.add.at(f, i, fi)
    np.add.at(f, j, -fi)
    return f


class StiffnessParts(NamedTuple):
    """What the spring Jacobian reads (``springs::prepare``): K_s = (a - b) u u^T + b I."""

    u: np.ndarray  # (S, 3) unit direction x_j - x_i (0 for a zero-length spring)
    a: np.ndarray  # (S,) axial stiffness k [N/m] (0 for a zero-length spring)
    b: np.ndarray  # (S,) transverse stiffness k max(0, 1 - L0/L) [N/m] (k at zero length)


def stiffness_parts(model: Model, q: np.ndarray) -> StiffnessParts:
    """Per spring u, a, b at q (N, 3): see :class:`StiffnessParts`."""
    i, j = _ends(model)
    d = q[j] - q[i]
    length = np.linalg.norm(d, axis=1)
    k = model.spring_stiffness
    live = length > 0.0
    u = np.zeros_like(d)
    u[live] = d[live] / length[live, None]
    a = np.where(live, k, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        side = k * np.maximum(0.0, 1.0 - model.spring_rest_length / length)
    b = np.where(live, side, k)
    return StiffnessParts(u, a, b)


def jacobian_product(
    model: Model,
    p: np.ndarray,
    alpha_c: float,
    alpha_k: float,
    parts: StiffnessParts,
) -> np.ndarray:
    """(alpha_c C + alpha_k K) p [N] of the springs, shape (N, 3), for p (N, 3): per
    spring w = alpha_k [b d + (a - b)(u . d) u] + alpha_c c (u . d) u with d = p_j - p_i,
    added to i and subtracted from j. ``parts`` from :func:`stiffness_parts` (or any
    blocks of that form, as the stability estimate passes)."""
    i, j = _ends(model)
    u, a, b = parts
    d = p[j] - p[i]
    ud = np.einsum("sk,sk->s", u, d)
    axial = alpha_k * (a - b) * ud + alpha_c * model.spring_damping * ud
    w = (alpha_k * b)[:, None] * d + axial[:, None] * u
    out = np.zeros_like(p, dtype=np.float64)
    np.add.at(out, i, w)
    np.add.at(out, j, -w)
    return out


#: This term's force for softbody.reference.forces (by its name in the core's registry).
TERMS = {"springs": lambda model, control, t, q, qd, gas: force(model, q, qd)}
