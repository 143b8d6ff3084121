"""Parameter sweeps (softbody.sweep, ``softbody sweep``) on Dask.

Each run is a tiny ball (42 vertices) dropped on a plane for 0.3 s, so a run takes
milliseconds and the Dask tests are dominated by starting their clusters.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("dask.distributed")
pq = pytest.importorskip("pyarrow.parquet")

import softbody.sweep as sweeps  # noqa: E402
from softbody.cli import main  # noqa: E402
from softbody.sweep.metrics import History, compute_metrics  # noqa: E402
from softbody.sweep.runner import run_one  # noqa: E402

SCENE = """
name = "tiny-drop"
[simulation]
integrator = "midpoint"
dt = 0.002
duration = 0.3
[[colliders]]
type = "plane"
point = [0.0, 0.0, 0.0]
[[bodies]]
mesh = { shape = "icosphere", subdivisions = 1, radius = 0.3 }
position = [0.0, 0.5, 0.0]
mass = 1.0
stiffness = 200.0
damping = 0.5
gas = { law = "isothermal", nrt = 10.0 }
"""
#: 4 x 2 = 8 runs
VARY = {"bodies.0.gas.nrt": [5.0, 10.0, 20.0, 40.0], "bodies.0.stiffness": [100.0, 300.0]}
METRICS = ["body0.sag", "body0.volume_ratio_final", "body0.rebound_ratio", "energy_drift"]


@pytest.fixture
def scene(tmp_path) -> Path:
    path = tmp_path / "tiny-drop.toml"
    path.write_text(SCENE)
    return path


def _table(path: Path) -> dict[str, dict]:
    return {r["run_id"]: r for r in pq.read_table(path / "runs.parquet").to_pylist()}


def _one_by_one(spec) -> dict[str, dict]:
    args = (spec.scene_name, str(spec.base), spec.sample_rate, spec.metrics, spec.user_metrics)
    return {run.run_id: run_one(run, *args)[0] for run in spec.runs}


def _same_metrics(rows: dict, reference: dict) -> None:
    assert rows.keys() == reference.keys()
    for rid, ref in reference.items():
        assert rows[rid]["status"] == ref["status"] == "ok"
        for m in METRICS:
            np.testing.assert_allclose(rows[rid][m], ref[m], rtol=1e-12, atol=1e-15)


def test_local_cluster_equals_runs_one_by_one(scene, tmp_path):
    """Reference: the same 8 runs done one by one in this process. Each Dask task runs
    the same deterministic code on the same inputs, so every metric agrees to round-off;
    the series dataset holds 31 samples (0.3 s at 100 per second, and t = 0) per run."""
    spec = sweeps.build_spec(str(scene), vary=VARY)
    assert len(spec.runs) == 8
    result = sweeps.run_sweep(spec, tmp_path / "out", workers=2, progress=None)
    assert (result.executed, result.ok, result.skipped) == (8, 8, 0)
    rows = _table(tmp_path / "out")
    _same_metrics(rows, _one_by_one(spec))
    assert len({r["worker"] for r in rows.values()}) == 2  # both workers took runs
    import pyarrow.dataset as ds

    series = ds.dataset(tmp_path / "out" / "series", format="parquet").to_table()
    assert series.num_rows == 8 * 31
    assert set(series.column("run_id").to_pylist()) == rows.keys()
    assert result.figure is not None and result.figure.stat().st_size > 0


def test_resume_runs_only_what_is_missing(scene, tmp_path):
    """Invariant: a run id is the hash of its resolved scene, so a rerun finds the runs
    already in the table and executes only the new ones (counted), and the table holds
    each run once."""
    out = tmp_path / "out"
    first = sweeps.sweep(str(scene), out, vary={"bodies.0.gas.nrt": [5.0, 10.0]},
                         workers=0, figure=False, progress=None)  # fmt: skip
    assert (first.executed, first.skipped) == (2, 0)
    again = sweeps.sweep(str(scene), out, vary={"bodies.0.gas.nrt": [5.0, 10.0]},
                         workers=0, figure=False, progress=None)  # fmt: skip
    assert (again.executed, again.skipped) == (0, 2)
    more = sweeps.sweep(str(scene), out, vary={"bodies.0.gas.nrt": [5.0, 10.0, 20.0]},
                        workers=0, figure=False, progress=None)  # fmt: skip
    assert (more.executed, more.skipped) == (1, 2)
    assert len(_table(out)) == 3
    with pytest.raises(sweeps.SweepError, match="different sweep"):
        sweeps.sweep(str(scene), out, vary={"bodies.0.mass": [1.0]}, workers=0,
                     progress=None)  # fmt: skip


def test_blow_up_and_error_are_rows(scene, tmp_path):
    """A run stepped far above its stable step (explicit Euler, dt = 0.02 s on a stiff
    ball) blows up: its row says so with the time of the blow-up, the other runs go on.
    A user metric that raises makes its run an error row naming it."""
    out = tmp_path / "out"
    result = sweeps.sweep(
        str(scene),
        out,
        vary={"simulation.integrator": ["midpoint", "euler"], "bodies.0.stiffness": [5000.0]},
        set={"simulation.dt": 0.02, "simulation.duration": 2.0},
        workers=0,
        figure=False,
        progress=None,
    )
    rows = {r["simulation.integrator"]: r for r in _table(out).values()}
    assert rows["euler"]["status"] == "blew up"
    assert "blew up" in rows["euler"]["message"] and "\n" not in rows["euler"]["message"]
    assert 0 < rows["euler"]["blowup_time"] < 2.0
    assert result.blew_up >= 1

    def broken(history):
        raise ZeroDivisionError("no")

    bad = sweeps.sweep(str(scene), tmp_path / "bad", vary={"bodies.0.mass": [1.0]},
                       user_metrics={"broken": broken}, workers=0, figure=False,
                       progress=None)  # fmt: skip
    row = next(iter(_table(tmp_path / "bad").values()))
    assert bad.errors == 1 and row["status"] == "error"
    assert row["message"] == "metric: ZeroDivisionError: no"
    # the metric fixed, a rerun runs the error again and its row is replaced
    fixed = sweeps.sweep(str(scene), tmp_path / "bad", vary={"bodies.0.mass": [1.0]},
                         user_metrics={"broken": lambda h: 1.0}, workers=0, figure=False,
                         progress=None)  # fmt: skip
    rows = list(_table(tmp_path / "bad").values())
    assert (fixed.executed, fixed.ok, len(rows), rows[0]["broken"]) == (1, 1, 1, 1.0)


def test_killed_worker_run_is_retried(scene, tmp_path):
    """A worker SIGKILLed mid-run (its own run kills it, once, marked by a file): Dask
    reschedules that run on a live worker, and the sweep completes with every run ok."""
    marker = tmp_path / "killed"

    def kill_once(history):
        if not marker.exists():
            marker.write_text(str(os.getpid()))
            os.kill(os.getpid(), signal.SIGKILL)
        return 0.0

    spec = sweeps.build_spec(str(scene), vary={"bodies.0.gas.nrt": [5.0, 10.0, 20.0, 40.0]},
                             user_metrics={"kill_once": kill_once})  # fmt: skip
    result = sweeps.run_sweep(spec, tmp_path / "out", workers=2, figure=False, progress=None)
    assert marker.exists()
    assert (result.executed, result.ok) == (4, 4)
    rows = _table(tmp_path / "out")
    killed = int(marker.read_text())
    assert all(int(r["worker"].rsplit(":", 1)[1]) != killed for r in rows.values())


RUNS = 240


def test_interrupt_leaves_a_consistent_table(scene, tmp_path):
    """Invariant: Ctrl-C (SIGINT) mid-sweep exits with 130 and leaves a whole table whose
    every run has its series on disk; the rerun executes only the runs not in it. The
    sweep is long enough (240 runs of 2 s) that its first table flush, after 2 s of runs,
    comes well before its end: 60 runs of 1 s could all finish before that flush."""
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "softbody.cli", "sweep", str(scene), "--out", str(out),
            "--workers", "2", "--no-figure", "--vary", f"bodies.0.gas.nrt=5:40:{RUNS}",
            "--set", "simulation.duration=2.0"]  # fmt: skip
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while not (out / "runs.parquet").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.decode().strip().endswith("softbody: interrupted (SIGINT)")
    rows = _table(out)
    assert 0 < len(rows) < RUNS
    import pyarrow.dataset as ds

    series = ds.dataset(out / "series", format="parquet").to_table()
    assert set(series.column("run_id").to_pylist()) == rows.keys()
    spec = sweeps.build_spec(str(scene), vary={"bodies.0.gas.nrt": np.linspace(5, 40, RUNS)},
                             set={"simulation.duration": 2.0})  # fmt: skip
    result = sweeps.run_sweep(spec, out, workers=0, figure=False, progress=None)
    assert (result.skipped, result.executed) == (len(rows), RUNS - len(rows))


def _dask() -> list[str]:
    exe = Path(sys.executable).parent / "dask"
    return [str(exe)] if exe.exists() else [shutil.which("dask") or "dask"]


def test_loopback_cluster_by_address(scene, tmp_path, capsys):
    """A real cluster on loopback (``dask scheduler`` and two ``dask worker`` processes)
    reached by ``softbody sweep --address`` gives the same table as the runs done one
    by one."""
    file = tmp_path / "scheduler.json"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "env": env}
    scheduler = [*_dask(), "scheduler", "--host", "127.0.0.1", "--port", "0",
                 "--no-dashboard", "--scheduler-file", str(file)]  # fmt: skip
    procs = [subprocess.Popen(scheduler, **quiet)]
    try:
        deadline = time.monotonic() + 60
        while not file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        address = json.loads(file.read_text())["address"]
        for _ in range(2):
            procs.append(subprocess.Popen(
                [*_dask(), "worker", address, "--nthreads", "1", "--no-dashboard",
                 "--no-nanny"], cwd=tmp_path, **quiet))  # fmt: skip
        from dask.distributed import Client

        with Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=60)
        argv = ["sweep", str(scene), "--out", str(tmp_path / "out"), "--address", address,
                "--no-figure"]  # fmt: skip
        for key, values in VARY.items():
            argv += ["--vary", f"{key}={','.join(map(str, values))}"]
        assert main(argv) == 0, capsys.readouterr().err
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
    rows = _table(tmp_path / "out")
    assert len({r["worker"] for r in rows.values()}) == 2
    _same_metrics(rows, _one_by_one(sweeps.build_spec(str(scene), vary=VARY)))


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('scene = "tiny-drop.toml"\nvary = { "bodies.0.gas.nrtt" = [1, 2] }', "nrtt"),
        ('scene = "tiny-drop.toml"\nvaryy = { "bodies.0.mass" = [1] }', "unknown key 'varyy'"),
        ('scene = "tiny-drop.toml"\n[vary]\n"bodies.0.mass" = [1, -2]', "bodies.0.mass"),
        ('scene = "tiny-drop.toml"\n[vary]\n"bodies.0.mass" = { low = 1, high = 2 }', "range"),
        ('scene = "nowhere.toml"\n[vary]\n"bodies.0.mass" = [1]', "no such scene file"),
        ('scene = "tiny-drop.toml"\n[vary]\n"bodies.3.mass" = [1]', "not an index"),
        ('scene = "tiny-drop.toml"\nmetrics = ["sagg"]', "unknown metric 'sagg'"),
        ('scene = "tiny-drop.toml"\n[random]\nsamples = 4\n[random.vary]\n'
         '"bodies.0.mass" = { distribution = "gauss", mean = 1, std = 1 }', "distribution"),
        ('scene = "tiny-drop.toml"\n[vary\n', "not valid TOML"),
    ],
)
def test_bad_sweep_files_are_one_line_errors(scene, tmp_path, capsys, text, match):
    """Reference: the CLI's contract, one line ``softbody: error: ...`` naming the key,
    status 2, before anything runs (no output folder)."""
    path = tmp_path / "bad.toml"
    path.write_text(text)
    assert main(["sweep", str(path), "--out", str(tmp_path / "out"), "--workers", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("softbody: error:") and "\n" not in err and match in err, err
    assert not (tmp_path / "out").exists()


def test_inline_values_and_random_samples(scene):
    """Reference: ``low:high:count:log`` is numpy.geomspace; seeded random draws repeat
    with the seed; Latin hypercube samples fall one in each of the N strata."""
    assert sweeps.parse_values("10:100:3:log", "k") == pytest.approx([10.0, 31.6227766, 100.0])
    assert sweeps.parse_values("1,4,16", "k") == [1, 4, 16]
    assert sweeps.parse_values("midpoint,rk4", "k") == ["midpoint", "rk4"]
    uniform = {"distribution": "uniform", "low": 1.0, "high": 2.0}
    random = {"samples": 8, "seed": 3, "latin": True, "vary": {"bodies.0.mass": uniform}}
    a = sweeps.build_spec(str(scene), random=random)
    b = sweeps.build_spec(str(scene), random=random)
    masses = [r.params["bodies.0.mass"] for r in a.runs]
    assert masses == [r.params["bodies.0.mass"] for r in b.runs]
    assert sorted(int((m - 1.0) * 8) for m in masses) == list(range(8))
    star = sweeps.build_spec("hanging-ball", vary={"bodies.*.stiffness": [10.0]})
    assert [b["stiffness"] for b in star.runs[0].data["bodies"]] == [10.0] * 3


def test_metrics_of_a_known_history():
    """Reference: a centre of mass falling from 1 m to 0.2 m and rebounding to 0.6 m
    recovers (0.6 - 0.2) / (1 - 0.2) = 0.5 of its fall; the volume ratio is V / V_rest;
    the kinetic energy stays below 1e-3 of its peak from t = 3 s on."""
    t = np.arange(6.0)
    y = np.array([1.0, 0.2, 0.6, 0.4, 0.45, 0.45])
    com = np.zeros((6, 1, 3))
    com[:, 0, 1] = y
    h = History(t=t, volume=np.array([[2.0], [1.0], [1.5], [2.0], [2.0], [3.0]]),
                rest_volume=np.array([2.0]), pressure=np.ones((6, 1)), center_of_mass=com,
                kinetic=np.array([[0.0], [10.0], [1.0], [0.001], [0.0], [0.0]]),
                extent=np.tile([1.0, 3.0, 2.0], (6, 1, 1)),
                energy=np.array([5.0, 5.0, 5.0, 4.0, 4.0, 4.0]),
                collider_impulse=np.zeros((6, 0, 3)), body_names=["b"])  # fmt: skip
    m = compute_metrics(h)
    assert m["body0.rebound_ratio"] == pytest.approx(0.5)
    assert m["body0.rebound_height"] == pytest.approx(0.6)
    assert m["body0.sag"] == pytest.approx(0.55)
    assert m["body0.aspect_final"] == 2.0  # 3 / ((1 + 2) / 2)
    assert (m["body0.volume_ratio_min"], m["body0.volume_ratio_final"]) == (0.5, 1.5)
    assert m["body0.settling_time"] == 3.0
    assert m["energy_drift"] == -1.0 and m["energy_drift_relative"] == -0.2


def test_import_softbody_does_not_import_dask():
    """``import softbody`` and the CLI's ``run`` path load no sweep dependency."""
    code = ("import sys, softbody, softbody.cli, softbody.run, softbody.scenes\n"
            "bad = [m for m in ('dask', 'distributed', 'pyarrow', 'zarr') if m in sys.modules]\n"
            "assert not bad, bad\nassert callable(softbody.sweep)")  # fmt: skip
    subprocess.run([sys.executable, "-c", code], check=True)


