"""All forces of a state: every term the core registers (``core/terms/registry.hpp``,
``softbody.core.terms()``), each by its reference module's ``TERMS`` entry, summed in the
registry's order; and the potential energy of the conservative ones.
"""

from __future__ import annotations

import functools
import importlib
import pkgutil
from typing import NamedTuple

import numpy as np

import softbody.reference
from softbody.core import terms as registered_terms
from softbody.reference import (
    attachments,
    bending,
    external,
    gas,
    gravity,
    membrane,
    springs,
    volume,
)
from softbody.sim.control import ControlData
from softbody.sim.model import Model


class Forces(NamedTuple):
    """What ``softbody._core.eval_forces`` returns, in its order."""

    force: np.ndarray  # (N, 3) [N]
    volume: np.ndarray  # (B,) [m^3], each body by its own method
    pressure: np.ndarray  # (B,) absolute [Pa]
    volume_gradient: np.ndarray  # (N, 3) exact dV/dx [m^2]


def gas_state(
    model: Model, control: ControlData, t: float, q: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(volume (B,) [m^3] by each body's method, pressure (B,) [Pa], exact dV/dx (N, 3)
    [m^2]) at time t [s] and positions q (N, 3): what ``softbody._core.eval_volumes``
    returns."""
    v = volume.volumes(model, q)
    return v, gas.pressures(model, control, t, v), volume.gradient(model, q)


def terms(
    model: Model, control: ControlData, t: float, q: np.ndarray, qd: np.ndarray
) -> dict[str, np.ndarray]:
    """Each registered term's force (N, 3) [N] at time t [s], q, qd (N, 3), by name, in
    the order the core adds them. A term without a reference is a KeyError."""
    state = gas_state(model, control, t, q)
    forms = reference_terms()
    return {
        name: forms[name](model, control, t, q, qd, state)
        for name in (term["name"] for term in registered_terms())
    }


@functools.cache
def reference_terms() -> dict:
    """Every reference module's ``TERMS``: term name -> its force function (the package
    scanned once)."""
    out: dict = {}
    for info in pkgutil.iter_modules(softbody.reference.__path__):
        module = importlib.import_module(f"softbody.reference.{info.name}")
        out.update(getattr(module, "TERMS", {}))
    return out


def eval_forces(
    model: Model, control: ControlData, t: float, q: np.ndarray, qd: np.ndarray
) -> Forces:
    """The total force and the gas state at time t [s] for q, qd (N, 3)."""
    v, pressure, grad = gas_state(model, control, t, q)
    f = np.zeros_like(q, dtype=np.float64)
    for term in terms(model, control, t, q, qd).values():
        f += term
    return Forces(f, v, pressure, grad)


def potential_energy(model: Model, control: ControlData, t: float, q: np.ndarray) -> float:
    """Energy [J] of the conservative terms at q (N, 3): gravity, springs, attachments,
    the grab spring, bending, the membranes and the closed bodies' gas (at their exact
    volumes). At zero
    velocities, without dissipative and external forces, and with every body closed and of the
    exact volume, -dE/dx is the total force."""
    return (
        gravity.energy(model, q)
        + springs.energy(model, q)
        + attachments.energy(model, control, q)
        + external.grab_energy(control, q)
        + bending.energy(model, q)
        + membrane.energy(model, q)
        + gas.potential_energy(model, control, t, q)
    )
