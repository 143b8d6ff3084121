"""What changes every step: positions, velocities, time."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(eq=False)
class State:
    """Positions and velocities of all particles at one instant.

    Volumes, pressures and energies are derived from it by
    :func:`softbody.body_volume`, :func:`softbody.body_pressure` and :func:`softbody.energies`.
    ``Simulator.step`` advances a state in place.
    """

    particle_q: np.ndarray
    """Particle positions [m], shape (N, 3), float64, C-contiguous."""
    particle_qd: np.ndarray
    """Particle velocities [m/s], shape (N, 3), float64, C-contiguous."""
    time: float = 0.0
    """Simulated time [s]."""
    step_count: int = 0
    """Number of steps taken since the state was made."""
    collider_q: np.ndarray | None = None
    """Centre of each rigid collider [m], shape (C, 3)."""
    collider_rotation: np.ndarray | None = None
    """Orientation of each rigid collider, shape (C, 3, 3)."""
    collider_impulse: np.ndarray | None = None
    """Impulse each collider received from particles during the last ``Simulator.run``
    call [N s], shape (C, 3)."""

    def __post_init__(self):
        if self.collider_q is None:
            self.collider_q = np.zeros((0, 3))
        if self.collider_rotation is None:
            self.collider_rotation = np.zeros((len(self.collider_q), 3, 3)) + np.eye(3)
        if self.collider_impulse is None:
            self.collider_impulse = np.zeros((len(self.collider_q), 3))
        self.collider_q = np.ascontiguousarray(self.collider_q, dtype=np.float64)
        self.collider_rotation = np.ascontiguousarray(self.collider_rotation, dtype=np.float64)
        self.collider_impulse = np.ascontiguousarray(self.collider_impulse, dtype=np.float64)
        self.particle_q = np.ascontiguousarray(self.particle_q, dtype=np.float64)
        self.particle_qd = np.ascontiguousarray(self.particle_qd, dtype=np.float64)
        if self.particle_q.ndim != 2 or self.particle_q.shape[1] != 3:
            raise ValueError(f"particle_q must have shape (N, 3), got {self.particle_q.shape}")
        if self.particle_qd.shape != self.particle_q.shape:
            raise ValueError(
                f"particle_qd shape {self.particle_qd.shape} differs from particle_q "
                f"shape {self.particle_q.shape}"
            )

    def copy(self) -> State:
        """An independent copy."""
        return State(
            self.particle_q.copy(),
            self.particle_qd.copy(),
            self.time,
            self.step_count,
            self.collider_q.copy(),
            self.collider_rotation.copy(),
            self.collider_impulse.copy(),
        )