# -- issue 29: links, identity, sizes, a wrong --address ----------------------------------


def _tiny_sweep(scene: Path, out: Path, **kwargs):
    """Two runs of the tiny drop in this process (no Dask), no figure."""
    kwargs.setdefault("vary", {"bodies.0.gas.nrt": [5.0, 10.0]})
    return sweeps.sweep(str(scene), out, workers=0, figure=False, progress=None, **kwargs)


def test_series_link_is_never_followed(scene, tmp_path):
    """Issue 29 item 12: with ``series/`` a link to another folder, a resumed sweep
    deleted that folder's ``part-*.parquet`` files (any part no table row named). A link
    in place of ``series/`` now stops the sweep with one line and nothing behind it is
    touched."""
    out, elsewhere = tmp_path / "out", tmp_path / "elsewhere"
    _tiny_sweep(scene, out)
    (out / "series").rename(elsewhere)
    shutil.copy(elsewhere / "part-00000.parquet", elsewhere / "part-00007.parquet")
    (out / "series").symlink_to(elsewhere, target_is_directory=True)
    kept = sorted(p.name for p in elsewhere.iterdir())
    from softbody.io.outputs import OutputError

    with pytest.raises(OutputError, match="series is not a folder"):
        _tiny_sweep(scene, out)
    assert kept == ["part-00000.parquet", "part-00007.parquet"]
    assert sorted(p.name for p in elsewhere.iterdir()) == kept


