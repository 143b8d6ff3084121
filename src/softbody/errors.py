"""Exceptions and warnings raised by softbody.

Every error says what is wrong and, where it can, how much of it: a user should be
able to fix the input from the message alone.
"""

from __future__ import annotations


class MeshError(ValueError):
    """A mesh cannot enclose gas: open, non-manifold, inconsistently wound or degenerate."""


class MeshWarning(UserWarning):
    """A mesh was repaired on the way in (welded seams, flipped inward-facing winding)."""


class SimulationError(RuntimeError):
    """A run blew up: non-finite values, runaway speed or a collapsed/exploded volume.

    Attributes
    ----------
    step : int
        Index of the step (``State.step_count`` numbering) at which the problem was found.
    time : float
        Simulated time of that step [s].
    body : int
        Body index, or -1 when the problem is not tied to a body (a free particle).
    particle : int
        Particle index, or -1 when the problem is a whole-body quantity (volume).
    """

    def __init__(self, message: str, *, step: int, time: float, body: int, particle: int):
        super().__init__(message)
        self.step = step
        self.time = time
        self.body = body
        self.particle = particle


class StabilityWarning(UserWarning):
    """The time step exceeds the stability estimate of the chosen integrator."""


class SizeLimitError(ValueError):
    """A job would need more memory than :func:`softbody.limits.memory_limit` allows; the
    message names the key or argument, the estimated memory and the limit."""
