"""Projective dynamics: backward Euler by local-global iterations on a matrix factored
once per step size (:mod:`softbody.solvers.factor`; the iterations are the core's,
core/solvers/projective.hpp)."""

from __future__ import annotations

import numpy as np

from softbody import _core
from softbody.integrators import Integrator
from softbody.solvers.base import RunLimits, RunResult, Solver
from softbody.solvers.factor import Projective, build_projective

#: Factored matrices kept, one per step size.
PROJECTIVE_FACTORS = 4


def check_iterations(iterations) -> int:
    """``projective_iterations`` checked: an integer >= 1, else a ``ValueError``."""
    integer = isinstance(iterations, int | np.integer) and not isinstance(iterations, bool)
    if not integer or iterations < 1:
        raise ValueError(f"projective_iterations must be an integer >= 1, got {iterations!r}")
    return int(iterations)


class ProjectiveSolver(Solver):
    """``projective``: the springs implicit at any step, the pressure explicit within each
    iteration, which bounds the step by the gas's volume mode (``stability``).

    Option: ``projective_iterations`` (>= 1, default 2), local-global iterations per
    step; more converge to backward Euler.

    Thickness contacts (``set_soft_contact("surface", thickness=h)``): the pairs nearer
    than 2 h at a step's start are held at 1.5 h or more inside the iterations, by forces
    that one dual step with the factor updates after each global solve (one more
    triangular solve per iteration while a pair is near); the contact stage still runs
    after the step (core/solvers/projective.hpp).
    """

    integrators = (Integrator.PROJECTIVE,)
    option_names = ("projective_iterations",)

    def __init__(self, model, integrator, *, threads=1, projective_iterations=2):
        self.iterations_per_step = check_iterations(projective_iterations)
        self._factors: dict[float, Projective] = {}
        super().__init__(model, integrator, threads=threads)

    @property
    def options(self) -> dict:
        return {"projective_iterations": self.iterations_per_step}

    def factor(self, dt: float) -> Projective:
        """The global matrix factored for step ``dt`` [s]: built once per step size (about
        0.5 s at 40,962 particles), the last ``PROJECTIVE_FACTORS`` kept, since
        :meth:`Simulator.advance` may alternate between a few substep sizes."""
        cache = self._factors
        if dt not in cache:
            if len(cache) >= PROJECTIVE_FACTORS:
                del cache[next(iter(cache))]
            cache[dt] = build_projective(self.model, dt)
        return cache[dt]

    @classmethod
    def step_limit(cls, integrator: Integrator, mode) -> float:
        """1 / omega_gas [s], the gas's volume mode (``mode.omega_gas``).

        Projective dynamics takes the springs implicitly and the pressure explicitly
        within each iteration: on a pressure mode x'' = -omega^2 x resisted by the masses
        alone, one iteration from y = x0 + h v0 is stable for (h omega)^2 < 4/3 and the
        iterations contract for (h omega)^2 < 1. The local part (P - P_a) d2V/dx2 of the
        pressure Hessian, of order P times an edge length per particle, is not counted:
        the global matrix holds every spring's full stiffness k against it (k = 500 N/m
        against about 1 N/m in the ball drop), so it is resisted by the springs, not the
        masses; a model where it is not (springs far softer than the pressure) is caught
        by the blow-up checks.
        """
        w = mode.omega_gas
        return float("inf") if w <= 0 else 1.0 / w

    def _make_core(self, hash_capacity):
        return _core.ProjectiveSolver(
            self._core_model(), hash_capacity=hash_capacity, threads=self.threads
        )

    def _simulate(self, state, steps, dt, control, limits: RunLimits, progress) -> RunResult:
        factor = self.factor(dt)
        if self._core.factor is not factor:  # checked once per factor (per dt)
            self._core.set_factor(factor)
        return self._result(
            self._core.simulate(
                steps, dt, self.iterations_per_step, control, state, limits, progress
            )
        )