def test_resume_removes_only_series_parts_it_wrote(scene, tmp_path):
    """Issue 29 item 12: a resumed sweep removes a series part no row names (left by a
    crash between two renames) only when it is a regular file holding run ids of this
    sweep alone: a copy of one of its parts goes, a user's Parquet file named like a
    part (other run ids) and a link named like one stay."""
    import pyarrow as pa

    out = tmp_path / "out"
    _tiny_sweep(scene, out)
    series = out / "series"
    shutil.copy(series / "part-00000.parquet", series / "part-00005.parquet")  # ours
    pq.write_table(pa.table({"run_id": ["mine"], "x": [1.0]}), series / "part-00006.parquet")
    (tmp_path / "t.parquet").write_bytes((series / "part-00000.parquet").read_bytes())
    (series / "part-00008.parquet").symlink_to(tmp_path / "t.parquet")
    _tiny_sweep(scene, out)
    assert sorted(p.name for p in series.iterdir()) == [
        "part-00000.parquet",
        "part-00006.parquet",
        "part-00008.parquet",
    ]
    assert (tmp_path / "t.parquet").exists()


def test_changed_set_is_another_sweep(scene, tmp_path):
    """Issue 29 item 13: rerunning a sweep with another ``--set`` mixed two sweeps in one
    table (rows of mass 1 and mass 5 under one nRT, no column saying which). Every fixed
    override is now part of the table's identity: the second sweep is refused with one
    line naming the override in both, and the table keeps its two rows."""
    out = tmp_path / "out"
    _tiny_sweep(scene, out, set={"bodies.0.mass": 1.0})
    message = (r"holds a sweep with other fixed overrides \(bodies.0.mass=1.0; this one: "
               r"bodies.0.mass=5.0\)")  # fmt: skip
    with pytest.raises(sweeps.SweepError, match=message):
        _tiny_sweep(scene, out, set={"bodies.0.mass": 5.0})
    with pytest.raises(sweeps.SweepError, match="bodies.0.mass unset"):
        _tiny_sweep(scene, out)
    assert len(_table(out)) == 2
    again = _tiny_sweep(scene, out, set={"bodies.0.mass": 1.0})
    assert (again.executed, again.skipped) == (0, 2)


