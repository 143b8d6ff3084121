"""The explicit schemes: explicit Euler, midpoint (RK2, the paper's choice), classical RK4,
symplectic Euler and velocity Verlet (core/solvers/explicit.hpp)."""

from __future__ import annotations

from softbody import _core
from softbody.integrators import Integrator
from softbody.solvers.base import RunLimits, RunResult, Solver
from softbody.stability import TOLERATED_GROWTH_RATE, StiffestMode, largest_stable_step


class ExplicitSolver(Solver):
    """The five explicit schemes; their stable step is bounded by the stiffest spring and
    gas modes (``stability``), so :class:`Simulator` warns above it."""

    integrators = (Integrator.EULER, Integrator.MIDPOINT, Integrator.RK4,
                   Integrator.SYMPLECTIC_EULER, Integrator.VELOCITY_VERLET)  # fmt: skip

    @classmethod
    def step_limit(cls, integrator: Integrator, mode: StiffestMode) -> float:
        """The step at which no mode bounded by ``mode`` grows faster than
        ``stability.TOLERATED_GROWTH_RATE``: the scheme's amplification over the damped
        spring modes, the undamped (pressure, stretched-spring) ones and both together
        (``stability.largest_stable_step``)."""
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
            self._core_model(), hash_capacity=hash_capacity, threads=self.threads
        )

    def simulate(self, state, steps, dt, control, limits: RunLimits) -> RunResult:
        return self._result(
            self._core.simulate(
                int(self.integrator), steps, float(state.time), dt, control, state.particle_q,
                state.particle_qd, state.collider_q, state.collider_rotation,
                state.collider_impulse, limits.max_speed, limits.ratio_min, limits.ratio_max,
            )
        )  # fmt: skip
