"""A sweep description: a base scene, fixed overrides, parameters to vary, metrics.

A sweep file (TOML)::

    scene = "hanging-ball"            # a built-in scene, or a .toml path beside this file
    set = { "simulation.duration" = 2.0 }
    metrics = ["sag", "volume_ratio_final"]   # default: every built-in metric
    sample_rate = 100.0               # history samples per simulated second [1/s]

    [vary]                            # grid: the product of every list and range
    "bodies.0.gas.nrt" = [1, 4, 16]
    "bodies.0.stiffness" = { low = 10, high = 100, count = 4, log = true }
    "simulation.integrator" = ["midpoint", "rk4"]

    [random]                          # instead of a grid: seeded random samples
    samples = 20
    seed = 1
    latin = true                      # Latin hypercube for the uniform draws
    [random.vary]
    "bodies.0.gas.nrt" = { distribution = "loguniform", low = 1, high = 100 }
    "bodies.0.mass" = { distribution = "normal", mean = 1.0, std = 0.1 }

Keys are addressed like ``softbody run --set`` (``bodies.0.gas.nrt``); ``*`` stands for
every entry of a list (``bodies.*.stiffness``). On the command line a varied value is a
list ``1,4,16``, a range ``low:high:count`` with an optional ``:log``, or a distribution
``uniform:low:high``, ``loguniform:low:high``, ``normal:mean:std`` (with ``--samples``).

Every run's scene is resolved and validated against the scene schema before anything
runs, so that a typo is one line naming the key (:class:`SweepError`).
"""

from __future__ import annotations

import builtins
import copy
import hashlib
import json
import math
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from itertools import product
from pathlib import Path
from typing import Any

import numpy as np

from softbody.scenes import loader

#: Most runs one sweep may hold: more is almost always a count off by orders of magnitude.
MAX_RUNS = 1_000_000
SWEEP_KEYS = {"scene", "set", "vary", "random", "metrics", "sample_rate", "description", "name"}
RANDOM_KEYS = {"samples", "seed", "latin", "vary"}
DISTRIBUTIONS = {"uniform": ("low", "high"), "loguniform": ("low", "high"),
                 "normal": ("mean", "std")}  # fmt: skip


class SweepError(ValueError):
    """A sweep description is wrong; the message is one line saying where and why."""


@dataclass
class Run:
    """One run of a sweep: its id, its varied values and its resolved scene table."""

    run_id: str
    """Hash of the resolved scene table (16 hex digits): the same run has the same id."""
    params: dict[str, Any]
    """Varied key -> value, as the sweep names them (``bodies.*.stiffness``)."""
    data: dict
    """The scene table with every override applied."""


@dataclass
class SweepSpec:
    """A parsed, validated sweep. ``runs`` lists every run in order."""

    scene: str
    """Built-in scene name or scene file path."""
    scene_name: str
    base: Path | None
    """Folder relative mesh paths of the scene are read from (None: built-in)."""
    varied: list[str]
    runs: list[Run]
    metrics: list[str] | None = None
    """Built-in metric names to keep (None: all)."""
    user_metrics: dict[str, Callable] = field(default_factory=dict)
    sample_rate: float = 100.0
    description: str = ""

    def fingerprint(self) -> dict:
        """What makes two sweeps the same sweep (stored in the output folder)."""
        return {
            "scene": self.scene_name,
            "varied": self.varied,
            "sample_rate": self.sample_rate,
            "metrics": self.metrics,
            "user_metrics": sorted(self.user_metrics),
        }


def run_id(data: dict) -> str:
    """A run's id: SHA-256 of the resolved scene table as canonical JSON, 16 hex digits."""
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


