"""Backward Euler and BDF2: one Newton step each, solved matrix-free by preconditioned
conjugate gradients (core/solvers/implicit.hpp), with a multigrid V-cycle of the spring
Laplacian (:mod:`softbody.solvers.multigrid`) or Jacobi as the preconditioner."""

from __future__ import annotations

import numpy as np

from softbody import _core
from softbody.integrators import Integrator
from softbody.sim.state import StepHistory
from softbody.solvers.base import RunLimits, RunResult, Solver, Status
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
    BDF2 reads the step before a run's first from the state's history
    (:attr:`~softbody.State.history`, which it writes as it steps) when that belongs to
    the state (no step by another scheme, no write the state saw: ``State.version``) at the
    same dt; otherwise that step is backward Euler.
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
        super().start_hash(entries)  # BDF2's history is the state's: it carries over

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

    def _simulate(self, state, steps, dt, control, limits: RunLimits, progress) -> RunResult:
        bdf2 = self.integrator == Integrator.BDF2
        # the system matrix's step: dt for backward Euler, 2/3 dt for BDF2
        h = dt * (2.0 / 3.0 if bdf2 else 1.0)
        if self._multigrid is not None and self._multigrid_step != h:
            set_multigrid_step(self._multigrid, h)
            self._multigrid_step = h
        if not bdf2:
            return self._result(
                self._core.simulate(
                    False, steps, dt, control, state, limits, self.tolerance,
                    self.max_iterations, False, progress,
                )
            )  # fmt: skip
        # BDF2's history travels with the state: read when it is this state's, and written
        # by the run into its arrays (a new history's, or the old one's reused)
        history = state.history
        use = history is not None and history.belongs_to(state, dt)
        if history is None or history.particle_q.shape != state.particle_q.shape:
            history = StepHistory(dt, state.step_count, state.version,
                                  np.zeros_like(state.particle_q),
                                  np.zeros_like(state.particle_qd))  # fmt: skip
        result = self._result(
            self._core.simulate(
                True, steps, dt, control, state, limits, self.tolerance, self.max_iterations,
                use, progress, history.particle_q, history.particle_qd,
                use and history.contacts_acted,
            )
        )  # fmt: skip
        if result.status in (Status.OK, Status.STOPPED) and (result.steps_done > 0 or use):
            history.dt, history.step_count, history.version = dt, state.step_count, state.version
            history.contacts_acted = self._core.contacts_acted
            state.history = history
        else:  # no whole step, or a failed one: its arrays hold no previous step
            state.history = None
        return result
