"""The solvers a :class:`~softbody.Simulator` steps with, one class per method, each
owning its options, the compiled core's loop and buffers, its history and caches and its
stable-step rule: :class:`ExplicitSolver` (five explicit schemes), :class:`ImplicitSolver`
(backward Euler and BDF2), :class:`ProjectiveSolver` (projective dynamics) and
:class:`SubstepSolver` (XPBD with small steps)."""

from __future__ import annotations

from softbody.integrators import Integrator
from softbody.solvers.base import RunLimits, RunResult, Solver, Status
from softbody.solvers.explicit import ExplicitSolver
from softbody.solvers.implicit import ImplicitSolver
from softbody.solvers.projective import ProjectiveSolver
from softbody.solvers.substep import SubstepSolver

SOLVERS: tuple[type[Solver], ...] = (
    ExplicitSolver, ImplicitSolver, ProjectiveSolver, SubstepSolver
)


def solver_class(integrator: Integrator) -> type[Solver]:
    """The solver class that steps ``integrator``."""
    for cls in SOLVERS:
        if integrator in cls.integrators:
            return cls
    raise ValueError(f"no solver steps {integrator!r}")


__all__ = [
    "SOLVERS",
    "ExplicitSolver",
    "ImplicitSolver",
    "ProjectiveSolver",
    "RunLimits",
    "RunResult",
    "Solver",
    "Status",
    "SubstepSolver",
    "solver_class",
]
