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
  one nonzero eigenvalue |P'(V)| sum_i |g_i|^2 / m_i adds to the bound; and the material
  bending hinges' stiffness, per hinge 2 k g g^T (g the gradient of its dihedral angle:
  the Gauss-Newton stiffness) times 1 + 2 |theta - theta0| for the Hessian's other part,
  block rows by Gershgorin.

Membranes (``core/terms/membrane.hpp``) count as damped: their damping is beta times their
stiffness near rest, so their beta joins the range of c / k. Their stiffness is bounded by
Gershgorin on 3 x 3 blocks, a triangle's block (a, b) of norm at most |H_F| |g_a| |g_b|
(|H_F| the spectral radius of its F-Hessian at the given positions, so at their stretch),
and added to the springs' bounds (Weyl); their damping rate likewise.

Each term computes its own pieces of these bounds in its file of the compiled core, its
``bound`` form (``core/terms/*.hpp``: the springs' and attachments' rows against the row
sums both add by their ``add_row_sums``, the gas's pressure rows and rank-one volume mode,
the membranes' and bending's rows), by part, returned by ``softbody._core.stiffness_bounds``
(under ``"terms"``, by name, with the traits that say how they combine);
:func:`stiffest_mode` adds and compares them.

Gershgorin bounds hold for any spring directions but overestimate: on a triangle mesh
the largest eigenvalue of the spring matrix is about half their bound (a flat triangular
lattice: 6 k / m against 12 k / m). So each of these four bounds (damped, undamped, whole,
damping rate) is replaced by ``SPECTRAL_MARGIN`` times the largest eigenvalue at the
given positions, found by Lanczos on matrix-free products (:func:`spectral_bounds`),
where that is smaller.

The stable step of each scheme for modes so bounded is the rule of the solver that
steps it (``step_limit``), from the schemes' amplification on those modes
(:mod:`softbody.amplification`, whose names this module also gives).
"""

from __future__ import annotations

import numpy as np

from softbody import _core
from softbody.amplification import (
    TOLERATED_GROWTH_RATE,
    StiffestMode,
    amplification_matrix,
    largest_stable_step,
    step_radius,
)
from softbody.core import core_model
from softbody.integrators import Integrator
from softbody.sim.control import control_data
from softbody.sim.state import kernel_array
from softbody.solvers import solver_class

__all__ = [
    "DENSE_EIGEN_SIZE",
    "LANCZOS_TOLERANCE",
    "SPECTRAL_MARGIN",
    "TOLERATED_GROWTH_RATE",
    "StiffestMode",
    "amplification_matrix",
    "largest_stable_step",
    "mode_stable_step",
    "spectral_bounds",
    "stable_dt",
    "step_radius",
    "stiffest_mode",
]

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
    damped stiffness, the undamped stiffness, the whole stiffness, and the damping matrix:
    (omega_damped^2, omega_undamped^2, omega^2 [1/s^2], damping rate [1/s]). Stiffness here
    is -df/dx. Each registered term says which of its stiffness goes where (its
    ``spectral_product`` form, ``core/terms/term.hpp``): the springs' and attachments'
    axial k u u^T damped, their transverse k |1 - L0/L| (I - u u^T) undamped; the gas's
    pressure rows and volume mode undamped; material bending's Gauss-Newton stiffness
    undamped; the membranes' clamped stiffness damped and their damping in the damping
    part; a term that does not split its Jacobian counts it whole in every part. The gas's
    state is the estimate's: body_pnet (B,) = P - P_ambient [Pa], body_dpdv (B,) [Pa/m^3]
    and volume_gradient (N, 3) = dV/dx [m^2]. The products come from the compiled core
    (``softbody._core.SpectralOperator``), linearised once. Pinned particles (inverse mass
    0) drop out."""
    n = model.particle_count
    # the compiled product takes C-contiguous float64 arrays
    operator = _core.SpectralOperator(
        core_model(model), control_data(model), kernel_array(q), kernel_array(body_pnet),
        kernel_array(body_dpdv), kernel_array(volume_gradient),
    )  # fmt: skip
    scale = np.sqrt(model.particle_inv_mass)[:, None]
    out = np.zeros((n, 3))

    def part(index: int):
        def matvec(y):
            operator.apply(index, scale * y.reshape(n, 3), out)
            return (scale * -out).ravel()

        return matvec

    size = 3 * n
    damped, undamped, whole, damping = (_largest_eigenvalue(part(k), size) for k in range(4))
    return damped, undamped, whole, damping


def stiffest_mode(model, q: np.ndarray | None = None, *, spectral: bool = True) -> StiffestMode:
    """Bound the vibration frequencies of ``model`` at positions ``q`` (N, 3) [m].

    The gas is taken at its largest scheduled value, so the bound holds for the whole run.
    Attachments are taken at their default anchors. Each bound is the Gershgorin one
    (module docstring), valid for any spring directions; with ``spectral`` it is the
    smaller of that and ``SPECTRAL_MARGIN`` times the largest eigenvalue at ``q``
    (:func:`spectral_bounds`), about half the Gershgorin bound on a triangle mesh.
    """
    q = model.particle_q if q is None else np.asarray(q, dtype=np.float64)
    # each term's Gershgorin pieces from its own file of the core (core/terms/), by name:
    # the terms whose rows are shared (springs and attachments: one row per particle holds
    # both) are bounded together, by the largest of theirs; the terms with a volume mode
    # (the gas: its local pressure rows and that mode) are reported apart; every other
    # term's own bound adds (Weyl): the membranes' (damped), material bending's (undamped)
    pieces = _core.stiffness_bounds(core_model(model), control_data(model), kernel_array(q))
    terms, modes = pieces["terms"], pieces["volume_modes"]
    shared = [terms[name] for name in pieces["shared_rows"]]
    rows = [max(part) for part in zip(*shared, strict=True)] if shared else [0.0] * 4
    alone = {name: parts for name, parts in terms.items()
             if name not in modes and name not in pieces["shared_rows"]}  # fmt: skip
    own = np.sum(list(alone.values()), axis=0) if alone else np.zeros(4)
    w2_damped, w2_transverse, w2_springs, damping_rate = (
        r + float(t) for r, t in zip(rows, own, strict=True)
    )
    low, high = pieces["damping_ratio"]
    beta = (low, high) if low <= high else (0.0, 0.0)  # no spring with stiffness: none
    if pieces["pure_dampers"]:
        beta = (beta[0], np.inf)
    body_pnet, body_dpdv = pieces["body_pnet"], pieces["body_dpdv"]
    volume_gradient = pieces["volume_gradient"]
    # the volume-mode terms' whole bound (its rows and the mode) and the mode alone
    rank_one = float(sum(modes.values()))
    w2_pressure = float(sum(terms[name][1] for name in modes))
    # Weyl: the largest eigenvalue of a sum is at most the sum of the largest eigenvalues
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
        {name: float(np.sqrt(parts[2])) for name, parts in alone.items()},
        {name: float(parts[3]) for name, parts in alone.items()},
    )


def mode_stable_step(integrator: Integrator, mode: StiffestMode) -> float:
    """Largest stable step [s] of ``integrator`` for the modes bounded by ``mode``: the
    rule of the solver that steps it (``softbody.solvers``: ``step_limit``)."""
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