# -- values ------------------------------------------------------------------------------
def _number(text: str, where: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise SweepError(f"{where}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise SweepError(f"{where}: {text!r} must be finite")
    return value


def _range(low: float, high: float, count: Any, log: bool, where: str) -> list[float]:
    if isinstance(count, bool) or not isinstance(count, int | float) or count != int(count):
        raise SweepError(f"{where}: count must be a whole number, got {count!r}")
    count = int(count)
    if not 1 <= count <= MAX_RUNS:
        raise SweepError(f"{where}: count must lie in [1, {MAX_RUNS:,}], got {count}")
    for name, v in (("low", low), ("high", high)):
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise SweepError(f"{where}: {name} must be a finite number, got {v!r}")
    if log:
        if low <= 0 or high <= 0:
            raise SweepError(f"{where}: a log range needs low and high > 0, got {low}, {high}")
        values = np.geomspace(low, high, count)
    else:
        values = np.linspace(low, high, count)
    return [float(v) for v in values]


def parse_values(text: str, where: str) -> list | dict:
    """A ``--vary`` value: ``1,4,16`` -> list; ``10:100:4[:log]`` -> range as a list;
    ``uniform:0:1`` / ``loguniform:1:100`` / ``normal:1:0.1`` -> a distribution table."""
    text = text.strip()
    head = text.split(":", 1)[0]
    if head in DISTRIBUTIONS:
        parts = text.split(":")
        if len(parts) != 3:
            raise SweepError(f"{where}: write {head}:{':'.join(DISTRIBUTIONS[head])}")
        a, b = DISTRIBUTIONS[head]
        return {"distribution": head, a: _number(parts[1], where), b: _number(parts[2], where)}
    if ":" in text and "," not in text and not text.startswith(("[", '"', "'")):
        parts = text.split(":")
        log = parts[-1] == "log"
        if log:
            parts = parts[:-1]
        if len(parts) != 3:
            raise SweepError(
                f"{where}: a range is low:high:count with an optional :log, got {text!r}"
            )
        low, high = _number(parts[0], where), _number(parts[1], where)
        return _range(low, high, _number(parts[2], where), log, where)
    items = [loader.parse_override(f"v={item}")[1] for item in text.split(",")]
    if any(isinstance(v, str) and not v for v in items):
        raise SweepError(f"{where}: empty value in the list {text!r}")
    return items


def _values(spec: Any, where: str) -> list:
    """A grid entry of ``[vary]``: a list (a tuple or NumPy array is one too), or a range
    table {low, high, count, log}."""
    if isinstance(spec, np.ndarray | tuple):
        spec = np.asarray(spec).tolist() if isinstance(spec, np.ndarray) else list(spec)
    if isinstance(spec, list):
        if not spec:
            raise SweepError(f"{where}: the list of values is empty")
        return spec
    if isinstance(spec, dict):
        if "distribution" in spec:
            raise SweepError(f"{where}: a distribution belongs in [random.vary], not [vary]")
        unknown = set(spec) - {"low", "high", "count", "log"}
        if unknown or not {"low", "high", "count"} <= set(spec):
            raise SweepError(
                f"{where}: a range is {{ low, high, count, log }}, got keys {sorted(spec)}"
            )
        return _range(spec["low"], spec["high"], spec["count"], bool(spec.get("log")), where)
    return [spec]


def _distribution(spec: Any, where: str) -> dict:
    if not isinstance(spec, dict) or spec.get("distribution") not in DISTRIBUTIONS:
        raise SweepError(
            f"{where}: a random parameter is {{ distribution = "
            f"{' | '.join(repr(d) for d in DISTRIBUTIONS)}, ... }}"
        )
    kind = spec["distribution"]
    need = DISTRIBUTIONS[kind]
    if set(spec) != {"distribution", *need}:
        raise SweepError(f"{where}: {kind} needs exactly {', '.join(need)}, got {sorted(spec)}")
    for k in need:
        v = spec[k]
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise SweepError(f"{where}.{k} must be a finite number, got {v!r}")
    a, b = (float(spec[k]) for k in need)
    if kind == "normal" and b < 0:
        raise SweepError(f"{where}.std must be >= 0, got {b}")
    if kind != "normal" and not a < b:
        raise SweepError(f"{where}: low must be < high, got {a}, {b}")
    if kind == "loguniform" and a <= 0:
        raise SweepError(f"{where}: loguniform needs low > 0, got {a}")
    return {"distribution": kind, "a": a, "b": b}


def _samples(dists: dict[str, dict], count: int, seed: int, latin: bool) -> list[dict]:
    """``count`` seeded draws of every distribution; Latin hypercube strata when ``latin``
    (one draw in each of ``count`` equal-probability strata per parameter)."""
    from scipy import stats

    rng = np.random.default_rng(seed)
    columns = {}
    for key, d in dists.items():
        if latin:
            u = (rng.permutation(count) + rng.random(count)) / count
        else:
            u = rng.random(count)
        a, b = d["a"], d["b"]
        if d["distribution"] == "uniform":
            x = a + (b - a) * u
        elif d["distribution"] == "loguniform":
            x = np.exp(np.log(a) + (np.log(b) - np.log(a)) * u)
        else:
            x = stats.norm.ppf(u, loc=a, scale=b) if b > 0 else np.full(count, a)
        columns[key] = [float(v) for v in x]
    return [{k: columns[k][i] for k in dists} for i in range(count)]


# -- resolving ---------------------------------------------------------------------------
def _flatten(table: dict, leaf: Callable[[dict], bool] = lambda d: False, prefix: str = "") -> dict:
    """Nested TOML tables as dotted keys (``[set] simulation.duration = 2`` is the table
    ``{"simulation": {"duration": 2}}``); a table for which ``leaf`` holds stays a value."""
    out = {}
    for key, value in table.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict) and value and not leaf(value):
            out.update(_flatten(value, leaf, dotted + "."))
        else:
            out[dotted] = value
    return out


def _is_range(d: dict) -> bool:
    return bool({"low", "high", "count", "distribution", "mean", "std"} & set(d))


def _paths(key: str, data: dict, where: str) -> list[list[str]]:
    """The concrete paths a key names: ``bodies.*.x`` -> one per body."""
    parts = [p for p in key.split(".") if p]
    if not parts:
        raise SweepError(f"{where}: empty key")
    paths: list[list[str]] = [[]]
    for part in parts:
        if part != "*":
            paths = [[*p, part] for p in paths]
            continue
        grown = []
        for p in paths:
            node: Any = data
            for k in p:
                node = node[int(k)] if isinstance(node, list) else node.get(k, {})
            if not isinstance(node, list) or not node:
                raise SweepError(f"{where}: {'.'.join(p) or key} is not a list to match * in")
            grown += [[*p, str(i)] for i in range(len(node))]
        paths = grown
    return paths


def _apply(data: dict, key: str, value: Any, where: str) -> None:
    for path in _paths(key, data, where):
        try:
            loader.set_path(data, path, value, f"{key}={value}")
        except loader.SceneError as exc:
            raise SweepError(f"{where}: {exc}") from None


def _scene_data(scene: str, folder: Path | None) -> tuple[str, str, dict, Path | None]:
    """(scene argument as resolved, name, table, mesh folder) of a built-in name or file."""
    candidate = Path(scene)
    if folder is not None and not candidate.is_absolute() and (folder / candidate).exists():
        candidate = folder / candidate
        scene = str(candidate)
    try:
        name, text, base = loader.scene_text(scene)
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SweepError(f"{scene}: not valid TOML ({exc})") from None
    except loader.SceneError as exc:
        raise SweepError(str(exc)) from None
    if isinstance(data.get("name"), str) and data["name"]:
        name = data["name"]  # the scene's own name, as `softbody run` shows it
    return scene, name, data, base


def build_spec(
    scene: str,
    *,
    vary: dict[str, Any] | None = None,
    set: dict[str, Any] | None = None,
    random: dict | None = None,
    metrics: Sequence[str] | None = None,
    user_metrics: dict[str, Callable] | None = None,
    sample_rate: float = 100.0,
    description: str = "",
    folder: Path | None = None,
    label: str = "sweep",
) -> SweepSpec:
    """Resolve and validate a sweep: every run's scene is built as a table and checked
    against the scene schema. ``vary``: key -> list of values or range table (a grid);
    ``random``: ``{samples, seed, latin, vary: {key: distribution}}``. Raises
    :class:`SweepError` naming the key."""
    from softbody.sweep.metrics import BUILTIN_METRICS

    scene, name, base_data, base = _scene_data(scene, folder)
    fixed = _flatten(set or {})
    vary = _flatten(vary or {}, _is_range)
    for key, value in fixed.items():
        _apply(base_data, key, value, f"{label}: set.{key}")

    grid = {k: _values(v, f"{label}: vary.{k}") for k, v in (vary or {}).items()}
    points: list[dict] = [dict(zip(grid, combo, strict=True)) for combo in product(*grid.values())]
    varied = list(grid)
    if random:
        unknown = builtins.set(random) - RANDOM_KEYS
        if unknown:
            raise SweepError(f"{label}: unknown key random.{sorted(unknown)[0]}; "
                             f"valid keys: {', '.join(sorted(RANDOM_KEYS))}")  # fmt: skip
        count, seed = random.get("samples"), random.get("seed", 0)
        if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= MAX_RUNS:
            raise SweepError(f"{label}: random.samples must be a whole number in [1, {MAX_RUNS:,}]")
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise SweepError(f"{label}: random.seed must be a whole number >= 0, got {seed!r}")
        dists = {k: _distribution(v, f"{label}: random.vary.{k}")
                 for k, v in _flatten(random.get("vary") or {}, _is_range).items()}  # fmt: skip
        if not dists:
            raise SweepError(f"{label}: [random] needs a [random.vary] table")
        clash = builtins.set(dists) & builtins.set(grid)
        if clash:
            raise SweepError(f"{label}: {sorted(clash)[0]} is in both vary and random.vary")
        draws = _samples(dists, count, seed, bool(random.get("latin", False)))
        points = [{**p, **d} for p in points for d in draws]
        varied += list(dists)
    if len(points) > MAX_RUNS:
        raise SweepError(f"{label}: {len(points):,} runs, over the limit of {MAX_RUNS:,}")

    known = builtins.set(BUILTIN_METRICS)
    for m in metrics or ():
        if m not in known:
            raise SweepError(f"{label}: unknown metric {m!r}; built-in metrics: "
                             f"{', '.join(sorted(known))}")  # fmt: skip
    if not (isinstance(sample_rate, int | float) and 0 < sample_rate < math.inf):
        raise SweepError(f"{label}: sample_rate must be a number > 0 per second")

    runs: list[Run] = []
    seen: builtins.set[str] = builtins.set()
    for i, point in enumerate(points):
        data = copy.deepcopy(base_data)
        for key, value in point.items():
            _apply(data, key, value, f"{label}: vary.{key}")
        try:
            loader.validate(data)
        except (loader.SceneError, ValueError) as exc:
            shown = ", ".join(f"{k}={v}" for k, v in point.items())
            raise SweepError(f"{label}: run {i} ({shown}): {exc}") from None
        rid = run_id(data)
        if rid not in seen:  # the same scene twice is one run
            seen.add(rid)
            runs.append(Run(rid, point, data))
    return SweepSpec(
        scene=scene,
        scene_name=name,
        base=base,
        varied=varied,
        runs=runs,
        metrics=list(metrics) if metrics else None,
        user_metrics=dict(user_metrics or {}),
        sample_rate=float(sample_rate),
        description=description,
    )


def load_sweep_file(path: str | Path, *, extra_set: dict | None = None) -> SweepSpec:
    """Read and validate a sweep file (module docstring); ``extra_set`` overrides its
    ``set`` table (the command line's ``--set``)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise SweepError(f"{p}: cannot read the sweep file ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise SweepError(f"{p}: not a sweep file (TOML is UTF-8 text)") from None
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SweepError(f"{p}: not valid TOML ({exc})") from None
    unknown = set(table) - SWEEP_KEYS
    if unknown:
        raise SweepError(f"{p}: unknown key {sorted(unknown)[0]!r}; valid keys: "
                         f"{', '.join(sorted(SWEEP_KEYS))}")  # fmt: skip
    if not isinstance(table.get("scene"), str):
        raise SweepError(f"{p}: scene must name a built-in scene or a scene file")
    for key in ("set", "vary", "random"):
        if key in table and not isinstance(table[key], dict):
            raise SweepError(f"{p}: {key} must be a table")
    metrics = table.get("metrics")
    user: dict[str, Callable] = {}
    builtin: list[str] = []
    if metrics is not None:
        if not isinstance(metrics, list) or not all(isinstance(m, str) for m in metrics):
            raise SweepError(f"{p}: metrics must be a list of names")
        for m in metrics:
            if ":" in m:  # "module:function", a user metric
                user[m.split(":", 1)[1]] = import_metric(m, p)
            else:
                builtin.append(m)
    return build_spec(
        table["scene"],
        vary=table.get("vary"),
        set={**table.get("set", {}), **(extra_set or {})},
        random=table.get("random"),
        metrics=builtin or None,
        user_metrics=user,
        sample_rate=table.get("sample_rate", 100.0),
        description=table.get("description", ""),
        folder=p.parent,
        label=str(p),
    )


def import_metric(text: str, where: Path | str = "sweep") -> Callable:
    """``"module:function"`` -> the function (a user metric of a run's history)."""
    import importlib

    module, _, name = text.partition(":")
    try:
        fn = getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as exc:
        raise SweepError(f"{where}: cannot import metric {text!r} ({exc})") from None
    if not callable(fn):
        raise SweepError(f"{where}: metric {text!r} is not a function")
    return fn


def is_sweep_file(path: str | Path) -> bool:
    """Whether ``path`` is a sweep file (a top-level ``scene`` string and no bodies)."""
    p = Path(path)
    if p.suffix != ".toml" or not p.is_file():
        return False
    try:
        table = tomllib.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False
    return isinstance(table.get("scene"), str) and "bodies" not in table
