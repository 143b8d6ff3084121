"""Parameter sweeps on Dask: many runs of one scene, their metrics and time series.

``softbody.sweep(scene, out, vary={...})`` (this module is callable) and the command
``softbody sweep`` run a scene once per combination of varied values, on a Dask
``LocalCluster`` of worker processes by default or on any Dask cluster by address, and
write one Parquet table (a row per run), the runs' time series as a partitioned Parquet
dataset and a summary figure (:mod:`softbody.sweep.store`). Needs the ``sweep`` extra:
``pip install 'softbody[sweep]'``.
"""

from __future__ import annotations

import sys
import types
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from softbody.sweep.metrics import BUILTIN_METRICS, History, compute_metrics
from softbody.sweep.spec import (
    SweepError,
    SweepSpec,
    build_spec,
    is_sweep_file,
    load_sweep_file,
    parse_values,
)

__all__ = [
    "BUILTIN_METRICS",
    "History",
    "SweepError",
    "SweepResult",
    "SweepSpec",
    "build_spec",
    "compute_metrics",
    "is_sweep_file",
    "load_sweep_file",
    "parse_values",
    "run_one",
    "run_sweep",
    "sweep",
]


def __getattr__(name: str):
    if name in ("SweepResult", "run_one", "run_sweep"):
        from softbody.sweep import runner

        return getattr(runner, name)
    raise AttributeError(name)


def _check_dependencies() -> None:
    missing = []
    for module in ("dask.distributed", "pyarrow"):
        try:
            __import__(module)
        except ImportError:
            missing.append(module.split(".")[0])
    if missing:
        raise RuntimeError(
            f"sweeps need {' and '.join(missing)}: pip install 'softbody[sweep]'"
        )


def sweep(
    scene: str | Path | SweepSpec,
    out: str | Path,
    *,
    vary: dict[str, Any] | None = None,
    set: dict[str, Any] | None = None,
    random: dict | None = None,
    metrics: Sequence[str] | None = None,
    user_metrics: dict[str, Callable] | None = None,
    sample_rate: float = 100.0,
    workers: int | None = None,
    address: str | None = None,
    figure: bool = True,
    progress=sys.stderr,
):
    """Run a sweep and write its table, series and figure into ``out``; a ``SweepResult``.

    ``scene``: a built-in scene name, a scene file, a sweep file (then ``vary``,
    ``random`` and ``metrics`` come from it, ``set`` adds to its own) or a
    :class:`SweepSpec`. ``vary``: ``{"bodies.0.gas.nrt": [1, 4, 16], "bodies.0.stiffness":
    {"low": 10, "high": 100, "count": 4, "log": True}}`` (a grid: every combination);
    ``random``: ``{"samples": 20, "seed": 1, "latin": True, "vary": {key:
    {"distribution": "uniform", "low": 0, "high": 1}}}``. ``metrics``: built-in metric
    names to keep (default all, :data:`BUILTIN_METRICS`); ``user_metrics``: name ->
    ``f(history: History) -> float | dict``. ``sample_rate``: history samples per
    simulated second [1/s]. ``workers``: local worker processes (default one per core; 0
    runs in this process); ``address``: a Dask scheduler to run on instead. Rerunning
    with the same ``out`` skips the runs already in its table.
    """
    _check_dependencies()
    from softbody.sweep.runner import run_sweep

    if isinstance(scene, SweepSpec):
        spec = scene
    elif is_sweep_file(scene):
        spec = load_sweep_file(scene, extra_set=set)
        spec.user_metrics.update(user_metrics or {})
    else:
        spec = build_spec(
            str(scene),
            vary=vary,
            set=set,
            random=random,
            metrics=metrics,
            user_metrics=user_metrics,
            sample_rate=sample_rate,
        )
    return run_sweep(
        spec, out, workers=workers, address=address, figure=figure, progress=progress
    )


class _CallableModule(types.ModuleType):
    """``softbody.sweep`` is this package and its main function at once."""

    def __call__(self, *args, **kwargs):
        return sweep(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
