"""Metrics of one run, computed from its history in the worker.

A run's :class:`History` holds its time series sampled at the sweep's ``sample_rate``;
each built-in metric below is a number per body (column ``body{b}.{name}``) or per run
(column ``{name}``). A user metric is any function ``f(history) -> float | dict[str,
float]`` (a dict gives several columns ``{name}.{key}``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass
class History:
    """One run's sampled time series (T samples, B bodies, C colliders)."""

    t: np.ndarray
    """Sample times [s], shape (T,)."""
    volume: np.ndarray
    """Body volumes [m^3], shape (T, B)."""
    rest_volume: np.ndarray
    """Body rest volumes [m^3], shape (B,)."""
    pressure: np.ndarray
    """Body gas pressures [Pa], shape (T, B)."""
    center_of_mass: np.ndarray
    """Body centres of mass [m], shape (T, B, 3)."""
    extent: np.ndarray
    """Size of each body's axis-aligned bounding box [m], shape (T, B, 3)."""
    kinetic: np.ndarray
    """Body kinetic energies [J], shape (T, B)."""
    energy: np.ndarray
    """Total energy (kinetic + gravitational + spring + gas) [J], shape (T,)."""
    collider_impulse: np.ndarray
    """Impulse each collider took from the particles over the interval ending at each
    sample [N s], shape (T, C, 3) (zero at t = 0)."""
    body_names: list[str]
    blowup_time: float | None = None
    """Simulated time of the blow-up [s], None when the run finished."""
    params: dict | None = None
    """The run's varied values."""
    gas_moles: np.ndarray | None = None
    """Amount of gas in each body [mol], shape (T, B), NaN for a body without a gas state
    (a cloth, a fixed pressure); None when no body has one."""
    gas_temperature: np.ndarray | None = None
    """Gas temperature of each body [K], shape (T, B), as ``gas_moles``."""
    mass_inflow: np.ndarray | None = None
    """Mass flow of gas into each body [kg/s], shape (T, B) (vents, orifices, inflators,
    leaks), NaN as ``gas_moles``; None when the model has no flows."""
    mass_outflow: np.ndarray | None = None
    """Mass flow of gas out of each body [kg/s], shape (T, B), as ``mass_inflow``."""


def _settling_time(t: np.ndarray, kinetic: np.ndarray, fraction: float = 1e-3) -> float:
    """First time after which the kinetic energy stays below ``fraction`` of its peak
    [s]; NaN when it has not settled by the last sample."""
    peak = float(np.max(kinetic)) if kinetic.size else 0.0
    if peak <= 0:
        return float(t[0])
    above = np.flatnonzero(kinetic > fraction * peak)
    if not above.size:
        return float(t[0])
    last = above[-1]
    return float(t[last + 1]) if last + 1 < t.size else float("nan")


def _rebound(y: np.ndarray) -> tuple[float, float]:
    """(apex height of the centre of mass after its lowest point [m], the fraction of the
    fall recovered: (apex - lowest) / (start - lowest)); NaN without a fall."""
    low = int(np.argmin(y))
    drop = y[0] - y[low]
    if low + 1 >= y.size or drop <= 0:
        return float("nan"), float("nan")
    apex = float(np.max(y[low + 1 :]))
    return apex, float((apex - y[low]) / drop)


def _first_rebound(y: np.ndarray) -> float:
    """The first bounce of a fall: (apex - low) / (start - low), where low is the first
    local minimum of the centre-of-mass height in the lower half of the whole fall (the
    first impact) and apex the first local maximum after it (the last sample when the
    height rises to the end); 0 when it never rises again, NaN without a fall."""
    drop = y[0] - np.min(y)
    if y.size < 3 or drop <= 0:
        return float("nan")
    low = None
    for k in range(1, y.size - 1):
        if y[k] <= y[0] - 0.5 * drop and y[k + 1] > y[k] <= y[k - 1]:
            low = k
            break
    if low is None:
        return 0.0
    apex = low + 1
    while apex + 1 < y.size and y[apex + 1] >= y[apex]:
        apex += 1
    return float((y[apex] - y[low]) / (y[0] - y[low]))


def _gas_metrics(h: History, b: int) -> dict[str, float]:
    """Body ``b``'s gas metrics: where it has a gas state, and the flows where the model
    has flows (none otherwise)."""
    if h.gas_moles is None or np.isnan(h.gas_moles[0, b]):
        return {}
    out = {
        "gas_moles_final": float(h.gas_moles[-1, b]),
        "gas_moles_min": float(np.min(h.gas_moles[:, b])),
        "gas_temperature_final": float(h.gas_temperature[-1, b]),
        "gas_temperature_max": float(np.max(h.gas_temperature[:, b])),
    }
    if h.mass_inflow is not None:
        dt = np.diff(h.t)
        for name, flow in (("inflow", h.mass_inflow[:, b]), ("outflow", h.mass_outflow[:, b])):
            out[f"gas_mass_{name}_max"] = float(np.max(flow))
            out[f"gas_mass_{name}_total"] = float(np.sum(0.5 * (flow[1:] + flow[:-1]) * dt))
    return out


