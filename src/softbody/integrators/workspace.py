"""Scratch arrays for one model, allocated once so that steps allocate nothing."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Workspace(NamedTuple):
    """Scratch for the step kernels; N particles, B bodies."""

    f: np.ndarray  # (N, 3) force accumulator [N]
    q0: np.ndarray  # (N, 3) positions at the start of the step [m]
    v0: np.ndarray  # (N, 3) velocities at the start of the step [m/s]
    qs: np.ndarray  # (N, 3) stage positions
    vs: np.ndarray  # (N, 3) stage velocities
    acc_q: np.ndarray  # (N, 3) RK4 weighted sum of position slopes
    acc_v: np.ndarray  # (N, 3) RK4 weighted sum of velocity slopes
    volume_gradient: np.ndarray  # (N, 3) dV/dx of each particle's body [m^2]
    body_volume: np.ndarray  # (B,) [m^3]
    body_pressure: np.ndarray  # (B,) [Pa]
    body_lo: np.ndarray  # (B, 3) [m]
    body_hi: np.ndarray  # (B, 3) [m]

    @classmethod
    def for_model(cls, model) -> Workspace:
        """Allocate scratch sized for ``model``."""
        n, b = model.particle_count, model.body_count
        return cls(
            *(np.zeros((n, 3)) for _ in range(8)),
            np.zeros(b),
            np.zeros(b),
            np.zeros((b, 3)),
            np.zeros((b, 3)),
        )
