"""Spring energies (NumPy), for the diagnostics."""

from __future__ import annotations

import numpy as np


def spring_energy(
    q: np.ndarray, indices: np.ndarray, rest_length: np.ndarray, stiffness: np.ndarray
) -> np.ndarray:
    """Elastic energy 1/2 k (L - L0)^2 of each spring [J], shape (S,). NumPy reference."""
    length = np.linalg.norm(q[indices[:, 1]] - q[indices[:, 0]], axis=1)
    return 0.5 * stiffness * (length - rest_length) ** 2


def attachment_energy(
    q: np.ndarray,
    particle: np.ndarray,
    anchor: np.ndarray,
    rest_length: np.ndarray,
    stiffness: np.ndarray,
) -> np.ndarray:
    """Elastic energy of each attachment spring [J], shape (A,)."""
    length = np.linalg.norm(anchor - q[particle], axis=1)
    return 0.5 * stiffness * (length - rest_length) ** 2
