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


def body_metrics(h: History, b: int) -> dict[str, float]:
    """The built-in metrics of body ``b``."""
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
        "settling_time": _settling_time(h.t, h.kinetic[:, b]),
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
    "settling_time": "time after which the kinetic energy stays below 1e-3 of its peak [s]",
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
