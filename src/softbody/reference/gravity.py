"""Uniform gravity (``core/terms/gravity.hpp``).

f_i = m_i g,        E = -sum_i m_i g . x_i,        K = 0 (a constant force).
"""

from __future__ import annotations

import numpy as np

from softbody.sim.model import Model


def force(model: Model) -> np.ndarray:
    """Weight m_i g of every particle [N], shape (N, 3); pinned particles included (the
    integrators ignore forces on them through their inverse mass 0)."""
    return model.particle_mass[:, None] * model.gravity[None, :]


def energies(model: Model, q: np.ndarray) -> np.ndarray:
    """Gravitational energy -m_i g . x_i of each particle [J], shape (N,), at q (N, 3)."""
    return -model.particle_mass * (q @ model.gravity)


def energy(model: Model, q: np.ndarray) -> float:
    """Total gravitational energy -sum_i m_i g . x_i [J]; -dE/dx = :func:`force`."""
    return float(energies(model, q).sum())


#: This term's force for softbody.reference.forces (by its name in the core's registry).
TERMS = {"gravity": lambda model, control, t, q, qd, gas: force(model)}
