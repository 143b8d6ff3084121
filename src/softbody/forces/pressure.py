"""A readable NumPy form of the paper's pressure force, for the tests."""

from __future__ import annotations

import numpy as np


def pressure_forces_reference(q: np.ndarray, faces: np.ndarray, pressure: float) -> np.ndarray:
    """Readable NumPy version for one body: P * area * unit normal / 3 per corner, (N, 3) [N]."""
    a, b, c = q[faces[:, 0]], q[faces[:, 1]], q[faces[:, 2]]
    n = np.cross(b - a, c - a)
    area = 0.5 * np.linalg.norm(n, axis=1, keepdims=True)
    face_force = pressure * area * n / np.maximum(2.0 * area, 1e-300)
    f = np.zeros_like(q)
    for k in range(3):
        np.add.at(f, faces[:, k], face_force / 3.0)
    return f
