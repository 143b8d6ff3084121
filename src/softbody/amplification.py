"""How large a step each time-stepping scheme takes on bounded vibration modes.

The modes of a model are bounded by :func:`softbody.stability.stiffest_mode` (a
:class:`StiffestMode`); each solver's ``step_limit`` turns those bounds into its
largest stable step with the functions here. They know the schemes, not the model, so
the solvers build on this module and :mod:`softbody.stability` builds on the solvers.

A mode so bounded has squared frequency lambda = lambda_d + lambda_u with lambda_d in
[0, omega_damped^2], lambda_u in [0, omega_undamped^2], their sum at most omega^2 (the
springs bounded whole, each block of norm k max(1, |1 - L0/L|), plus pressure), and
damping rate (the d in x'' = -lambda x - d x') between beta_min lambda_d and
beta_max lambda_d, beta = c / k, and at most the largest damping rate (the same
Gershgorin bound on M^-1 C, c for k). Dampers without stiffness (k = 0, c > 0) may give
any mode the largest damping rate.
The stable step is the largest h for which the scheme's amplification matrix on every
such oscillator has spectral radius <= 1. Checking the stiffest mode alone is not enough:
with damping proportional to stiffness a strongly damped stiff mode can be stable at a
step where a less stiff, less damped one grows (the paper's ball under velocity Verlet:
tested against the ball's linearised equations). RK4 is stable to omega h ~ 2.8,
symplectic Euler and velocity Verlet to omega h = 2 undamped. Explicit Euler and Midpoint
amplify every undamped vibration, by (omega h)^2 / 2 and (omega h)^4 / 8 per step, at any
h; for them the estimate is the step at which no mode grows faster than
``TOLERATED_GROWTH_RATE`` (one e-fold per 10 simulated seconds) or, for slow modes,
1e-3 of the mode's own rate.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from math import factorial

import numpy as np

from softbody.integrators import Integrator

TOLERATED_GROWTH_RATE = 0.1
"""Growth rate [1/s] of the fastest-growing mode that the step estimate accepts."""


@dataclass(frozen=True)
class StiffestMode:
    """Bounds on the vibration frequencies of a model."""

    omega: float
    """Upper bound on the highest angular frequency [rad/s]; at most the damped and
    undamped bounds added, less where a spring's two parts overlap."""
    zeta: float
    """Damping ratio of that mode if its damped part is at its bound (0 = undamped)."""
    omega_damped: float
    """Bound on the part spring damping acts on: axial springs, attachments, membranes
    [rad/s]."""
    omega_undamped: float
    """Bound on the rest: transverse (stretched) springs, pressure [rad/s]."""
    damping_per_stiffness: tuple[float, float]
    """Smallest and largest c / k over damped springs and attachments, and membranes'
    damping times beta [s]; the largest is inf where a damper has no stiffness."""
    damping_rate: float
    """Bound on the largest eigenvalue of M^-1 C, C the damping matrix [1/s]."""
    omega_pressure: float
    """Part of the bound from the pressure terms alone [rad/s]."""
    omega_gas: float = 0.0
    """Part of that from the rank-one term dP/dV g g^T alone, the gas's resistance to a
    change of volume, against the masses [rad/s]."""
    omega_terms: dict = field(default_factory=dict)
    """The part of the bound from each registered term with a bound form of its own (the
    membranes, material bending: its Gershgorin rows, ``softbody.stability``), against
    the masses [rad/s], by name; absent where the model has none of that term."""
    damping_rate_terms: dict = field(default_factory=dict)
    """The bound on each of those terms' own damping rate (the largest eigenvalue of
    M^-1 C for its C alone) [1/s], by name: a membrane's strain-rate damping; 0 for
    undamped bending."""


def amplification_matrix(integrator: Integrator, h: float, omega: float, zeta: float) -> np.ndarray:
    """One step of ``integrator`` on x'' = -omega^2 x - 2 zeta omega x' as a (2, 2) matrix
    ((4, 4) on the last two states for the two-step BDF2)."""
    a = np.array([[0.0, 1.0], [-(omega**2), -2.0 * zeta * omega]])
    integrator = Integrator(integrator)
    if integrator == Integrator.PROJECTIVE:
        raise ValueError("projective dynamics has no fixed amplification matrix")
    if integrator == Integrator.XPBD:
        raise ValueError("xpbd has no fixed amplification matrix (its constraints are solved)")
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


