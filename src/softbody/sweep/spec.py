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

Before anything runs the sweep is sized and checked, in time that does not grow with its
run count: the number of runs is computed from the value counts (a grid of 10^9 is
refused before any list is built), the base scene (with the fixed overrides) is checked
against the scene schema once, and each varied key once per distinct value (or, past
:data:`MAX_CHECKED_VALUES` distinct numbers, at its smallest and largest: the schema's
bounds are intervals), and the first and last run whole; a typo or a bad value is one
line naming the key (:class:`SweepError`). A combination that is invalid only together is
an ``error`` row of the table, as its worker builds the scene.
"""

from __future__ import annotations

import builtins
import copy
import hashlib
import json
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from itertools import product
from pathlib import Path
from typing import Any

import numpy as np

from softbody import limits
from softbody.errors import SizeLimitError
from softbody.scenes import loader

#: Most runs one sweep may hold: more is almost always a count off by orders of magnitude.
MAX_RUNS = 1_000_000
#: A varied key's distinct values each checked against the schema up to this many; past
#: it, its smallest and largest numbers and each value that is not a number.
MAX_CHECKED_VALUES = 64
SWEEP_KEYS = {"scene", "set", "vary", "random", "metrics", "sample_rate", "description", "name"}
RANDOM_KEYS = {"samples", "seed", "latin", "vary"}
DISTRIBUTIONS = {"uniform": ("low", "high"), "loguniform": ("low", "high"),
                 "normal": ("mean", "std")}  # fmt: skip


class SweepError(ValueError):
    """A sweep description is wrong; the message is one line saying where and why."""


@dataclass(slots=True)
class Run:
    """One run of a sweep: its id, its varied values and the sweep's base scene table."""

    run_id: str
    """Hash of the base scene table (with the fixed overrides) and the run's varied values
    (16 hex digits): the same run has the same id."""
    params: dict[str, Any]
    """Varied key -> value, as the sweep names them (``bodies.*.stiffness``)."""
    base: dict = field(repr=False, compare=False)
    """The base scene table with the fixed overrides, shared by every run of the sweep
    (never modified)."""

    @property
    def data(self) -> dict:
        """The scene table with every override applied (a new copy, made when asked for:
        a sweep of 10^6 runs holds one scene table, not 10^6)."""
        return _resolved(self.base, self.params, "sweep")


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
    fixed: dict[str, Any] = field(default_factory=dict)
    """The fixed overrides (``set``, ``--set``): dotted key -> value."""
    scene_hash: str = ""
    """:func:`run_id` of the base scene's table before the overrides: its contents."""

    def fingerprint(self) -> dict:
        """What makes two sweeps the same sweep (stored in the output folder): the scene
        and its contents, every fixed override, the varied keys, the sampling and the
        metrics. Runs of sweeps that differ in any of these never share a table."""
        return json.loads(json.dumps({
            "scene": self.scene_name,
            "scene_hash": self.scene_hash,
            "set": dict(sorted(self.fixed.items())),
            "varied": self.varied,
            "sample_rate": self.sample_rate,
            "metrics": self.metrics,
            "user_metrics": sorted(self.user_metrics),
        }, default=str))  # fmt: skip


