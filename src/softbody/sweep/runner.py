"""Running a sweep: one run in a worker (:func:`run_one`), every run on Dask (:func:`run_sweep`).

Runs are Dask tasks on a ``LocalCluster`` of worker processes (one thread each) by
default, or on any cluster by its scheduler's address. Each task builds its scene, steps
it headless (nothing is rendered) and returns its table row and its history; the client
writes them as they arrive (:mod:`softbody.sweep.store`). A run that blows up or raises is
a row saying so; a worker that dies mid-run has its run rescheduled by Dask on another
worker (up to ``distributed.scheduler.allowed-failures`` times, then the row is an error).
"""

from __future__ import annotations

import copy
import os
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from softbody.sweep.spec import Run, SweepSpec

#: Seconds between writes of the table while results arrive (and at the end).
FLUSH_SECONDS = 2.0
#: Seconds a scheduler given by address has to accept the connection and greet (a Dask
#: scheduler greets at once), and then to answer an HTTP request when it stayed silent.
HANDSHAKE_SECONDS = 5.0
#: Seconds :class:`dask.distributed.Client` then has to register with the scheduler.
CONNECT_SECONDS = 10.0


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity; all of them elsewhere)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def _one_line(exc: BaseException) -> str:
    text = str(exc) or type(exc).__name__
    return "; ".join(line.strip() for line in text.splitlines() if line.strip())[:500]


def run_one(
    run: Run,
    scene_name: str,
    base: str | None,
    sample_rate: float,
    metrics: list[str] | None = None,
    user_metrics: dict | None = None,
) -> tuple[dict[str, Any], dict[str, np.ndarray] | None]:
    """Simulate one run headless; (table row, history arrays or None).

    The row holds ``run_id``, the varied values, ``status`` (``"ok"``, ``"blew up"`` or
    ``"error"``), ``message`` (one line: the blow-up or the exception), ``warning`` (the
    first warning, e.g. a time step above the stability estimate), the metrics, and
    ``steps``, ``build_time``, ``sim_time``, ``wall_time`` [s] and ``worker`` (host:pid).
    History is sampled every ``1 / sample_rate`` seconds of simulated time.
    """
    from softbody.diagnostics import (
        body_center_of_mass,
        body_gas_flows,
        body_pressure,
        body_volume,
        energies,
        gas_state_bodies,
        has_gas_flows,
    )
    from softbody.errors import SimulationError
    from softbody.scenes.loader import build_scene
    from softbody.scenes.plan import plan_frames
    from softbody.sim.simulator import Simulator
    from softbody.sweep.metrics import History, compute_metrics

    t_start = time.perf_counter()
    row: dict[str, Any] = {"run_id": run.run_id, **run.params, "status": "ok", "message": None,
                           "warning": None}  # fmt: skip
    series = None
    build_s = sim_s = 0.0
    steps = 0
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            folder = None if base is None else Path(base)
            scene = build_scene(scene_name, copy.deepcopy(run.data), folder)
            model = scene.model
            sim = Simulator(model, integrator=scene.integrator, dt=scene.dt,
                            implicit_tolerance=scene.implicit_tolerance)  # fmt: skip
            auto = scene.dt == "auto"
            plan = plan_frames(scene.duration, sample_rate, sim.dt, auto=auto)
            build_s = time.perf_counter() - t_start
            state = model.state()
            t, vol, pres, com, kin, energy, impulse = [], [], [], [], [], [], []
            extent = []
            gas = gas_state_bodies(model)
            flows = has_gas_flows(model)
            moles, temperature, inflow, outflow = [], [], [], []
            collider_count = model.collider_count
            owner = np.asarray(model.particle_body)
            members = [np.flatnonzero(owner == b) for b in range(model.body_count)]

            def sample() -> None:
                t.append(state.time)
                vol.append(body_volume(model, state))
                pres.append(body_pressure(model, state))
                com.append(body_center_of_mass(model, state))
                q = state.particle_q
                extent.append([np.ptp(q[m], axis=0) for m in members])
                e = energies(model, state)
                kin.append(e.body_kinetic)
                energy.append(e.total)
                imp = state.collider_impulse
                impulse.append(np.zeros((collider_count, 3)) if imp is None else imp.copy())
                if gas.any():
                    moles.append(np.where(gas, state.body_gas_moles, np.nan))
                    temperature.append(np.where(gas, state.body_gas_temperature, np.nan))
                if flows:
                    f = body_gas_flows(model, state)
                    inflow.append(np.where(gas, f.mass_inflow, np.nan))
                    outflow.append(np.where(gas, f.mass_outflow, np.nan))

            sample()
            blowup = None
            t0 = time.perf_counter()
            try:
                for _ in range(plan.frame_count):
                    if auto:
                        sim.advance(state, plan.frame_dt, progress=False)
                    else:
                        sim.run(state, plan.steps_per_frame, progress=False)
                    sample()
            except SimulationError as exc:
                blowup = exc.time
                row["status"], row["message"] = "blew up", _one_line(exc)
            sim_s = time.perf_counter() - t0
            steps = int(state.step_count)
        if caught:
            row["warning"] = _one_line(caught[0].message)
        series = {
            "t": np.asarray(t, dtype=float),
            "volume": np.asarray(vol, dtype=float).reshape(len(t), -1),
            "pressure": np.asarray(pres, dtype=float).reshape(len(t), -1),
            "center_of_mass": np.asarray(com, dtype=float).reshape(len(t), -1, 3),
            "extent": np.asarray(extent, dtype=float).reshape(len(t), -1, 3),
            "kinetic": np.asarray(kin, dtype=float).reshape(len(t), -1),
            "energy": np.asarray(energy, dtype=float),
            "collider_impulse": np.asarray(impulse, dtype=float).reshape(len(t), -1, 3),
        }
        for key, values in (("gas_moles", moles), ("gas_temperature", temperature),
                            ("mass_inflow", inflow), ("mass_outflow", outflow)):  # fmt: skip
            if values:
                series[key] = np.asarray(values, dtype=float).reshape(len(t), -1)
        history = History(
            rest_volume=np.asarray(model.body_rest_volume, dtype=float),
            body_names=list(scene.body_names),
            blowup_time=blowup,
            params=dict(run.params),
            **series,
        )
        try:
            row.update(compute_metrics(history, metrics, user_metrics))
        except Exception as exc:  # a user metric's bug: the run's row says which
            row["status"] = "error"
            row["message"] = f"metric: {type(exc).__name__}: {_one_line(exc)}"
    except Exception as exc:
        row["status"], row["message"] = "error", f"{type(exc).__name__}: {_one_line(exc)}"
    row.update(
        steps=steps,
        build_time=build_s,
        sim_time=sim_s,
        wall_time=time.perf_counter() - t_start,
        worker=f"{os.uname().nodename}:{os.getpid()}",
    )
    return row, series


