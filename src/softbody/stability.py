"""Largest stable time step, from spring stiffness, masses and pressure stiffness.

The stiffest vibration mode bounds explicit time steps. Its squared angular frequency is
the largest eigenvalue of M^-1/2 K M^-1/2; K, the stiffness matrix, has parts bounded
separately and added (Weyl's inequality), split by whether spring damping acts on them:

* damped: the axial spring blocks k u u^T (and the attachments'); Gershgorin on the
  spring-by-spring matrix gives max over springs (i, j) of sqrt(k) (R_i / m_i + R_j / m_j),
  R_i the sum of sqrt(k) over springs at i (exact for one spring, the Anderson-Morley
  bound for equal springs). Spring damping c u u^T acts on exactly this part, with
  c / k [s] per spring;
* undamped: the transverse (geometric) spring blocks k (1 - L0/L)(I - u u^T), bounded
  the same way with k |1 - L0/L|; the local pressure term (P - P_a) d2V/dx2, for a face
  (i, j, l) a block coupling i to j of norm |P - P_a| |x_l - x_i| / 6 (Gershgorin by
  rows); and the rank-one term -P'(V) g g^T with g = dV/dx (the breathing mode), whose
  one nonzero eigenvalue |P'(V)| sum_i |g_i|^2 / m_i adds to the bound.

Each term computes its own pieces of these bounds in its file of the compiled core
(``core/terms/springs.hpp``, ``attachments.hpp``, ``gas.hpp``: ``bound_weights``,
``add_root_sums``, ``row_bounds``, ``damping_ratios``; ``bound_slopes``,
``add_pressure_rows``, ``rank_one_bound``), returned by ``softbody._core.stiffness_bounds``;
:func:`stiffest_mode` adds and compares them.

Gershgorin bounds hold for any spring directions but overestimate: on a triangle mesh
the largest eigenvalue of the spring matrix is about half their bound (a flat triangular
lattice: 6 k / m against 12 k / m). So each of these four bounds (damped, undamped, whole,
damping rate) is replaced by ``SPECTRAL_MARGIN`` times the largest eigenvalue at the
given positions, found by Lanczos on matrix-free products (:func:`spectral_bounds`),
where that is smaller.

A mode then has squared frequency lambda = lambda_d + lambda_u with lambda_d in
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

from dataclasses import dataclass
from math import factorial

import numpy as np

from softbody import _core
from softbody.core import core_model
from softbody.integrators import Integrator
from softbody.sim.control import control_data
from softbody.sim.state import kernel_array

TOLERATED_GROWTH_RATE = 0.1
"""Growth rate [1/s] of the fastest-growing mode that the step estimate accepts."""

SPECTRAL_MARGIN = 1.15
"""Factor on the largest eigenvalues found by Lanczos before they replace a Gershgorin
bound. It covers Lanczos' tolerance (``LANCZOS_TOLERANCE``) and the change of the
spectrum as bodies move and deform after the estimate: over each built-in scene's run
(inflation, squashing against walls and floors) the largest eigenvalue of the damped
part and of the damping rose by at most 7% from its value at the start."""

DENSE_EIGEN_SIZE = 300
"""Operators up to this size (3 x particles) are built whole and solved densely."""

LANCZOS_TOLERANCE = 1e-2
"""ARPACK's relative tolerance for the largest eigenvalue (its Ritz residual at most this
times the eigenvalue, so the eigenvalue is at most this fraction low). On the 40,962-vertex
ball it made the four runs 3.4x faster than 1e-3 (0.56 s against 1.92 s) and the step
estimate 0.24% longer, well inside ``SPECTRAL_MARGIN``."""


@dataclass(frozen=True)
class StiffestMode:
    """Bounds on the vibration frequencies of a model."""

    omega: float
    """Upper bound on the highest angular frequency [rad/s]; at most the damped and
    undamped bounds added, less where a spring's two parts overlap."""
    zeta: float
    """Damping ratio of that mode if its damped part is at its bound (0 = undamped)."""
    omega_damped: float
    """Bound on the part spring damping acts on: axial springs, attachments [rad/s]."""
    omega_undamped: float
    """Bound on the rest: transverse (stretched) springs, pressure [rad/s]."""
    damping_per_stiffness: tuple[float, float]
    """Smallest and largest c / k over damped springs and attachments [s]; the largest is
    inf where a damper has no stiffness."""
    damping_rate: float
    """Bound on the largest eigenvalue of M^-1 C, C the damping matrix [1/s]."""
    omega_pressure: float
    """Part of the bound from the pressure terms alone [rad/s]."""
    omega_gas: float = 0.0
    """Part of that from the rank-one term dP/dV g g^T alone, the gas's resistance to a
    change of volume, against the masses [rad/s]."""