def body_metrics(h: History, b: int) -> dict[str, float]:
    """The built-in metrics of body ``b`` (the gas metrics only where it has a gas state,
    the flow metrics only where the model has flows)."""
    ratio = h.volume[:, b] / h.rest_volume[b]
    com = h.center_of_mass[:, b]
    apex, recovered = _rebound(com[:, 1])
    size = h.extent[-1, b]
    return {
        "volume_ratio_final": float(ratio[-1]),
        "volume_ratio_min": float(np.min(ratio)),
        "volume_ratio_max": float(np.max(ratio)),
        "pressure_final": float(h.pressure[-1, b]),
        "pressure_max": float(np.max(h.pressure[:, b])),
        "com_x_final": float(com[-1, 0]),
        "com_y_final": float(com[-1, 1]),
        "com_z_final": float(com[-1, 2]),
        "sag": float(com[0, 1] - com[-1, 1]),
        "aspect_final": float(size[1] / max(0.5 * (size[0] + size[2]), 1e-300)),
        "rebound_height": apex,
        "rebound_ratio": recovered,
        "first_rebound_ratio": _first_rebound(com[:, 1]),
        "settling_time": _settling_time(h.t, h.kinetic[:, b]),
        **_gas_metrics(h, b),
    }


#: Built-in per-body metrics (column ``body{b}.{name}``) with their units.
BODY_METRICS = {
    "volume_ratio_final": "volume over rest volume at the end",
    "volume_ratio_min": "smallest volume over rest volume",
    "volume_ratio_max": "largest volume over rest volume",
    "pressure_final": "gas pressure at the end [Pa]",
    "pressure_max": "largest gas pressure [Pa]",
    "com_x_final": "centre of mass x at the end [m]",
    "com_y_final": "centre of mass y (up) at the end [m]",
    "com_z_final": "centre of mass z at the end [m]",
    "sag": "fall of the centre of mass from start to end [m]",
    "aspect_final": "height over mean width (y extent over the mean of x and z) at the end",
    "rebound_height": "apex of the centre of mass after its lowest point [m]",
    "rebound_ratio": "(apex - lowest) / (start - lowest) of the centre of mass height",
    "first_rebound_ratio": "(apex - low) / (start - low) of the first bounce: low is the first "
    "impact (the first local minimum of the centre of mass height in the lower half of the "
    "fall), apex the first maximum after it; 0 when it does not rise again",
    "settling_time": "time after which the kinetic energy stays below 1e-3 of its peak [s]",
    "gas_moles_final": "amount of gas at the end [mol] (a body with a gas state)",
    "gas_moles_min": "smallest amount of gas [mol]",
    "gas_temperature_final": "gas temperature at the end [K]",
    "gas_temperature_max": "largest gas temperature [K]",
    "gas_mass_inflow_max": "largest mass flow of gas in [kg/s] (a model with flows)",
    "gas_mass_inflow_total": "mass of gas that came in [kg] (trapezoid rule over the samples)",
    "gas_mass_outflow_max": "largest mass flow of gas out [kg/s]",
    "gas_mass_outflow_total": "mass of gas that went out [kg] (trapezoid rule over the samples)",
}
#: Built-in per-run metrics (column ``{name}``).
RUN_METRICS = {
    "energy_drift": "total energy at the end minus at the start [J]",
    "energy_drift_relative": "energy_drift over the largest |total energy| seen",
    "blowup_time": "simulated time of the blow-up [s] (NaN: none)",
    "duration": "simulated time reached [s]",
}
BUILTIN_METRICS = {**BODY_METRICS, **RUN_METRICS}


def compute_metrics(
    h: History,
    names: list[str] | None = None,
    user: dict[str, Callable] | None = None,
) -> dict[str, float]:
    """Metric columns of one run: the built-in ``names`` (all when None) for every body
    and the run, then each user metric (one that raises makes the run's row an error
    naming it)."""
    keep = set(BUILTIN_METRICS) if names is None else set(names)
    out: dict[str, float] = {}
    for b in range(h.volume.shape[1]):
        for key, value in body_metrics(h, b).items():
            if key in keep:
                out[f"body{b}.{key}"] = value
    e = h.energy
    run = {
        "energy_drift": float(e[-1] - e[0]),
        "energy_drift_relative": float((e[-1] - e[0]) / max(np.max(np.abs(e)), 1e-300)),
        "blowup_time": float("nan") if h.blowup_time is None else float(h.blowup_time),
        "duration": float(h.t[-1]),
    }
    out.update({k: v for k, v in run.items() if k in keep})
    for name, fn in (user or {}).items():
        value = fn(h)
        if isinstance(value, dict):
            out.update({f"{name}.{k}": float(v) for k, v in value.items()})
        else:
            out[name] = float(value)
    return out
