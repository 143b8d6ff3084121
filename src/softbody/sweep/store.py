"""A sweep's output folder: one Parquet table, a partitioned Parquet dataset of series.

    OUT/sweep.json          what sweep this folder holds (scene, varied keys, metrics)
    OUT/runs.parquet        a row per finished run (run_id, varied values, status, metrics)
    OUT/series/part-NNNNN.parquet   time series of many runs each, one row per sample
    OUT/summary.png         the summary figure

Results are written as they arrive, in batches: a batch's series part first, then the
whole table, each to a temporary file in the same folder renamed over the old one (with
SIGINT/SIGTERM held for those milliseconds), so that the table on disk is always whole
and lists only runs whose series are on disk. The folder is locked while a sweep writes
to it; nothing but these files is ever written.

Nothing is written or removed through a link: each of these names must be absent or a
regular file (``series`` a real folder), or the sweep stops with one line. The only file
a sweep ever removes is a series part that no table row names (a crash between the two
renames), when the sweep is resumed, and only when it is a regular file in that real
folder whose ``run_id`` column holds run ids of this sweep alone: what this sweep wrote.

A folder holds one sweep: its identity (:meth:`SweepSpec.fingerprint`: the scene and its
contents, every fixed override, the varied keys, the sampling, the metrics) is kept in
``sweep.json``, and a sweep that differs in any of them is refused with one line saying
what differs, rather than mixing its rows into the table.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import stat
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from softbody.io.outputs import OutputError, folder_lock, prepare, signals_held
from softbody.sweep.spec import SweepError, SweepSpec

TABLE = "runs.parquet"
SERIES = "series"
MANIFEST = "sweep.json"
FIGURE = "summary.png"
_UMASK = os.umask(0)
os.umask(_UMASK)
PART = re.compile(r"part-(\d{5,})\.parquet")


def series_columns(series: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """A run's history arrays as flat columns (one row per sample): ``t``, ``energy``,
    ``body{b}.volume`` / ``.pressure`` / ``.kinetic`` / ``.com_x|y|z`` / ``.extent_x|y|z``
    (and ``.gas_moles`` / ``.gas_temperature`` where the body has a gas state,
    ``.mass_inflow`` / ``.mass_outflow`` where the model has flows),
    ``collider{c}.impulse_x|y|z``."""
    cols = {"t": series["t"], "energy": series["energy"]}
    for b in range(series["volume"].shape[1]):
        cols[f"body{b}.volume"] = series["volume"][:, b]
        cols[f"body{b}.pressure"] = series["pressure"][:, b]
        cols[f"body{b}.kinetic"] = series["kinetic"][:, b]
        for k, axis in enumerate("xyz"):
            cols[f"body{b}.com_{axis}"] = series["center_of_mass"][:, b, k]
        for k, axis in enumerate("xyz"):
            cols[f"body{b}.extent_{axis}"] = series["extent"][:, b, k]
        for key in ("gas_moles", "gas_temperature", "mass_inflow", "mass_outflow"):
            if key in series and not np.all(np.isnan(series[key][:, b])):
                cols[f"body{b}.{key}"] = series[key][:, b]
    for c in range(series["collider_impulse"].shape[1]):
        for k, axis in enumerate("xyz"):
            cols[f"collider{c}.impulse_{axis}"] = series["collider_impulse"][:, c, k]
    return cols


def _atomic(path: Path, write) -> None:
    """``write(tmp_path)`` then rename onto ``path``, signals held for the rename."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        os.chmod(tmp, 0o666 & ~_UMASK)  # as an ordinary new file, not mkstemp's 0600
        write(tmp)
        with signals_held():
            os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)