def test_scene_file_changed_since_is_another_sweep(scene, tmp_path):
    """Issue 29 item 13: the base scene's contents are part of the identity too: a sweep
    resumed after its scene file was edited is refused with one line saying so."""
    out = tmp_path / "out"
    _tiny_sweep(scene, out)
    scene.write_text(SCENE.replace("damping = 0.5", "damping = 0.7"))
    with pytest.raises(sweeps.SweepError, match="the scene has changed since"):
        _tiny_sweep(scene, out)


def test_huge_grid_is_refused_before_any_list_is_built(scene, tmp_path):
    """Issue 29 item 14: a grid of 10^9 combinations built its whole list first (7.7 GB)
    before refusing. The count is now the product of the value counts, refused at once:
    run under a 4 GiB address-space limit, the command ends with one line giving the
    count and the limit, and writes nothing."""
    import resource

    def limit_memory():
        resource.setrlimit(resource.RLIMIT_AS, (4 * 1024**3, 4 * 1024**3))

    argv = [sys.executable, "-m", "softbody.cli", "sweep", str(scene), "--out",
            str(tmp_path / "out"), "--workers", "0"]  # fmt: skip
    for key in ("bodies.0.gas.nrt", "bodies.0.mass", "bodies.0.stiffness"):
        argv += ["--vary", f"{key}=1:100:1000"]
    result = subprocess.run(argv, capture_output=True, text=True, timeout=120,
                            preexec_fn=limit_memory)  # fmt: skip
    assert result.returncode == 2, result.stderr
    assert result.stderr.splitlines() == [
        "softbody: error: softbody sweep: the grid would have at least 1,000,000,000 runs "
        "(1,000 x 1,000 x 1,000 values), over the limit of 1,000,000"
    ]
    assert not (tmp_path / "out").exists()