def _stretch(length, rest_length):
    """|1 - L0 / L|, 1 where L = 0 (the transverse stiffness factor)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(length > 0, np.abs(1.0 - rest_length / length), 1.0)


def _largest_eigenvalue(matvec, size: int, seed: int = 0) -> float:
    """Largest eigenvalue of the symmetric operator ``matvec`` on vectors of ``size``:
    dense for small operators, else Lanczos (ARPACK, relative tolerance
    ``LANCZOS_TOLERANCE``, from a seeded random start); inf if Lanczos does not converge."""
    if size <= DENSE_EIGEN_SIZE:
        a = np.column_stack([matvec(e) for e in np.eye(size)])
        return float(np.linalg.eigvalsh(0.5 * (a + a.T))[-1])
    from scipy.sparse.linalg import ArpackNoConvergence, LinearOperator, eigsh

    v0 = np.random.default_rng(seed).standard_normal(size)
    if not np.any(matvec(v0)):
        return 0.0  # ARPACK stops on a zero operator
    operator = LinearOperator((size, size), matvec=matvec, dtype=np.float64)
    try:
        top = eigsh(
            operator, k=1, which="LA", v0=v0, tol=LANCZOS_TOLERANCE, return_eigenvectors=False
        )
    except ArpackNoConvergence:
        return float("inf")
    return float(top[0])


def spectral_bounds(
    model, q: np.ndarray, body_pnet: np.ndarray, body_dpdv: np.ndarray, volume_gradient
) -> tuple[float, float, float, float]:
    """Largest eigenvalues of M^-1/2 A M^-1/2 at positions ``q`` (N, 3) [m] for A the
    damped stiffness (axial springs and attachments), the undamped stiffness (transverse
    springs k |1 - L0/L| (I - u u^T), attachments alike, and the pressure terms), the
    whole stiffness, and the damping matrix: (omega_damped^2, omega_undamped^2,
    omega^2 [1/s^2], damping rate [1/s]). Stiffness here is -df/dx. The pressure terms
    use body_pnet (B,) = P - P_ambient [Pa], body_dpdv (B,) [Pa/m^3] and
    volume_gradient (N, 3) = dV/dx [m^2]; products come from the implicit integrator's
    matrix-free ``apply_jacobians``. Pinned particles (inverse mass 0) drop out."""
    n = model.particle_count
    # the compiled product takes C-contiguous float64 arrays
    q = kernel_array(q)
    body_pnet, body_dpdv = kernel_array(body_pnet), kernel_array(body_dpdv)
    volume_gradient = kernel_array(volume_gradient)
    scale = np.sqrt(model.particle_inv_mass)[:, None]
    idx = model.spring_indices.reshape(-1, 2)
    k = kernel_array(model.spring_stiffness)
    d = q[idx[:, 1]] - q[idx[:, 0]]
    length = np.linalg.norm(d, axis=1)
    u = np.divide(d, length[:, None], out=np.zeros_like(d), where=length[:, None] > 0)
    transverse = k * _stretch(length, model.spring_rest_length)
    # attachments: a (3, 3) block on their particle each, added here
    a = model.attachment_particle
    da = model.attachment_anchor - q[a]
    la = np.linalg.norm(da, axis=1)
    ua = np.divide(da, la[:, None], out=np.zeros_like(da), where=la[:, None] > 0)
    axial_block = ua[:, :, None] * ua[:, None, :]
    ka = model.attachment_stiffness
    ta = ka * _stretch(la, model.attachment_rest_length)
    damped_a = ka[:, None, None] * axial_block
    undamped_a = ta[:, None, None] * (np.eye(3) - axial_block)
    damping_a = model.attachment_damping[:, None, None] * axial_block
    core = core_model(model)
    control = control_data(model)
    out = np.zeros((n, 3))
    no_gas = np.zeros(model.body_count)

    def operator(axial, side, alpha_c, alpha_k, pnet, dpdv, anchored):
        # spring blocks (axial - side) u u^T + side I, as apply_jacobians builds them
        def matvec(y):
            p = scale * y.reshape(n, 3)
            # attachments are added below, as the blocks at this call's anchors
            _core.apply_jacobians(
                core, control, q, p, 0.0, alpha_c, alpha_k, u, axial, side,
                volume_gradient, dpdv, pnet, out, attachments=False,
            )  # fmt: skip
            r = -out
            if len(a):
                np.add.at(r, a, np.einsum("aij,aj->ai", anchored, p[a]))
            return (scale * r).ravel()

        return matvec

    zero = np.zeros_like(k)
    size = 3 * n
    return (
        _largest_eigenvalue(operator(k, zero, 0.0, 1.0, no_gas, no_gas, damped_a), size),
        _largest_eigenvalue(
            operator(zero, transverse, 0.0, 1.0, body_pnet, body_dpdv, undamped_a), size
        ),
        _largest_eigenvalue(
            operator(k, transverse, 0.0, 1.0, body_pnet, body_dpdv, damped_a + undamped_a), size
        ),
        _largest_eigenvalue(operator(k, zero, 1.0, 0.0, no_gas, no_gas, damping_a), size),
    )


def stiffest_mode(model, q: np.ndarray | None = None, *, spectral: bool = True) -> StiffestMode:
    """Bound the vibration frequencies of ``model`` at positions ``q`` (N, 3) [m].

    The gas is taken at its largest scheduled value, so the bound holds for the whole run.
    Attachments are taken at their default anchors. Each bound is the Gershgorin one
    (module docstring), valid for any spring directions; with ``spectral`` it is the
    smaller of that and ``SPECTRAL_MARGIN`` times the largest eigenvalue at ``q``
    (:func:`spectral_bounds`), about half the Gershgorin bound on a triangle mesh.
    """
    q = model.particle_q if q is None else np.asarray(q, dtype=np.float64)
    # each term's Gershgorin pieces from its own file of the core (core/terms/): springs
    # and attachments share the row sums R_i, so the two terms' rows are bounded together
    pieces = _core.stiffness_bounds(core_model(model), control_data(model), kernel_array(q))
    springs, attached = pieces["springs"], pieces["attachments"]
    w2_damped, w2_transverse, w2_springs, damping_rate = (
        max(s, a) for s, a in zip(springs, attached, strict=True)
    )
    low, high = pieces["damping_ratio"]
    beta = (low, high) if low <= high else (0.0, 0.0)  # no spring with stiffness: none
    if pieces["pure_dampers"]:
        beta = (beta[0], np.inf)
    body_pnet, body_dpdv = pieces["body_pnet"], pieces["body_dpdv"]
    volume_gradient = pieces["volume_gradient"]
    rank_one = pieces["gas_rank_one"]
    # Weyl: the largest eigenvalue of a sum is at most the sum of the largest eigenvalues
    w2_pressure = pieces["pressure_rows"] + rank_one
    w2_undamped = w2_transverse + w2_pressure
    w2_total = min(w2_damped + w2_undamped, w2_springs + w2_pressure)
    if spectral and model.particle_count > 0:
        bounds = spectral_bounds(model, q, body_pnet, body_dpdv, volume_gradient)
        s_damped, s_undamped, s_total, s_rate = (SPECTRAL_MARGIN * max(x, 0.0) for x in bounds)
        w2_damped = min(w2_damped, s_damped)
        w2_undamped = min(w2_undamped, s_undamped)
        w2_total = min(w2_total, s_total, w2_damped + w2_undamped)
        damping_rate = min(damping_rate, s_rate)
    omega = float(np.sqrt(w2_total))
    zeta = beta[0] * w2_damped / (2.0 * omega) if omega > 0 else 0.0
    return StiffestMode(
        omega,
        float(zeta),
        float(np.sqrt(w2_damped)),
        float(np.sqrt(w2_undamped)),
        beta,
        damping_rate,
        float(np.sqrt(w2_pressure)),
        float(np.sqrt(rank_one)),
    )


def amplification_matrix(integrator: Integrator, h: float, omega: float, zeta: float) -> np.ndarray:
    """One step of ``integrator`` on x'' = -omega^2 x - 2 zeta omega x' as a (2, 2) matrix
    ((4, 4) on the last two states for the two-step BDF2)."""
    a = np.array([[0.0, 1.0], [-(omega**2), -2.0 * zeta * omega]])
    integrator = Integrator(integrator)
    if integrator == Integrator.PROJECTIVE:
        raise ValueError("projective dynamics has no fixed amplification matrix")
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


def mode_stable_step(integrator: Integrator, mode: StiffestMode) -> float:
    """Largest stable step [s] of ``integrator`` for the modes bounded by ``mode``: the
    rule of the solver that steps it (``softbody.solvers``: ``step_limit``)."""
    from softbody.solvers import solver_class  # the solvers build on this module

    integrator = Integrator.parse(integrator)
    return solver_class(integrator).step_limit(integrator, mode)


def stable_dt(
    model, integrator: str | Integrator = "midpoint", q: np.ndarray | None = None
) -> float:
    """Estimate of the largest stable time step [s] for ``model`` with ``integrator``.

    See the module docstring for the derivation. Euler and Midpoint amplify undamped
    vibration at any step size; their estimate is the step at which that growth stays
    below ``TOLERATED_GROWTH_RATE`` (tiny for Euler).
    """
    integrator = Integrator.parse(integrator)
    # the implicit schemes have no step limit: skip the Lanczos runs, as Simulator does
    return mode_stable_step(integrator, stiffest_mode(model, q, spectral=integrator.explicit))
