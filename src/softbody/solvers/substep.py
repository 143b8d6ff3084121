"""XPBD with small steps: each step cut into substeps, each a prediction under the forces
that stay explicit and one pass (or a few) of compliant constraints over the springs and
attachments, Gauss-Seidel colour by colour (core/solvers/substep.hpp; Macklin et al.
2016, 2019)."""

from __future__ import annotations

import numpy as np

from softbody import _core
from softbody.amplification import StiffestMode
from softbody.integrators import Integrator
from softbody.solvers.base import RunLimits, RunResult, Solver

#: Substeps per step by default: the fewest that keep the 2,562-vertex ball drop's
#: rebound >= 0.9 m at 1/60 s steps with its volume within [0.7, 1.5] of its start
#: (``benchmarks/ball_drop.py``, measured: 12 substeps rebound 1.02 m but swell to 2.5x,
#: 24 to 1.62x, 32 to 1.47x; docs/guide/integrators.md).
DEFAULT_SUBSTEPS = 32


def check_count(name: str, value) -> int:
    """An option that counts (``xpbd_substeps``, ``xpbd_iterations``) checked: an integer
    >= 1, else a ``ValueError`` naming it."""
    integer = isinstance(value, int | np.integer) and not isinstance(value, bool)
    if not integer or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    return int(value)


def check_relaxation(value) -> float:
    """``xpbd_relaxation`` checked: a real number in (0, 2) (successive over-relaxation
    converges for a symmetric positive definite system there), else a ``ValueError``
    naming it."""
    number = isinstance(value, int | float | np.integer | np.floating)
    if isinstance(value, bool) or not number or not 0.0 < float(value) < 2.0:
        raise ValueError(f"xpbd_relaxation must be a number in (0, 2), got {value!r}")
    return float(value)


def colour_springs(indices: np.ndarray, particle_count: int) -> tuple[np.ndarray, np.ndarray]:
    """A greedy edge colouring of the springs ``indices`` (S, 2): each spring, in order,
    takes the lowest colour neither end has yet, so no two springs of a colour share a
    particle (at most 2 d - 1 colours for largest degree d; an icosphere takes 7-8).

    Returns ``(order, colour_ptr)``: the springs colour by colour, (S,) int64, each colour
    in spring order, and colour c's entries ``order[colour_ptr[c]:colour_ptr[c + 1]]``,
    (colours + 1,) int64.
    """
    ends = np.asarray(indices, dtype=np.int64).reshape(-1, 2)
    used = [0] * int(particle_count)  # per particle: a bit per colour taken
    colour = np.empty(len(ends), dtype=np.int64)
    for s, (i, j) in enumerate(ends.tolist()):
        taken = used[i] | used[j]
        c = (~taken & (taken + 1)).bit_length() - 1  # the lowest clear bit
        colour[s] = c
        bit = 1 << c
        used[i] |= bit
        used[j] |= bit
    order = np.argsort(colour, kind="stable").astype(np.int64)
    counts = np.bincount(colour, minlength=1) if len(colour) else np.zeros(0, np.int64)
    colour_ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return order, colour_ptr


