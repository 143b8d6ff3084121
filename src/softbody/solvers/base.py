"""What every solver shares: the run's outcome codes and the interface a Simulator steps.

A solver owns its method's options, the compiled core's loop with its buffers, its
history and caches (BDF2's previous step, a multigrid hierarchy, factored matrices) and
its stable-step rule. :class:`softbody.Simulator` is the public front: it checks the
options common to all, chooses the step, and turns a failed run into a
:class:`~softbody.SimulationError`.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from softbody.amplification import StiffestMode
from softbody.core import core_model
from softbody.integrators import Integrator


class Status(IntEnum):
    """Outcome of a run of steps (the core's ``softbody::Status``)."""

    OK = 0
    NONFINITE = 1  # a position or velocity became NaN or infinite
    RUNAWAY = 2  # a particle moved faster than the speed limit
    BAD_VOLUME = 3  # a body volume became NaN, zero or negative
    SHRUNK = 4  # a body volume fell below the lower limit
    EXPLODED = 5  # a body volume grew past the upper limit
    NEED_HASH = 6  # the contacts' hash would need > 512 entries a triangle (value: entries)
    STOPPED = 7  # a signal handler or the progress callback raised (the core raises it)
    BAD_GAS = 8  # a body's gas amount or temperature became negative or not finite
    CROSSED = 9  # an edge passes through a triangle (index: its particle, value: the triangle)
    NEED_PAIRS = 10  # the self-contact pair list would need > 4096 pairs a triangle (value: pairs)


@dataclass(frozen=True)
class RunLimits:
    """The checks every step makes: the largest particle speed [m/s] and each body's
    volume between ``ratio_min`` and ``ratio_max`` times its rest volume."""

    max_speed: float
    ratio_min: float
    ratio_max: float


@dataclass(frozen=True)
class RunResult:
    """How a run of steps ended: ``status``, the steps done, the body or particle at
    fault (-1 when none) and the value that failed (a speed [m/s], a volume ratio, a
    volume [m^3], or the hash entries needed)."""

    status: Status
    steps_done: int
    where: int
    value: float


class Solver:
    """A method's loop in the compiled core with its options, buffers and history.

    Subclasses set :attr:`integrators` (the schemes they step) and :attr:`option_names`,
    build their core loop in
    :meth:`_make_core` and step with :meth:`simulate`.
    """

    integrators: tuple[Integrator, ...] = ()
    #: The keyword options of :class:`Simulator` this solver takes.
    option_names: tuple[str, ...] = ()

    def __init__(self, model, integrator: Integrator, *, threads: int = 1):
        if integrator not in self.integrators:
            raise ValueError(f"{type(self).__name__} does not step {integrator.name.lower()}")
        self.model = model
        self.integrator = integrator
        self.threads = int(threads)
        self._core = self._make_core(hash_capacity=None)

    @property
    def options(self) -> dict:
        """This solver's own options, as keyword arguments of :class:`Simulator`."""
        return {}

    @property
    def iterations(self) -> tuple[float, int]:
        """(mean, most) inner iterations per step over the last run; (0, 0) without."""
        return (0.0, 0)

    @classmethod
    def step_limit(cls, integrator: Integrator, mode: StiffestMode) -> float:
        """The largest stable step [s] of ``integrator`` for the modes bounded by ``mode``
        (``stability.stiffest_mode``): each solver's own rule."""
        raise NotImplementedError

    def stable_step(self, mode: StiffestMode) -> float:
        """This solver's largest stable step [s] for the modes bounded by ``mode``."""
        return self.step_limit(self.integrator, mode)

    def start_hash(self, entries: int) -> None:
        """Rebuild the core with room for ``entries`` entries of the surface contacts'
        spatial hash at first (a run grows it inside the core as it needs; the tests start
        small); the solver's history starts over."""
        self._core = self._make_core(hash_capacity=int(entries))

    def begin_run(self) -> None:
        """Called once per :meth:`Simulator.run`, before its first :meth:`simulate`."""

    def end_run(self) -> None:
        """Called once per :meth:`Simulator.run`, after its last :meth:`simulate`."""

    def _make_core(self, hash_capacity: int | None):
        raise NotImplementedError

    def _core_model(self):
        return core_model(self.model)

    def simulate(
        self, state, steps: int, dt: float, control, limits: RunLimits, progress=None
    ) -> RunResult:
        """Advance ``state`` by at most ``steps`` steps of ``dt`` [s] with the control's
        data; stops at the first failed check.

        The core writes the arrays in place and, before it returns or raises, ``state.time``
        and ``state.step_count`` (by the steps done), so no interrupt can leave them behind
        the positions. Between steps it runs Python's signal handlers (on the main thread)
        and, every 50 ms or so, calls ``progress(steps_done)`` (when not None); an exception
        from either (``KeyboardInterrupt`` on Ctrl-C) stops the run after its last whole
        step and is raised here. A state that has not met the model yet (its gas amounts,
        temperatures or vent latches None) is conformed to it first.
        """
        if state.body_gas_moles is None or state.body_gas_temperature is None or (
            state.vent_open is None
        ):
            state.conform(self.model)
        return self._simulate(state, steps, dt, control, limits, progress)

    def _simulate(self, state, steps, dt, control, limits: RunLimits, progress) -> RunResult:
        """The solver's run (simulate's contract), on a state that has met the model."""
        raise NotImplementedError

    @staticmethod
    def _result(raw) -> RunResult:
        status, done, where, value = raw
        return RunResult(Status(status), int(done), int(where), float(value))