@dataclass
class SweepResult:
    """What a sweep did and where its files are."""

    out: Path
    table: Path
    series: Path
    figure: Path | None
    total: int
    """Runs in the sweep."""
    skipped: int
    """Runs already in the table (a resumed sweep)."""
    executed: int
    """Runs done by this call."""
    ok: int
    blew_up: int
    errors: int
    wall_time: float
    """Seconds this call took, cluster start and figure included."""
    cluster_start: float = 0.0
    """Seconds from asking for the cluster to a client with workers (0 without Dask)."""
    run_span: float = 0.0
    """Seconds from the first run's start (its submission) to the last result's arrival."""

    def read(self):
        """The table as a ``pyarrow.Table`` (``.to_pandas()`` for a DataFrame)."""
        import pyarrow.parquet as pq

        return pq.read_table(self.table)


class _Progress:
    """``done/total``, failures, runs left and an estimate of the time left."""

    def __init__(self, total: int, skipped: int, stream):
        self.total, self.skipped, self.stream = total, skipped, stream
        self.tty = stream is not None and hasattr(stream, "isatty") and stream.isatty()
        self.start = time.perf_counter()
        self.done = self.failed = 0
        self._last = 0.0

    def update(self, failed: bool, force: bool = False) -> None:
        self.done += 1
        self.failed += failed
        self.show(force)

    def show(self, force: bool = False) -> None:
        if self.stream is None:
            return
        now = time.perf_counter()
        left = self.total - self.skipped - self.done
        if not (force or left == 0 or self.tty or now - self._last >= 5.0):
            return
        self._last = now
        elapsed = now - self.start
        eta = elapsed / self.done * left if self.done else float("nan")
        eta_text = "?" if not np.isfinite(eta) else time.strftime("%H:%M:%S", time.gmtime(eta))
        text = (f"{self.skipped + self.done}/{self.total} done ({self.failed} failed), "
                f"{left} left, elapsed {time.strftime('%H:%M:%S', time.gmtime(elapsed))}, "
                f"ETA {eta_text}")  # fmt: skip
        if self.tty:
            end = "\n" if left == 0 else ""
            self.stream.write(f"\r\x1b[2Ksweep: {text}{end}")
        else:
            self.stream.write(f"sweep: {text}\n")
        self.stream.flush()