def run_id(data: dict) -> str:
    """SHA-256 of ``data`` as canonical JSON, 16 hex digits: a run's id from its base scene's
    and its values (:func:`build_spec`)."""
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
        data = loader.parse_toml(text, scene)
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
    scene_hash = run_id(base_data)
    fixed = _flatten(set or {})
    vary = _flatten(vary or {}, _is_range)
    for key, value in fixed.items():
        _apply(base_data, key, value, f"{label}: set.{key}")

    # sizes first: the run count from the value counts, before any list of runs is built
    grid: dict[str, list] = {}
    count = 1
    for k, v in vary.items():
        grid[k] = _values(v, f"{label}: vary.{k}")
        count *= len(grid[k])
        if count > MAX_RUNS:
            raise SweepError(
                f"{label}: the grid would have at least {count:,} runs ("
                f"{' x '.join(f'{len(g):,}' for g in grid.values())} values), over the limit "
                f"of {MAX_RUNS:,}"
            )
    varied = list(grid)
    draws: list[dict] = [{}]
    if random:
        unknown = builtins.set(random) - RANDOM_KEYS
        if unknown:
            raise SweepError(f"{label}: unknown key random.{sorted(unknown)[0]}; "
                             f"valid keys: {', '.join(sorted(RANDOM_KEYS))}")  # fmt: skip
        samples, seed = random.get("samples"), random.get("seed", 0)
        if (isinstance(samples, bool) or not isinstance(samples, int)
                or not 1 <= samples <= MAX_RUNS):  # fmt: skip
            raise SweepError(f"{label}: random.samples must be a whole number in [1, {MAX_RUNS:,}]")
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise SweepError(f"{label}: random.seed must be a whole number >= 0, got {seed!r}")
        if count * samples > MAX_RUNS:
            raise SweepError(f"{label}: {count:,} grid points x {samples:,} samples = "
                             f"{count * samples:,} runs, over the limit of "
                             f"{MAX_RUNS:,}")  # fmt: skip
        dists = {k: _distribution(v, f"{label}: random.vary.{k}")
                 for k, v in _flatten(random.get("vary") or {}, _is_range).items()}  # fmt: skip
        if not dists:
            raise SweepError(f"{label}: [random] needs a [random.vary] table")
        clash = builtins.set(dists) & builtins.set(grid)
        if clash:
            raise SweepError(f"{label}: {sorted(clash)[0]} is in both vary and random.vary")
        draws = _samples(dists, samples, seed, bool(random.get("latin", False)))
        varied += list(dists)

    known = builtins.set(BUILTIN_METRICS)
    for m in metrics or ():
        if m not in known:
            raise SweepError(f"{label}: unknown metric {m!r}; built-in metrics: "
                             f"{', '.join(sorted(known))}")  # fmt: skip
    if not (isinstance(sample_rate, int | float) and 0 < sample_rate < math.inf):
        raise SweepError(f"{label}: sample_rate must be a number > 0 per second")

    # validity once, not per run: the first run, then each key's values in it, then the
    # last run
    first = {**{k: v[0] for k, v in grid.items()}, **draws[0]}
    _check(base_data, first, label, f"{label}: run 0 ({_shown(first)})")
    for key, values in grid.items():
        for value in _to_check(values):
            _check(base_data, {**first, key: value}, label, f"{label}: vary.{key}={value}")
    for key in varied[len(grid) :]:  # drawn numbers: the smallest and the largest
        for value in (min(d[key] for d in draws), max(d[key] for d in draws)):
            where = f"{label}: random.vary.{key} drew {value:.6g}"
            _check(base_data, {**first, key: value}, label, where)
    points = (
        {**dict(zip(grid, combo, strict=True)), **d}
        for combo in product(*grid.values())
        for d in draws
    )
    base_id = run_id(base_data)
    runs: list[Run] = []
    seen: builtins.set[str] = builtins.set()
    for point in points:
        rid = run_id({"scene": base_id, "params": point})
        if rid not in seen:  # the same values twice are one run
            seen.add(rid)
            runs.append(Run(rid, point, base_data))
    last = runs[-1].params
    _check(base_data, last, label, f"{label}: run {len(runs) - 1} ({_shown(last)})")
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
        fixed=fixed,
        scene_hash=scene_hash,
    )


def _resolved(base_data: dict, point: dict[str, Any], label: str) -> dict:
    """The base scene table with the point's values applied (a copy)."""
    data = copy.deepcopy(base_data)
    for key, value in point.items():
        _apply(data, key, value, f"{label}: vary.{key}")
    return data


def _shown(point: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v}" for k, v in point.items())


def _check(base_data: dict, point: dict[str, Any], label: str, where: str) -> None:
    """Validate the base scene with ``point`` applied; :class:`SweepError` naming ``where``
    (or the key, for a key that names nothing)."""
    data = _resolved(base_data, point, label)
    try:
        loader.validate(data)
    except (loader.SceneError, ValueError) as exc:
        raise SweepError(f"{where}: {exc}") from None


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _to_check(values: list) -> list:
    """The values of one key to check against the schema: each distinct one, or past
    :data:`MAX_CHECKED_VALUES`, the smallest and largest number and every other value
    (the schema's numeric bounds are intervals)."""

    def distinct(items: list) -> list:
        return list({json.dumps(v, sort_keys=True, default=str): v for v in items}.values())

    if len(values) <= MAX_CHECKED_VALUES:
        return distinct(values)
    numbers = [v for v in values if _is_number(v)]
    others = distinct([v for v in values if not _is_number(v)])
    return ([min(numbers), max(numbers)] if numbers else []) + others


def load_sweep_file(path: str | Path, *, extra_set: dict | None = None) -> SweepSpec:
    """Read and validate a sweep file (module docstring); ``extra_set`` overrides its
    ``set`` table (the command line's ``--set``)."""
    p = Path(path)
    try:
        text = _read_text(p)
    except OSError as exc:
        raise SweepError(f"{p}: cannot read the sweep file ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise SweepError(f"{p}: not a sweep file (TOML is UTF-8 text)") from None
    try:
        table = loader.parse_toml(text, str(p))
    except loader.SceneError as exc:
        raise SweepError(str(exc)) from None
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


def _read_text(p: Path) -> str:
    """A sweep file's text, refused by size (``SizeLimitError``) before it is read, as a
    scene file is (:data:`softbody.limits.MAX_SCENE_FILE_BYTES`)."""
    with p.open("rb") as f:
        size = os.fstat(f.fileno()).st_size
        limits.check_file_size(str(p), size, factor=4, maximum=limits.MAX_SCENE_FILE_BYTES)
        raw = f.read(limits.MAX_SCENE_FILE_BYTES + 1)  # st_size is 0 for a pipe
    limits.check_file_size(str(p), len(raw), factor=4, maximum=limits.MAX_SCENE_FILE_BYTES)
    return raw.decode("utf-8")


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
        table = loader.parse_toml(_read_text(p), str(p))
    except (OSError, UnicodeDecodeError, loader.SceneError, SizeLimitError):
        return False  # a scene file then, or none: its reader says why
    return isinstance(table.get("scene"), str) and "bodies" not in table
