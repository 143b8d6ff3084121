"""Reference time steps of the implicit solvers, dense and plain, for small meshes.

Backward Euler (``core/solvers/implicit.hpp``), one Newton step of M v' = f(x, v)
linearised at the step's start x0, v0 (time t, step h):

    (M - h C - h^2 K) dv = h (f0 + K y),   y = h v0,
    v1 = v0 + dv,   x1 = x0 + h v1,

with f0 = f(x0, v0, t) every force (those without a Jacobian included, explicitly),
C = df/dv and K = df/dx the products of :mod:`softbody.reference.jacobians`. Pinned
particles (inverse mass 0) are no unknowns: dv = 0 there. The core solves by
preconditioned conjugate gradients; here the matrix is built column by column and solved
directly.

Projective dynamics (``core/solvers/projective.hpp``; Liu et al. 2013), backward Euler by
local-global iterations: from x = y = x0 + h v0, each iteration takes v = (x - x0) / h,
the forces it keeps explicit at (x, v, t + h) (every registered term without a
projection: ``softbody.core.terms()``) and each spring's projections
(:func:`spring_projection`) at x, and solves

    (M / h^2 + sum_s (k_s + c_s / h) A_s^T A_s) x = M y / h^2 + f + sum_s A_s^T t_s

with A_s x = x_j - x_i and t_s = k_s p_s + c_s / h q_s (attachments alike, A_a x = x_i -
anchor). Pinned particles' rows are the identity (x = y), and a spring's pull on a pinned
end moves to the free end's side. At the end v1 = (x1 - x0) / h; pinned particles keep
their velocity.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from softbody.core import terms as registered_terms
from softbody.reference import forces, jacobians
from softbody.sim.control import ControlData
from softbody.sim.model import Model


class BackwardEulerStep(NamedTuple):
    """One backward Euler step and its linear system on the free unknowns."""

    q: np.ndarray  # (N, 3) x1 [m]
    qd: np.ndarray  # (N, 3) v1 [m/s]
    matrix: np.ndarray  # (3F, 3F) M - h C - h^2 K on the F free particles [kg]
    rhs: np.ndarray  # (3F,) h (f0 + K y) [N s]


def backward_euler_step(
    model: Model, control: ControlData, t: float, h: float, q0: np.ndarray, v0: np.ndarray
) -> BackwardEulerStep:
    """One backward Euler step of h [s] from q0, v0 (N, 3) at time t [s] (module
    docstring), solved exactly by ``numpy.linalg.solve``."""
    f0 = forces.eval_forces(model, control, t, q0, v0).force
    inputs = jacobians.prepare(model, control, t, q0)
    ky = jacobians.apply_jacobians(model, control, q0, h * v0, 0.0, 0.0, 1.0, inputs)
    free = np.repeat(model.particle_inv_mass > 0.0, 3)  # rows x_i, y_i, z_i of free particles
    a = jacobians.dense(model, control, q0, 1.0, -h, -h * h, inputs)[np.ix_(free, free)]
    b = (h * (f0 + ky)).ravel()[free]
    dv = np.zeros(3 * model.particle_count)
    dv[free] = np.linalg.solve(a, b)
    v1 = v0 + dv.reshape(-1, 3)
    return BackwardEulerStep(q0 + h * v1, v1, a, b)


def spring_projection(d: np.ndarray, e: np.ndarray, rest: np.ndarray, k: np.ndarray,
                      c_h: np.ndarray) -> np.ndarray:  # fmt: skip
    """The local step t = k p + c_h q [N] of springs (rows): d (S, 3) their vectors now
    [m], e (S, 3) at the step's start, rest (S,) [m], k (S,) [N/m], c_h = c / h (S,)
    [N/m]. p = L0 d / |d| is d projected onto the sphere |d| = L0 (the minimiser of
    k / 2 (|d| - L0)^2 = min_p k / 2 |d - p|^2); q = (d . e / |d|^2) d onto the plane
    u . (d - e) = 0 (the damper's backward Euler term). A zero-length d: both are d."""
    length2 = np.einsum("sk,sk->s", d, d)
    live = length2 > 0.0
    safe = np.where(live, length2, 1.0)
    s = k * rest / np.sqrt(safe) + c_h * np.einsum("sk,sk->s", d, e) / safe
    return np.where(live, s, k + c_h)[:, None] * d


def projective_matrix(model: Model, h: float) -> np.ndarray:
    """The global step's matrix (N, N) [kg/s^2], the same for x, y and z (module
    docstring): M / h^2 + sum_s (k + c / h) A_s^T A_s + each attachment's (k + c / h) on
    its particle's diagonal, pinned particles' rows and columns the identity."""
    n = model.particle_count
    free = model.particle_inv_mass > 0.0
    a = np.diag(np.where(free, model.particle_mass / h**2, 1.0))
    w = model.spring_stiffness + model.spring_damping / h
    for (i, j), ws in zip(model.spring_indices, w, strict=True):
        for r, o in ((i, j), (j, i)):
            if free[r]:
                a[r, r] += ws
                if free[o]:
                    a[r, o] -= ws
    wa = model.attachment_stiffness + model.attachment_damping / h
    for i, ws in zip(model.attachment_particle, wa, strict=True):
        if free[i]:
            a[i, i] += ws
    assert a.shape == (n, n)
    return a


def projective_rhs(model: Model, control: ControlData, t: float, h: float, x: np.ndarray,
                   x0: np.ndarray, y: np.ndarray) -> np.ndarray:  # fmt: skip
    """The global step's right-hand side (N, 3) [N] at the iterate x (module docstring):
    M y / h^2 + f(x, (x - x0) / h, t) on free rows (f the explicit forces), y on pinned
    rows, plus the springs' and attachments' projection terms."""
    free = model.particle_inv_mass > 0.0
    v = (x - x0) / h
    term = forces.terms(model, control, t, x, v)
    explicit = [t["name"] for t in registered_terms() if not t["projected"]]
    f = sum(term[name] for name in explicit)
    rhs = np.where(free[:, None], model.particle_mass[:, None] / h**2 * y + f, y)
    i, j = model.spring_indices.T
    k, c_h = model.spring_stiffness, model.spring_damping / h
    ts = spring_projection(x[j] - x[i], x0[j] - x0[i], model.spring_rest_length, k, c_h)
    pull = (k + c_h)[:, None]
    np.add.at(rhs, i[free[i]], -ts[free[i]])
    np.add.at(rhs, i[free[i] & ~free[j]], (pull * x[j])[free[i] & ~free[j]])
    np.add.at(rhs, j[free[j]], ts[free[j]])
    np.add.at(rhs, j[free[j] & ~free[i]], (pull * x[i])[free[j] & ~free[i]])
    a = model.attachment_particle
    anchor = np.asarray(control.attachment_anchor, dtype=np.float64).reshape(-1, 3)
    ka, ca_h = model.attachment_stiffness, model.attachment_damping / h
    ta = spring_projection(x[a] - anchor, x0[a] - anchor, model.attachment_rest_length, ka, ca_h)
    np.add.at(rhs, a[free[a]], ((ka + ca_h)[:, None] * anchor + ta)[free[a]])
    return rhs


def projective_step(
    model: Model,
    control: ControlData,
    t: float,
    h: float,
    q0: np.ndarray,
    v0: np.ndarray,
    iterations: int,
) -> tuple[np.ndarray, np.ndarray]:
    """One projective-dynamics step of h [s] from q0, v0 (N, 3) at time t [s] with
    ``iterations`` local-global iterations: (x1, v1) (module docstring)."""
    a = projective_matrix(model, h)
    y = q0 + h * v0
    x = y.copy()
    for _ in range(iterations):
        x = np.linalg.solve(a, projective_rhs(model, control, t + h, h, x, q0, y))
    free = (model.particle_inv_mass > 0.0)[:, None]
    return np.where(free, x, y), np.where(free, (x - q0) / h, v0)