def _say(stream, text: str) -> None:
    if stream is not None:
        print(text, file=stream, flush=True)


def run_sweep(
    spec: SweepSpec,
    out: str | Path,
    *,
    workers: int | None = None,
    address: str | None = None,
    figure: bool = True,
    progress=sys.stderr,
) -> SweepResult:
    """Run every run of ``spec`` not yet in ``out``'s table and write the results.

    ``workers``: worker processes of the local cluster (default: one per available core,
    and at most that many: a run is one process on one core; 0 runs everything in this
    process, without Dask); ``address``: a running Dask scheduler (``tcp://host:8786``)
    to use instead, which must greet within :data:`HANDSHAKE_SECONDS`. ``progress``: a
    text stream for progress lines (None: quiet).
    """
    t_start = time.perf_counter()
    out = Path(out)
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int) or workers < 0
    ):
        raise ValueError(f"workers must be a whole number >= 0, got {workers!r}")
    cores = available_cores()
    if workers is not None and workers > cores:
        raise ValueError(
            f"--workers {workers:,}: this machine has {cores} core{'s' if cores != 1 else ''} "
            f"available, so at most {cores} workers (each run is one process on one core; "
            "more only compete for them and take memory)"
        )
    # a cluster given by address is reached first: an unreachable one writes nothing
    remote = _connect(address) if address is not None else None
    try:
        return _sweep_into(spec, out, workers, remote, figure, progress, t_start)
    finally:
        if remote is not None:
            remote.close()


def _connect(address: str):
    """A Dask client of the scheduler at ``address``; ValueError (one line) when it cannot
    be reached or what answers there is not a Dask scheduler (:func:`_probe`)."""
    from dask.distributed import Client

    _probe(address)
    try:
        return Client(address, timeout=CONNECT_SECONDS)
    except (OSError, TimeoutError) as exc:
        raise ValueError(f"cannot reach the Dask scheduler at {address} ({exc})") from None


def _probe(address: str, timeout: float = HANDSHAKE_SECONDS) -> None:
    """Check that a Dask scheduler answers at a ``tcp://`` ``address``, in bounded time:
    it greets a new connection at once with its handshake (a msgpack message naming its
    ``compression`` and ``pickle-protocol``). :class:`ValueError` naming what answered
    instead: nothing (refused, or no greeting within ``timeout`` seconds), an HTTP
    server (asked ``HEAD /`` after the silence), or other bytes. ``Client`` itself would
    wait for ever on a listener that never answers. Other schemes (``tls://``) are left
    to ``Client``."""
    import socket

    from distributed.comm import parse_address, parse_host_port

    try:
        scheme, location = parse_address(address)
        host, port = parse_host_port(location)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"--address {address!r} is not a scheduler address ({exc})") from None
    if scheme != "tcp":
        return
    where = f"the Dask scheduler at {address}"
    deadline = time.monotonic() + timeout
    try:
        conn = socket.create_connection((host, port), timeout=timeout)
    except OSError as exc:
        reason = "timed out" if isinstance(exc, TimeoutError) else exc.strerror or exc
        raise ValueError(f"cannot reach {where} ({reason})") from None
    with conn:
        data = b""
        try:
            while len(data) < 4096 and time.monotonic() < deadline:
                conn.settimeout(max(0.01, deadline - time.monotonic()))
                chunk = conn.recv(4096)
                if not chunk:
                    break
                data += chunk
                if b"pickle-protocol" in data and b"compression" in data:
                    return  # a Dask comm's greeting
        except TimeoutError:
            pass
        except OSError as exc:
            raise ValueError(f"cannot reach {where} ({exc.strerror or exc})") from None
        if not data:
            try:  # silent: an HTTP server waits for a request
                conn.settimeout(2.0)
                conn.sendall(b"HEAD / HTTP/1.0\r\n\r\n")
                data = conn.recv(4096)
            except OSError:
                data = b""
    if data.startswith(b"HTTP/"):
        status = data.split(b"\r\n", 1)[0].decode("latin-1")[:80]
        answer = f"an HTTP server answered ({status})"
    elif data:
        answer = f"it answered {data[:60]!r}"
    else:
        answer = f"something accepts connections there but sent nothing in {timeout:g} s"
    raise ValueError(f"{where} is not a Dask scheduler: {answer}")