def test_each_varied_value_is_validated_once_not_each_run(scene, monkeypatch):
    """Issue 29 item 14: a 10^6-run sweep validated every run's scene (8 minutes before
    printing anything). The scene schema now checks the first run, each key's distinct
    values in it (a range's past 64 values: its smallest and largest, as the schema's
    bounds are intervals), and the last run: 1 + (4 + 2) + 1 validations for a
    4 x 5,000 grid of 20,000 runs. A bad value is still one error naming the key."""
    from softbody.scenes import loader

    calls = []
    real = loader.validate
    monkeypatch.setattr(loader, "validate", lambda data: calls.append(1) or real(data))
    vary = {"bodies.0.gas.nrt": [5.0, 10.0, 20.0, 40.0],
            "bodies.0.stiffness": {"low": 100.0, "high": 300.0, "count": 5000}}  # fmt: skip
    spec = sweeps.build_spec(str(scene), vary=vary)
    assert len(spec.runs) == 20_000 and len(calls) == 8
    assert spec.runs[-1].data["bodies"][0]["stiffness"] == 300.0
    vary["bodies.0.gas.nrt"][2] = -1.0
    with pytest.raises(sweeps.SweepError, match=r"vary.bodies.0.gas.nrt=-1.0: .*\bnrt\b"):
        sweeps.build_spec(str(scene), vary=vary)