def step_radius(integrator: Integrator, h: float, lam: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Spectral radius of one explicit step of ``integrator`` on x'' = -lam x - d x', for
    arrays of squared frequencies ``lam`` [1/s^2] and damping rates ``d`` [1/s]; the same
    matrices as :func:`amplification_matrix` (omega^2 = lam, 2 zeta omega = d), in closed
    form over whole arrays."""
    integrator = Integrator(integrator)
    lam, d = np.broadcast_arrays(np.asarray(lam, dtype=np.float64), np.asarray(d, np.float64))
    one, zero = np.ones_like(lam), np.zeros_like(lam)
    if integrator in (Integrator.EULER, Integrator.MIDPOINT, Integrator.RK4):
        # sum over p of (h a)^p / p!, a = [[0, 1], [-lam, -d]]
        a00, a01, a10, a11 = zero, h * one, -h * lam, -h * d
        g = [one, zero, zero, one]
        t = [one, zero, zero, one]
        for p in range(1, integrator.order + 1):
            t = [
                (t[0] * a00 + t[1] * a10) / p,
                (t[0] * a01 + t[1] * a11) / p,
                (t[2] * a00 + t[3] * a10) / p,
                (t[2] * a01 + t[3] * a11) / p,
            ]
            g = [gi + ti for gi, ti in zip(g, t, strict=True)]
    elif integrator == Integrator.SYMPLECTIC_EULER:
        v_x, v_v = -h * lam, one - h * d
        g = [one + h * v_x, h * v_v, v_x, v_v]
    elif integrator == Integrator.VELOCITY_VERLET:
        vh_x, vh_v = -0.5 * h * lam, one - 0.5 * h * d
        x_x, x_v = one + h * vh_x, h * vh_v
        g = [
            x_x,
            x_v,
            vh_x + 0.5 * h * (-lam * x_x - d * vh_x),
            vh_v + 0.5 * h * (-lam * x_v - d * vh_v),
        ]
    else:
        raise ValueError(f"{integrator.name.lower()} is not an explicit one-step scheme")
    # eigenvalues (g00 + g11) / 2 +- sqrt(((g00 - g11) / 2)^2 + g01 g10): this form of the
    # discriminant has no cancellation of terms near 1. The textbook trace^2 / 4 - det
    # lost it all at small steps (rounding of 1e-16 against a true value of order
    # (omega h)^2): radii of 1 + 1e-8 for stable modes made the estimate for a 40,962-
    # vertex ball 2e-22 s instead of 1e-5 s
    half_trace = 0.5 * (g[0] + g[3])
    half_gap = 0.5 * (g[0] - g[3])
    root = np.sqrt((half_gap**2 + g[1] * g[2]).astype(np.complex128))
    return np.maximum(np.abs(half_trace + root), np.abs(half_trace - root))


def largest_stable_step(
    integrator: Integrator,
    omega: float,
    zeta: float,
    *,
    omega_undamped: float = 0.0,
    omega_total: float | None = None,
    damping_per_stiffness: tuple[float, float] | None = None,
    damping_rate: float = np.inf,
    growth_rate: float = 0.0,
    tolerance: float = 1e-12,
) -> float:
    """Largest h [s] such that for every step up to h no mode grows faster than
    ``growth_rate`` [1/s] or 1e-3 of its own rate sqrt(lambda) + d (spectral radius <=
    exp(that h) (1 + tolerance)).

    The modes (module docstring): damped part lambda_d = s omega^2 for s in [0, 1] with
    damping rate beta lambda_d, beta = 2 zeta / omega (stiffness-proportional damping, so
    the damping ratio falls with the frequency) or each end of ``damping_per_stiffness``
    [s], at most ``damping_rate`` [1/s]; plus an undamped part in [0, omega_undamped^2];
    the two adding to at most ``omega_total``^2 (default: no limit beyond the parts).
    """
    integrator = Integrator(integrator)
    total = float(np.hypot(omega, omega_undamped) if omega_total is None else omega_total)
    rate = total if np.isinf(damping_rate) else max(total, damping_rate)
    if rate <= 0 or not integrator.explicit:
        # backward Euler: |1 / (1 - h lambda)| <= 1 whenever Re(lambda) <= 0 (projective
        # dynamics: for its springs; its solver adds its pressure limit)
        return float("inf")
    if damping_per_stiffness is None:
        damping_per_stiffness = (2.0 * zeta / omega if omega > 0 else 0.0,) * 2
    s_damped = np.linspace(0.0, 1.0, 129)[:, None, None]
    s_undamped = np.linspace(0.0, 1.0, 9 if omega_undamped > 0 else 1)[None, :, None]
    low, high = damping_per_stiffness
    # the two ends and their geometric mean (damping ratios can spread over decades)
    middle = np.sqrt(low * high) if np.isfinite(high) else low
    beta = np.array(sorted({low, middle, high}))[None, None, :]
    lam_damped = s_damped * min(omega, total) ** 2
    lam_undamped = np.clip(
        np.minimum(s_undamped * omega_undamped**2, total**2 - lam_damped), 0, None
    )
    with np.errstate(invalid="ignore"):  # inf * 0: a pure damper on a mode of any stiffness
        d = np.where(np.isinf(beta), damping_rate, beta * lam_damped)
    lam, d = np.broadcast_arrays(lam_damped + lam_undamped, np.minimum(d, damping_rate))
    lam, d = lam.ravel(), d.ravel()

    # growth accepted per mode: growth_rate, but never more than 1e-3 of the mode's own
    # rate, so slow modes (a soft damper, say) keep their sharp limits
    accepted = np.minimum(growth_rate, 1e-3 * (np.sqrt(lam) + d))

    def stable(h):
        bound = np.exp(accepted * h) * (1.0 + tolerance)
        return bool(np.all(step_radius(integrator, h, lam, d) <= bound))

    grid = np.geomspace(1e-6, 10.0, 50) / rate
    good = 0.0
    for h in grid:
        if not stable(h):
            break
        good = h
    else:
        return float(grid[-1])
    lo, hi = good, h
    for _ in range(48):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return float(lo)