def _sweep_into(spec, out, workers, remote, figure, progress, t_start) -> SweepResult:
    from softbody.sweep.store import FIGURE, SERIES, TABLE, SweepStore

    with SweepStore(out, spec) as store:
        finished = store.finished
        todo = [r for r in spec.runs if r.run_id not in finished]
        skipped = len(spec.runs) - len(todo)
        _say(progress, f"sweep: {len(spec.runs)} runs of {spec.scene_name} "
                       f"({skipped} already done), writing to {out}")  # fmt: skip
        bar = _Progress(len(spec.runs), skipped, progress)
        args = (spec.scene_name, None if spec.base is None else str(spec.base),
                spec.sample_rate, spec.metrics, spec.user_metrics)  # fmt: skip
        last = time.perf_counter()

        def arrived(row: dict, series) -> None:
            nonlocal last
            store.add(row, series)
            if time.perf_counter() - last >= FLUSH_SECONDS:
                store.flush()
                last = time.perf_counter()
            bar.update(row["status"] != "ok")

        started = span = 0.0
        if todo and workers == 0 and remote is None:
            t0 = time.perf_counter()
            for run in todo:
                arrived(*run_one(run, *args))
            span = time.perf_counter() - t0
        elif todo:
            started, span = _run_on_dask(todo, args, workers, remote, arrived, progress)
        store.flush()
        rows = store.rows
    figure_path = None
    if figure and rows:
        from softbody.sweep.figure import summary_figure

        figure_path = summary_figure(spec, rows, out / FIGURE)
        _say(progress, f"wrote {figure_path}")
    ids = {run.run_id for run in spec.runs}  # once: not per row of a 10^6-run table
    status = [r["status"] for r in rows if r["run_id"] in ids]
    _say(progress, f"wrote {out / TABLE} and {out / SERIES}/")
    return SweepResult(
        out=out,
        table=out / TABLE,
        series=out / SERIES,
        figure=figure_path,
        total=len(spec.runs),
        skipped=skipped,
        executed=len(todo),
        ok=status.count("ok"),
        blew_up=status.count("blew up"),
        errors=status.count("error"),
        wall_time=time.perf_counter() - t_start,
        cluster_start=started,
        run_span=span,
    )


def _run_on_dask(
    todo: list[Run], args: tuple, workers, remote, arrived, progress
) -> tuple[float, float]:
    """Submit every run to a Dask cluster (``remote``, a client, or else a new
    ``LocalCluster`` of ``workers`` processes) and hand each result to ``arrived`` as it
    comes; (seconds to a client with workers, seconds from the first submission to the
    last result)."""
    import logging

    from dask.distributed import Client, LocalCluster, as_completed

    t0 = time.perf_counter()
    cluster = None
    if remote is None:
        n = min(workers or available_cores(), len(todo))  # no idle processes
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            silence_logs=logging.ERROR,
            dashboard_address=":8787",  # another port when taken
        )
        client = Client(cluster)
    else:
        client = remote
    try:
        client.wait_for_workers(1, timeout=120)
        started = time.perf_counter() - t0
        try:
            import bokeh  # noqa: F401 - Dask's dashboard needs it

            link = client.dashboard_link
        except ImportError:
            link = "not served (pip install bokeh)"
        info = client.scheduler_info()
        _say(progress, f"sweep: {len(info.get('workers', {}))} Dask workers; dashboard {link}")
        futures = {}
        t_submit = time.perf_counter()
        for run in todo:
            future = client.submit(run_one, run, *args, key=f"softbody-run-{run.run_id}",
                                   pure=False)  # fmt: skip
            futures[future] = run
        for future in as_completed(futures):
            run = futures[future]
            try:
                row, series = future.result()
            except Exception as exc:  # the worker died too often (KilledWorker) or similar
                row = {"run_id": run.run_id, **run.params, "status": "error",
                       "message": f"{type(exc).__name__}: {_one_line(exc)}"}  # fmt: skip
                series = None
            arrived(row, series)
        span = time.perf_counter() - t_submit
    finally:
        if cluster is not None:  # a remote client is closed by its opener
            client.close()
            cluster.close()
    return started, span