def test_oversized_sweep_file_is_refused_before_it_is_read(tmp_path, capsys):
    """Issue 29 item 14: a sweep file is refused by its size (``stat``) before it is read,
    as ``softbody run`` refuses a scene file: a 3 GB file was read whole (6.4 GB peak)
    first. A sparse file one byte over the 64 MiB limit: one line naming it and the
    limit, and well under 64 MiB allocated while refusing it."""
    import tracemalloc

    from softbody import limits

    big = tmp_path / "big.toml"
    with big.open("wb") as f:
        f.write(b'scene = "hanging-ball"\n#')
        f.truncate(limits.MAX_SCENE_FILE_BYTES + 1)
    tracemalloc.start()
    try:
        code = main(["sweep", str(big), "--out", str(tmp_path / "out"), "--workers", "0"])
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "big.toml" in err and "64 MiB" in err, err
    assert peak < 16 * 1024**2
    with pytest.raises(ValueError, match="larger than the 64 MiB"):
        sweeps.load_sweep_file(big)


def test_workers_above_the_available_cores_are_refused(scene, tmp_path, capsys):
    """Issue 29 item 14: ``--workers 100000`` (or 50 on 2 cores) started that many
    processes. More workers than the cores this process may use is now one line saying
    how many it may have, before any cluster starts or anything is written."""
    from softbody.sweep.runner import available_cores

    cores = available_cores()
    code = main(["sweep", str(scene), "--out", str(tmp_path / "out"), "--workers",
                 str(cores + 1), "--vary", "bodies.0.gas.nrt=5,10"])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err, err
    assert f"--workers {cores + 1}" in err and f"at most {cores} workers" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("server", ["silent", "http"])
