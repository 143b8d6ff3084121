"""Backward Euler and BDF2: one Newton step each, solved matrix-free by preconditioned
conjugate gradients (core/solvers/implicit.hpp), with a multigrid V-cycle of the spring
Laplacian (:mod:`softbody.solvers.multigrid`) or Jacobi as the preconditioner."""

from __future__ import annotations

import weakref

import numpy as np

from softbody import _core
from softbody.integrators import Integrator
from softbody.solvers.base import RunLimits, RunResult, Solver
from softbody.solvers.multigrid import build_multigrid, set_multigrid_step

PRECONDITIONERS = ("multigrid", "jacobi")


def check_options(tolerance, max_iterations, preconditioner) -> tuple[float, int, str]:
    """The implicit solvers' options, checked: (tolerance, max_iterations, preconditioner);
    a ``ValueError`` names the one out of range."""
    if not (np.isfinite(tolerance) and 0 < tolerance < 1):
        raise ValueError(f"implicit_tolerance must lie in (0, 1), got {tolerance!r}")
    if int(max_iterations) != max_iterations or max_iterations < 1:
        raise ValueError(f"implicit_max_iterations must be an integer >= 1, got {max_iterations!r}")
    if preconditioner not in PRECONDITIONERS:
        raise ValueError(
            f"implicit_preconditioner must be 'multigrid' or 'jacobi', got {preconditioner!r}"
        )
    return float(tolerance), int(max_iterations), preconditioner


class ImplicitSolver(Solver):
    """``implicit_euler`` and ``bdf2``: no stable-step limit from the springs or the gas.

    Options: ``implicit_tolerance`` (CG's relative residual, in (0, 1)),
    ``implicit_max_iterations`` (>= 1; a step that reaches it keeps the last iterate) and
    ``implicit_preconditioner`` (``"multigrid"``, built once here, or ``"jacobi"``).
    BDF2 reads the step before a run's first (its history) when the state is the one it
    left, unedited, at the same dt; otherwise that step is backward Euler.
    """

    integrators = (Integrator.IMPLICIT_EULER, Integrator.BDF2)
    option_names = ("implicit_tolerance", "implicit_max_iterations", "implicit_preconditioner")

    def __init__(self, model, integrator, *, threads=1, implicit_tolerance=1.0e-6,
                 implicit_max_iterations=200, implicit_preconditioner="multigrid"):  # fmt: skip
        options = check_options(implicit_tolerance, implicit_max_iterations,
                                implicit_preconditioner)  # fmt: skip
        self.tolerance, self.max_iterations, self.preconditioner = options
        self._multigrid = build_multigrid(model) if implicit_preconditioner == "multigrid" else None
        self._multigrid_step = None
        # BDF2's history: which state, at which step and dt, the core's previous step
        # belongs to, and that state's arrays then (to see edits between calls)
        self._history: tuple | None = None
        self._q_end = np.zeros((model.particle_count, 3))
        self._v_end = np.zeros((model.particle_count, 3))
        self._stats = [0, 0, 0]  # steps, CG iterations, most in one step (this run)
        super().__init__(model, integrator, threads=threads)

    @property
    def options(self) -> dict:
        return {
            "implicit_tolerance": self.tolerance,
            "implicit_max_iterations": self.max_iterations,
            "implicit_preconditioner": self.preconditioner,
        }

    @property
    def multigrid(self):
        """The multigrid hierarchy (:class:`~softbody.solvers.multigrid.Multigrid`), or
        None with the Jacobi preconditioner."""
        return self._multigrid

    @property
    def iterations(self) -> tuple[float, int]:
        steps, total, most = self._stats
        return (total / steps if steps else 0.0, most)

    @classmethod
    def step_limit(cls, integrator: Integrator, mode) -> float:
        """No limit: backward Euler and BDF2 are A-stable, |amplification| <= 1 for every
        mode with Re(lambda) <= 0, whatever the step (the Newton step's linearisation is
        the accuracy limit, not a stability one)."""
        return float("inf")

    def _make_core(self, hash_capacity):
        return _core.ImplicitSolver(
            self._core_model(), multigrid=self._multigrid, hash_capacity=hash_capacity,
            threads=self.threads,
        )  # fmt: skip

    def start_hash(self, entries: int) -> None:
        self._collect_stats()
        super().start_hash(entries)
        self._history = None  # a new core holds no previous step

    def begin_run(self) -> None:
        self._stats = [0, 0, 0]
        self._core.clear_stats()

    def end_run(self) -> None:
        self._collect_stats()

    def _collect_stats(self) -> None:
        """Add the core's CG statistics to this run's, and clear them there."""
        steps, total, most = self._core.cg_stats
        acc = self._stats
        acc[0], acc[1], acc[2] = acc[0] + steps, acc[1] + total, max(acc[2], most)
        self._core.clear_stats()

    def _has_history(self, state, dt: float) -> bool:
        ref = self._history
        return (
            self.integrator == Integrator.BDF2
            and ref is not None
            and ref[0]() is state
            and ref[1:] == (state.step_count, dt)
            and np.array_equal(state.particle_q, self._q_end)
            and np.array_equal(state.particle_qd, self._v_end)
        )

    def _simulate(self, state, steps, dt, control, limits: RunLimits, progress) -> RunResult:
        bdf2 = self.integrator == Integrator.BDF2
        # the system matrix's step: dt for backward Euler, 2/3 dt for BDF2
        h = dt * (2.0 / 3.0 if bdf2 else 1.0)
        if self._multigrid is not None and self._multigrid_step != h:
            set_multigrid_step(self._multigrid, h)
            self._multigrid_step = h
        history = self._has_history(state, dt)
        result = self._result(
            self._core.simulate(
                bdf2, steps, dt, control, state, limits, self.tolerance, self.max_iterations,
                history, progress,
            )
        )  # fmt: skip
        if bdf2 and (result.steps_done > 0 or history):
            self._history = (weakref.ref(state), state.step_count, dt)
            self._q_end[:] = state.particle_q
            self._v_end[:] = state.particle_qd
        return result
