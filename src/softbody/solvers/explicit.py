"""The explicit schemes: explicit Euler, midpoint (RK2, the paper's choice), classical RK4,
symplectic Euler and velocity Verlet (core/solvers/explicit.hpp)."""

from __future__ import annotations

from softbody import _core
from softbody.amplification import TOLERATED_GROWTH_RATE, StiffestMode, largest_stable_step
from softbody.integrators import Integrator
from softbody.solvers.base import RunLimits, RunResult, Solver

#: The precisions of the explicit schemes' force pass (``force_precision``).
FORCE_PRECISIONS = ("float64", "float32")


def check_force_precision(precision) -> str:
    """``force_precision`` checked: ``"float64"`` or ``"float32"``, else a ``ValueError``."""
    if not isinstance(precision, str) or precision not in FORCE_PRECISIONS:
        raise ValueError(f"force_precision must be 'float64' or 'float32', got {precision!r}")
    return precision


class ExplicitSolver(Solver):
    """The five explicit schemes; their stable step is bounded by the stiffest spring and
    gas modes (``stability``), so :class:`Simulator` warns above it.

    Option: ``force_precision`` (``"float64"``, default, or ``"float32"``): the precision
    of the force pass's springs and faces (its ring pass). In float32 each particle's row
    holds its position relative to its body's first particle and its velocity, rounded to
    float32, and the ring's springs, dV/dx and volume shares run in float32 lanes (twice as
    many per instruction); the weight, the springs off the rings, the sums into the forces,
    dV/dx and the volumes, the pressure, the integration and every position and velocity
    stay float64. The forces are those of a state perturbed by 2^-24 of each body's size
    and of each velocity (``docs``: where that is safe).
    """

    integrators = (Integrator.EULER, Integrator.MIDPOINT, Integrator.RK4,
                   Integrator.SYMPLECTIC_EULER, Integrator.VELOCITY_VERLET)  # fmt: skip
    option_names = ("force_precision",)

    def __init__(self, model, integrator, *, threads=1, force_precision="float64"):
        self.force_precision = check_force_precision(force_precision)
        super().__init__(model, integrator, threads=threads)

    @property
    def options(self) -> dict:
        return {"force_precision": self.force_precision}

    @classmethod
    def step_limit(cls, integrator: Integrator, mode: StiffestMode) -> float:
        """The step at which no mode bounded by ``mode`` grows faster than
        ``amplification.TOLERATED_GROWTH_RATE``: the scheme's amplification over the damped
        spring modes, the undamped (pressure, stretched-spring) ones and both together
        (``amplification.largest_stable_step``)."""
        return largest_stable_step(
            integrator,
            mode.omega_damped,
            0.0,
            omega_undamped=mode.omega_undamped,
            omega_total=mode.omega,
            damping_per_stiffness=mode.damping_per_stiffness,
            damping_rate=mode.damping_rate,
            growth_rate=TOLERATED_GROWTH_RATE,
        )

    def _make_core(self, hash_capacity):
        return _core.ExplicitSolver(
            self._core_model(), hash_capacity=hash_capacity, threads=self.threads,
            float32=self.force_precision == "float32",
        )  # fmt: skip

    def _simulate(self, state, steps, dt, control, limits: RunLimits, progress) -> RunResult:
        return self._result(
            self._core.simulate(int(self.integrator), steps, dt, control, state, limits, progress)
        )