def test_address_of_something_else_is_one_line_in_bounded_time(scene, tmp_path, server):
    """Issue 29 item 15: ``--address`` at a port where something else listens (an HTTP
    server, a listener that never answers) hung for over 90 s with no output. The
    handshake is bounded now (a Dask scheduler greets at once): the command ends with
    one line saying what answered, exit 2, within the 60 s given here, and writes
    nothing."""
    import http.server
    import socket
    import threading

    if server == "http":
        httpd = http.server.HTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
        httpd.RequestHandlerClass.log_message = lambda *args: None
        port = httpd.server_address[1]
        threading.Thread(target=httpd.serve_forever, daemon=True).start()
        close = httpd.shutdown
        match = "is not a Dask scheduler: an HTTP server answered (HTTP/1.0 "
    else:
        listener = socket.socket()
        listener.bind(("127.0.0.1", 0))
        listener.listen(8)  # accepted by the kernel, never read nor answered
        port = listener.getsockname()[1]
        close = listener.close
        match = "is not a Dask scheduler: something accepts connections there but sent nothing"
    try:
        result = subprocess.run(
            [sys.executable, "-m", "softbody.cli", "sweep", str(scene), "--out",
             str(tmp_path / "out"), "--address", f"tcp://127.0.0.1:{port}",
             "--vary", "bodies.0.gas.nrt=5,10"],
            capture_output=True, text=True, timeout=60,
        )  # fmt: skip
    finally:
        close()
    assert result.returncode == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and f"tcp://127.0.0.1:{port} {match}" in lines[0], lines
    assert not (tmp_path / "out").exists()


def test_heat_map_cell_labels_fit_their_cells():
    """Contract of the sweep figure's heat-map texts (the landing-cushion sweep's labels
    ran into each other): values of 1e4 and above are shown over their power of ten with
    the scale in the title; the font shrinks to fit the widest text in the cell (0.62 of
    the font size per character), never above 7 pt; below 4.5 pt no text is drawn."""
    from softbody.sweep.figure import cell_labels

    pressures = np.array([[1.0932e5, 1.0911e5], [np.nan, 1.047e5]])
    texts, size, note = cell_labels(pressures, cell_points=15.0)
    assert texts == ["1.09", "1.09", "", "1.05"] and note == " (x 1e5)"
    assert size == pytest.approx(15.0 / (0.62 * 4))
    texts, size, note = cell_labels(np.array([[0.578, 0.00671]]), cell_points=100.0)
    assert texts == ["0.578", "0.00671"] and note == "" and size == 7.0
    assert cell_labels(np.array([[0.001234, 0.005]]), 20.0)[0] == ["1.23", "5"]
    assert cell_labels(np.array([[123.456]]), cell_points=8.0)[1] == 0.0