class SubstepSolver(Solver):
    """``xpbd``: XPBD with small steps. Each step of dt takes ``xpbd_substeps`` substeps of
    h = dt / n; each substep predicts x + h v + h^2 f / m under the forces of the terms
    without a constraint form (gravity, the pressure from the exact volume and dV/dx, the
    air on faces, bending, membranes, Control's), runs ``xpbd_iterations`` passes of the
    springs' and attachments' compliant distance constraints (compliance 1 / k, XPBD's
    damping from c), Gauss-Seidel over a colouring of the springs, sets v = (x - x_prev) /
    h and resolves the contacts.

    The constraints are stable at any h; the explicit forces are symplectic Euler within
    each substep, so the pressure bounds h (``step_limit``). First order: as the substeps
    grow the dynamics converge to the springs' own (velocity Verlet's), the error falling
    like h.

    Options: ``xpbd_substeps`` (>= 1, default ``DEFAULT_SUBSTEPS``), ``xpbd_iterations``
    (>= 1, default 1; Macklin et al. 2019: more substeps beat more iterations),
    ``xpbd_relaxation`` (omega in (0, 2), default 1): every pass after a substep's first
    moves each constraint by omega times its Gauss-Seidel step (successive
    over-relaxation). The first pass stays plain, so a lone constraint (solved exactly by
    it: the next pass's step is zero) keeps its exact static stretch at any omega, and the
    converged solution of the substep is the same; what omega > 1 speeds up is the
    coupled network's slow modes, which a few plain passes leave soft where
    (k h^2 + c h) w is not small (docs/guide/integrators.md).
    """

    integrators = (Integrator.XPBD,)
    option_names = ("xpbd_substeps", "xpbd_iterations", "xpbd_relaxation")

    def __init__(
        self,
        model,
        integrator,
        *,
        threads=1,
        xpbd_substeps=DEFAULT_SUBSTEPS,
        xpbd_iterations=1,
        xpbd_relaxation=1.0,
    ):
        self.substeps = check_count("xpbd_substeps", xpbd_substeps)
        self.iterations_per_substep = check_count("xpbd_iterations", xpbd_iterations)
        self.relaxation = check_relaxation(xpbd_relaxation)
        self.spring_order, self.colour_ptr = colour_springs(
            model.spring_indices, model.particle_count
        )
        super().__init__(model, integrator, threads=threads)

    @property
    def options(self) -> dict:
        return {
            "xpbd_substeps": self.substeps,
            "xpbd_iterations": self.iterations_per_substep,
            "xpbd_relaxation": self.relaxation,
        }

    @classmethod
    def substep_limit(cls, mode: StiffestMode) -> float:
        """The largest stable substep h [s]: 1 / omega, omega the largest of the gas's volume
        mode and the terms XPBD keeps explicit that have a bound of their own, material
        bending and the membranes (``mode.omega_gas``, ``mode.omega_terms``), and at most
        1 / c for c the largest damping rate of those terms (``mode.damping_rate_terms``: a
        membrane's strain-rate damping, explicit in the substep as its stiffness is).

        The constraints (springs, attachments) are solved, not integrated: XPBD with
        compliance is stable for them at any h. What stays explicit is symplectic Euler
        within the substep, stable on a mode x'' = -omega^2 x for h omega < 2; the pressure's
        volume mode (its rank-one dP/dV g g^T against the masses), the bending hinges and the
        membranes are the stiff ones, and 1 / omega keeps the margin projective dynamics
        keeps for the same mode. The local part of the pressure Hessian is resisted by the
        constraints (as in ``ProjectiveSolver.step_limit``); gravity and the air (slow) do
        not bound h.
        """
        w = max(mode.omega_gas, *mode.omega_terms.values())
        # their own damping, explicit too: symplectic Euler on x' = -c x needs h c < 2
        rate = max(0.0, *mode.damping_rate_terms.values())
        return min(float("inf") if w <= 0 else 1.0 / w, float("inf") if rate <= 0 else 1.0 / rate)

    @classmethod
    def step_limit(cls, integrator: Integrator, mode: StiffestMode) -> float:
        """The largest stable step [s] at ``DEFAULT_SUBSTEPS`` substeps: that many times
        :meth:`substep_limit` (an instance's :meth:`stable_step` uses its own count)."""
        return DEFAULT_SUBSTEPS * cls.substep_limit(mode)

    def stable_step(self, mode: StiffestMode) -> float:
        """``xpbd_substeps`` times the largest stable substep (:meth:`substep_limit`)."""
        return self.substeps * self.substep_limit(mode)

    def _make_core(self, hash_capacity):
        return _core.SubstepSolver(
            self._core_model(), self.spring_order, self.colour_ptr,
            hash_capacity=hash_capacity, threads=self.threads,
        )  # fmt: skip

    def _simulate(self, state, steps, dt, control, limits: RunLimits, progress) -> RunResult:
        return self._result(
            self._core.simulate(
                steps,
                dt,
                self.substeps,
                self.iterations_per_substep,
                self.relaxation,
                control,
                state,
                limits,
                progress,
            )
        )