class SweepStore:
    """The output folder of one sweep, open for writing (use as a context manager)."""

    def __init__(self, out: str | Path, spec: SweepSpec):
        self.out = Path(out)
        self.spec = spec
        self.rows: list[dict[str, Any]] = []
        self._pending_rows: list[dict] = []
        self._pending_series: list[tuple[str, dict]] = []
        self._lock = None

    # -- opening -------------------------------------------------------------------------
    def __enter__(self) -> SweepStore:
        try:
            prepare(self.out)
        except OSError as exc:
            raise OutputError(f"{self.out}: cannot create the folder ({exc.strerror})") from None
        self._lock = folder_lock(self.out)
        self._lock.__enter__()
        try:
            self._open()
        except BaseException:
            self._lock.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc) -> None:
        try:
            self.flush()
        finally:
            self._lock.__exit__(*exc)

    def _open(self) -> None:
        import pyarrow.parquet as pq

        self._refuse_links()
        manifest = self.out / MANIFEST
        fingerprint = self.spec.fingerprint()
        if manifest.exists():
            try:
                held = json.loads(manifest.read_text())["sweep"]
            except (OSError, ValueError, KeyError, TypeError):
                raise OutputError(f"{manifest}: not a softbody sweep manifest") from None
            if held != fingerprint:
                raise SweepError(
                    f"{self.out} holds {_difference(held, fingerprint)}; choose another --out "
                    "(rows of the two would mix in one table)"
                )
        else:
            ours = [n for n in (TABLE, SERIES, FIGURE) if os.path.lexists(self.out / n)]
            if ours:
                raise OutputError(
                    f"{self.out / ours[0]} exists and was not written by a sweep here; "
                    "choose another --out"
                )
            text = json.dumps({"softbody_sweep": 2, "sweep": fingerprint}, indent=2)
            _atomic(manifest, lambda tmp: Path(tmp).write_text(text))
        with contextlib.suppress(FileExistsError):
            (self.out / SERIES).mkdir()
        self._refuse_links()  # a link put in place of series/ since the first look
        if (self.out / TABLE).exists():
            self.rows = pq.read_table(self.out / TABLE).to_pylist()
        named = {r.get("series_file") for r in self.rows}
        ids = {run.run_id for run in self.spec.runs}
        self._next_part = 0
        for entry in os.listdir(self.out / SERIES):
            m = PART.fullmatch(entry)
            if not m:
                continue
            self._next_part = max(self._next_part, int(m.group(1)) + 1)
            path = self.out / SERIES / entry
            if f"{SERIES}/{entry}" not in named and _written_by(path, ids):
                os.unlink(path)  # ours, but no row lists it: a crash between two renames

    def _refuse_links(self) -> None:
        """:class:`OutputError` when one of the sweep's names in the folder is a link or
        not what the sweep writes there (``series`` a real folder, the rest files)."""
        for name in (MANIFEST, TABLE, SERIES, FIGURE):
            try:
                mode = os.lstat(self.out / name).st_mode
            except FileNotFoundError:
                continue
            kind = stat.S_ISDIR if name == SERIES else stat.S_ISREG
            if not kind(mode):
                what = "a folder" if name == SERIES else "a file"
                raise OutputError(
                    f"{self.out / name} is not {what} (a link?); a sweep writes nothing "
                    "through a link: move it away or choose another --out"
                )

    # -- writing -------------------------------------------------------------------------
    @property
    def finished(self) -> set[str]:
        """Run ids in the table with a result (``ok`` or ``blew up``): a rerun skips these
        and runs the errors again (a lost worker, a metric since fixed)."""
        return {r["run_id"] for r in self.rows if r.get("status") != "error"}

    def add(self, row: dict, series: dict[str, np.ndarray] | None) -> None:
        """Queue one run's row and series (written at the next :meth:`flush`)."""
        self._pending_rows.append(row)
        # an error row keeps no series, so that its rerun replaces the row and nothing else
        if series is not None and row.get("status") != "error":
            self._pending_series.append((row["run_id"], series))

    @property
    def pending(self) -> int:
        return len(self._pending_rows)

    def flush(self) -> None:
        """Write the queued runs: their series part, then the whole table."""
        if not self._pending_rows:
            return
        import pyarrow as pa
        import pyarrow.parquet as pq

        rows = self._pending_rows
        if self._pending_series:
            name = f"{SERIES}/part-{self._next_part:05d}.parquet"
            self._next_part += 1
            tables = []
            for rid, series in self._pending_series:
                cols = series_columns(series)
                n = len(cols["t"])
                tables.append(pa.table({"run_id": pa.array([rid] * n), **cols}))
            part = pa.concat_tables(tables, promote_options="default")
            _atomic(self.out / name, lambda tmp: pq.write_table(part, tmp))
            with_series = {rid for rid, _ in self._pending_series}
            for r in rows:
                r["series_file"] = name if r["run_id"] in with_series else None
        order = {run.run_id: i for i, run in enumerate(self.spec.runs)}
        new = {r["run_id"] for r in rows}
        kept = [r for r in self.rows if r["run_id"] not in new]  # errors that were rerun
        every = sorted(kept + rows, key=lambda r: order.get(r["run_id"], len(order)))
        table = _table(every)
        _atomic(self.out / TABLE, lambda tmp: pq.write_table(table, tmp))
        self.rows = every
        self._pending_rows, self._pending_series = [], []


def _written_by(path: Path, ids: set[str]) -> bool:
    """Whether ``path`` is a regular file (not a link) holding a Parquet table whose
    ``run_id`` column names runs of ``ids`` only: a series part this sweep wrote."""
    import pyarrow.parquet as pq

    try:
        if not stat.S_ISREG(os.lstat(path).st_mode):
            return False
        found = set(pq.read_table(path, columns=["run_id"]).column("run_id").to_pylist())
    except Exception:  # not Parquet, no run_id column, unreadable: not ours
        return False
    return bool(found) and found <= ids


def _difference(held: dict, wanted: dict) -> str:
    """What the sweep in a folder (``held``) is, said by how it differs from ``wanted``."""
    if not isinstance(held, dict):
        return "something else"
    if held.get("scene") != wanted["scene"]:
        return f"a sweep of another scene ({held.get('scene')})"
    if "set" not in held:
        return "a sweep by an older softbody, with no record of its fixed overrides"
    if held.get("scene_hash") != wanted["scene_hash"]:
        return f"a sweep of another version of {wanted['scene']} (the scene has changed since)"
    if held["set"] != wanted["set"]:
        keys = sorted(set(held["set"]) | set(wanted["set"]))
        diff = [k for k in keys if held["set"].get(k, None) != wanted["set"].get(k, None)]

        def shown(table: dict) -> str:
            return ", ".join(f"{k}={table[k]}" if k in table else f"{k} unset" for k in diff)

        return (
            f"a sweep with other fixed overrides ({shown(held['set'])}; this one: "
            f"{shown(wanted['set'])})"
        )
    if held.get("varied") != wanted["varied"]:
        return f"a different sweep (varying {', '.join(held.get('varied') or []) or 'nothing'})"
    return "a different sweep (other sample rate or metrics)"


def _table(rows: list[dict]):
    """Rows as a pyarrow table: every key a column (missing values null)."""
    import pyarrow as pa

    keys: dict[str, None] = {}
    for r in rows:
        keys.update(dict.fromkeys(r))
    columns = {}
    for k in keys:
        values = [r.get(k) for r in rows]
        try:
            columns[k] = pa.array(values)
        except (pa.ArrowInvalid, pa.ArrowTypeError):  # mixed kinds: keep them as text
            columns[k] = pa.array([None if v is None else str(v) for v in values])
    return pa.table(columns)
