"""Largest stable time step, from spring stiffness, masses and pressure stiffness.

The stiffest vibration mode bounds explicit time steps. Its squared angular frequency is
the largest eigenvalue of M^-1/2 K M^-1/2; K, the stiffness matrix, has three parts, each
bounded separately and added (Weyl's inequality):

* springs: block k d d^T + k (1 - L0/L)(I - d d^T) per spring, norm <= k max(1, |1 - L0/L|);
  Gershgorin on the spring-by-spring matrix gives max over springs (i, j) of
  sqrt(k) (R_i / m_i + R_j / m_j), R_i the sum of sqrt(k) over springs at i (exact for
  one spring, the Anderson-Morley bound for equal springs);
* the local pressure term (P - P_a) d2V/dx2: for a face (i, j, l) the block coupling i to
  j is (P - P_a)/6 [x_l - x_i]_x, of norm |P - P_a| |x_l - x_i| / 6 (Gershgorin by rows);
* the rank-one term -P'(V) g g^T with g = dV/dx (the breathing mode), whose one nonzero
  eigenvalue |P'(V)| sum_i |g_i|^2 / m_i adds to the bound.

Spring damping proportional to stiffness gives the stiffest mode a damping ratio
zeta = (c/k) omega_spring^2 / (2 omega). The stable step is then the largest h for which
the scheme's amplification matrix on the damped oscillator x'' = -omega^2 x - 2 zeta omega x'
has spectral radius <= 1. Explicit Euler and Midpoint amplify undamped oscillation at any
h (their estimate is ~0 without damping); RK4 is stable to omega h ~ 2.8, symplectic Euler
and velocity Verlet to omega h = 2.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import factorial

import numpy as np

from softbody.gas import GasLaw
from softbody.integrators import Integrator


@dataclass(frozen=True)
class StiffestMode:
    """Bounds on the stiffest vibration of a model."""

    omega: float
    """Upper bound on the highest angular frequency [rad/s]."""
    zeta: float
    """Damping ratio of that mode (0 = undamped)."""
    omega_spring: float
    """Part of the bound from springs alone [rad/s]."""
    omega_pressure: float
    """Part of the bound from the pressure terms alone [rad/s]."""


def stiffest_mode(model, q: np.ndarray | None = None) -> StiffestMode:
    """Bound the highest vibration frequency of ``model`` at positions ``q`` (N, 3) [m].

    The gas is taken at its largest scheduled value, so the bound holds for the whole run.
    """
    q = model.particle_q if q is None else np.asarray(q, dtype=np.float64)
    inv = model.particle_inv_mass
    n = model.particle_count
    # springs: Gershgorin on the edge matrix sqrt(k_s k_t) b_s^T M^-1 b_t (same nonzero
    # spectrum as M^-1/2 K M^-1/2): row s = sqrt(k_s) (R_i / m_i + R_j / m_j) with
    # R_i = sum of sqrt(k) over the springs at i; exact for a single spring
    idx = model.spring_indices
    root_sum = np.zeros(n)
    k_eff = np.zeros(0)
    if len(idx):
        i, j = idx[:, 0], idx[:, 1]
        length = np.linalg.norm(q[j] - q[i], axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            geometric = np.abs(1.0 - model.spring_rest_length / length)
        k_eff = model.spring_stiffness * np.maximum(1.0, np.nan_to_num(geometric))
        np.add.at(root_sum, i, np.sqrt(k_eff))
        np.add.at(root_sum, j, np.sqrt(k_eff))
    a = model.attachment_particle
    if len(a):
        np.add.at(root_sum, a, np.sqrt(model.attachment_stiffness))
    w2_spring = 0.0
    if len(idx):
        rows = np.sqrt(k_eff) * (root_sum[i] * inv[i] + root_sum[j] * inv[j])
        w2_spring = float(rows.max())
    if len(a):
        rows = np.sqrt(model.attachment_stiffness) * root_sum[a] * inv[a]
        w2_spring = max(w2_spring, float(rows.max()))

    pressure_rows = np.zeros(n)
    rank_one = 0.0
    for b in range(model.body_count):
        t0, t1 = model.body_tri_range[b]
        tri = model.tri_indices[t0:t1]
        x = q[tri]  # (F, 3, 3)
        n_scaled = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
        volume = np.einsum("ij,ij->", x[:, 0] - x[:, 0].mean(axis=0), n_scaled) / 6.0
        s0, s1 = model.body_schedule_range[b]
        value = max(model.body_gas_value[b], *model.schedule_value[s0:s1], 0.0)
        law = GasLaw(int(model.body_gas_law[b]))
        if law == GasLaw.FIXED_PRESSURE:
            pressure, dp_dv = value, 0.0
        elif law == GasLaw.ISOTHERMAL:
            pressure, dp_dv = value / volume, -value / volume**2
        else:
            g = model.body_gas_gamma[b]
            pressure = value * model.body_gas_reference_volume[b] ** (g - 1.0) / volume**g
            dp_dv = -g * pressure / volume
        p_net = abs(pressure - model.body_ambient_pressure[b])
        for c in range(3):
            ci, cj, cl = tri[:, c], tri[:, (c + 1) % 3], tri[:, (c + 2) % 3]
            lij = np.linalg.norm(x[:, (c + 1) % 3] - x[:, c], axis=1)
            lil = np.linalg.norm(x[:, (c + 2) % 3] - x[:, c], axis=1)
            row = (
                p_net / 6.0 * (lil * np.sqrt(inv[ci] * inv[cj]) + lij * np.sqrt(inv[ci] * inv[cl]))
            )
            np.add.at(pressure_rows, ci, row)
        grad = np.zeros((n, 3))
        for c in range(3):
            np.add.at(grad, tri[:, c], n_scaled / 6.0)
        rank_one = max(rank_one, abs(dp_dv) * float(np.sum(inv * np.sum(grad**2, axis=1))))

    # Weyl: the largest eigenvalue of a sum is at most the sum of the largest eigenvalues
    w2_pressure = float(pressure_rows.max(initial=0.0)) + rank_one
    w2 = w2_spring + w2_pressure
    omega = np.sqrt(w2)
    zeta = 0.0
    if len(idx) and omega > 0:
        stiff = model.spring_stiffness > 0
        if np.any(stiff):
            ratio = float(np.min(model.spring_damping[stiff] / model.spring_stiffness[stiff]))
            zeta = ratio * w2_spring / (2.0 * omega)
    return StiffestMode(
        float(omega), float(zeta), float(np.sqrt(w2_spring)), float(np.sqrt(w2_pressure))
    )


def amplification_matrix(integrator: Integrator, h: float, omega: float, zeta: float) -> np.ndarray:
    """One step of ``integrator`` on x'' = -omega^2 x - 2 zeta omega x' as a (2, 2) matrix
    ((4, 4) on the last two states for the two-step BDF2)."""
    a = np.array([[0.0, 1.0], [-(omega**2), -2.0 * zeta * omega]])
    integrator = Integrator(integrator)
    if integrator == Integrator.IMPLICIT_EULER:
        return np.linalg.inv(np.eye(2) - h * a)
    if integrator == Integrator.BDF2:
        # a two-step scheme: (4, 4) companion matrix on (y_n, y_n-1),
        # y_n+1 = (I - 2/3 h a)^-1 (4/3 y_n - 1/3 y_n-1)
        g = np.linalg.inv(np.eye(2) - (2.0 / 3.0) * h * a)
        return np.block([[4.0 / 3.0 * g, -1.0 / 3.0 * g], [np.eye(2), np.zeros((2, 2))]])
    if integrator in (Integrator.EULER, Integrator.MIDPOINT, Integrator.RK4):
        g = np.zeros((2, 2))
        term = np.eye(2)
        for p in range(integrator.order + 1):
            g += term / factorial(p)
            term = term @ (h * a)
        return g
    cols = []
    for x, v in ((1.0, 0.0), (0.0, 1.0)):
        acc = a[1, 0] * x + a[1, 1] * v
        if integrator == Integrator.SYMPLECTIC_EULER:
            v1 = v + h * acc
            x1 = x + h * v1
        else:  # velocity Verlet as implemented: closing force uses the half-step velocity
            vh = v + 0.5 * h * acc
            x1 = x + h * vh
            v1 = vh + 0.5 * h * (a[1, 0] * x1 + a[1, 1] * vh)
        cols.append((x1, v1))
    return np.array(cols).T


def _spectral_radius(m: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(m))))


def largest_stable_step(
    integrator: Integrator, omega: float, zeta: float, *, tolerance: float = 1e-12
) -> float:
    """Largest h [s] with spectral radius <= 1 + tolerance for every step up to h."""
    integrator = Integrator(integrator)
    if omega <= 0 or integrator.implicit:
        # backward Euler: |1 / (1 - h lambda)| <= 1 whenever Re(lambda) <= 0
        return float("inf")

    def stable(h):
        return _spectral_radius(amplification_matrix(integrator, h, omega, zeta)) <= 1 + tolerance

    grid = np.geomspace(1e-6, 10.0, 400) / omega
    good = 0.0
    for h in grid:
        if not stable(h):
            break
        good = h
    else:
        return float(grid[-1])
    lo, hi = good, h
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return float(lo)


def stable_dt(
    model, integrator: str | Integrator = "midpoint", q: np.ndarray | None = None
) -> float:
    """Estimate of the largest stable time step [s] for ``model`` with ``integrator``.

    See the module docstring for the derivation. Without damping, Euler's and Midpoint's
    estimate is ~0: they amplify undamped oscillation at any step size.
    """
    mode = stiffest_mode(model, q)
    return largest_stable_step(Integrator.parse(integrator), mode.omega, mode.zeta)
