"""What a run writes, and what it never touches (issue 19, items 2, 4, 5, 6 and 10).

Every case runs the real command line in a subprocess with short durations of the
hanging-ball scene (midpoint, the kernels every CLI test shares), in a temporary folder.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENE = (ROOT / "src/softbody/scenes/hanging-ball.toml").read_text()
#: each subprocess may compile the kernels on its first run (about a minute)
TIMEOUT = 600


def softbody(*args: str, cwd: Path, timeout: float = TIMEOUT) -> subprocess.CompletedProcess:
    """Run ``python -m softbody.cli ARGS`` in ``cwd``; its exit code, stdout and stderr."""
    return subprocess.run(
        [sys.executable, "-m", "softbody.cli", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def one_error_line(result: subprocess.CompletedProcess, match: str) -> str:
    """The run failed with exit 2 and exactly one stderr line, ``softbody: error: ...``
    containing ``match``; returns that line."""
    assert result.returncode == 2, (result.returncode, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("softbody: error: ") and match in lines[0], lines[0]
    return lines[0]


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative path -> contents)."""
    return {
        p.relative_to(folder).as_posix(): p.read_bytes() for p in folder.rglob("*") if p.is_file()
    }


def test_user_meshes_folder_survives_out_dot(tmp_path):
    """Issue 19 item 4: in a project folder whose scene loads ``meshes/my.obj``,
    ``softbody run scene.toml --out . --meshes obj`` used to ``rmtree`` the user's
    ``meshes/``. A run's mesh frames now go to ``NAME-meshes/``, so the user's folder is
    never in the way; a user's folder of that very name stops the run with one line
    naming it, and the project folder is unchanged."""
    import softbody as sb

    (tmp_path / "meshes").mkdir()
    sb.save_mesh(sb.icosphere(1, radius=0.5), tmp_path / "meshes" / "my.obj")
    scene = SCENE.replace(
        'mesh = { shape = "icosphere", subdivisions = 2, radius = 0.5 }',
        'mesh = { file = "meshes/my.obj" }',
        1,
    )
    assert scene != SCENE
    (tmp_path / "scene.toml").write_text(scene)
    mine = snapshot(tmp_path)
    args = ("run", "scene.toml", "--out", ".", "--meshes", "obj", "--duration", "0.01",
            "--no-video", "--no-gif")  # fmt: skip
    (tmp_path / "hanging-ball-meshes").mkdir()
    (tmp_path / "hanging-ball-meshes" / "notes.txt").write_text("mine")
    before = snapshot(tmp_path)
    one_error_line(softbody(*args, cwd=tmp_path), "hanging-ball-meshes/ already exists")
    assert snapshot(tmp_path) == before
    shutil.rmtree(tmp_path / "hanging-ball-meshes")
    result = softbody(*args, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    files = snapshot(tmp_path)
    assert {k: files[k] for k in mine} == mine
    assert "hanging-ball-meshes/frame_00000.obj" in files


@pytest.mark.parametrize("name", ["../../x", "{tmp}/abs/x", "..", "a/../../b\\c\nd"])
def test_scene_name_cannot_write_outside_out(tmp_path, name):
    """Issue 19 item 5: a scene's ``name`` is a file stem, so ``name = "../../x"`` or an
    absolute path wrote the video, plots and summary outside ``--out`` (and skipped the
    temporary folder). Now nothing is written outside ``--out`` and the files there
    have a plain stem."""
    name = name.replace("{tmp}", str(tmp_path))
    # a JSON string is a TOML basic string (same escapes)
    (tmp_path / "s.toml").write_text(
        SCENE.replace('name = "hanging-ball"', f"name = {json.dumps(name)}", 1)
    )
    out = tmp_path / "a" / "b" / "out"
    result = softbody(
        "run", "s.toml", "--out", str(out), "--duration", "0.01", "--no-video", cwd=tmp_path
    )
    assert result.returncode == 0, result.stderr
    outside = {p for p in snapshot(tmp_path) if not p.startswith("a/b/out/")}
    assert outside == {"s.toml"}
    names = sorted(p.name for p in out.iterdir())
    assert len(names) == 4
    assert all(not n.startswith(".") and "/" not in n and "\n" not in n for n in names)


ONE_RUN = ["hanging-ball-last-frame.png", "hanging-ball-plots.png", "hanging-ball-summary.json"]


def test_a_second_scene_keeps_the_first_scenes_files(tmp_path):
    """Issue 29 item 8: running another scene into the same ``--out`` silently removed
    the first scene's video, plots and summary. Each scene's files carry its name, and a
    run removes nothing: both scenes' files are there, the first's unchanged."""
    out = tmp_path / "out"
    args = ("--out", str(out), "--duration", "0.01", "--no-video", "--meshes", "ply")
    first = softbody("run", "hanging-ball", *args, cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    before = snapshot(out)
    second = softbody("run", "bouncing-balls", *args, "--no-gif", cwd=tmp_path)
    assert second.returncode == 0, second.stderr
    after = snapshot(out)
    assert {k: after[k] for k in before} == before
    assert {"bouncing-balls-summary.json", "bouncing-balls-meshes/frame_00000.ply"} <= after.keys()
    assert [line for line in second.stdout.splitlines() if line.startswith("replaced")] == []


def test_same_scene_again_needs_overwrite_and_says_what_it_replaced(tmp_path):
    """Issue 29 item 8: a second run of a scene whose files are in ``--out`` stops with
    one line naming them (nothing is written); with ``--overwrite`` it replaces exactly
    its own files and prints each one it replaced. Files of the first run that the
    second does not write (its GIF after ``--no-gif``, surplus mesh frames) are left as
    they were, and a note says so."""
    out = tmp_path / "out"
    args = ("run", "hanging-ball", "--out", str(out), "--no-video")
    first = softbody(*args, "--duration", "0.05", "--meshes", "ply", cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    before = snapshot(out)
    again = (*args, "--duration", "0.01", "--no-gif", "--meshes", "ply")
    line = one_error_line(softbody(*again, cwd=tmp_path), "already exist")
    assert f"{out}/hanging-ball-last-frame.png" in line and "--overwrite" in line
    assert snapshot(out) == before
    result = softbody(*again, "--overwrite", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert [x for x in lines if x.startswith("replaced")] == [
        f"replaced {out / name}" for name in ONE_RUN
    ]
    assert f"wrote {out / 'hanging-ball-meshes'} (replacing 2 of its files)" in lines
    assert any(x.startswith("note: ") and "frame_00002.ply" in x for x in lines), lines
    after = snapshot(out)
    assert after.keys() == before.keys()  # nothing removed
    assert after["hanging-ball.gif"] == before["hanging-ball.gif"]
    assert after["hanging-ball-summary.json"] != before["hanging-ball-summary.json"]
    assert json.loads(after["hanging-ball-summary.json"])["frames"] == 2


@pytest.mark.parametrize("case", ["foreign", "edited", "foreign-in-meshes"])
def test_files_softbody_did_not_write_are_never_overwritten(tmp_path, case):
    """A user's file named like an output (``out/hanging-ball.gif``), or one of a run's
    files the user has since edited, is never overwritten without ``--overwrite``: the
    run stops with one line naming it, before writing anything. A user's file put in a
    run's ``NAME-meshes/`` folder survives every later run, with ``--overwrite`` too."""
    out = tmp_path / "out"
    args = ("run", "hanging-ball", "--out", str(out), "--duration", "0.01", "--no-video")
    if case == "foreign":
        out.mkdir()
        (out / "hanging-ball.gif").write_bytes(b"my own animation")
    else:
        first = softbody(*args, "--meshes", "obj", cwd=tmp_path)
        assert first.returncode == 0, first.stderr
        if case == "edited":
            (out / "hanging-ball-summary.json").write_text("{}  # my notes\n")
        else:
            (out / "hanging-ball-meshes" / "notes.txt").write_text("my notes")
    before = snapshot(out)
    if case == "foreign-in-meshes":
        for extra in ((), ("--meshes", "obj")):
            result = softbody(*args, *extra, "--overwrite", cwd=tmp_path)
            assert result.returncode == 0, result.stderr
        assert snapshot(out).keys() == before.keys()
        assert (out / "hanging-ball-meshes" / "notes.txt").read_text() == "my notes"
        return
    name = "hanging-ball.gif" if case == "foreign" else "hanging-ball-last-frame.png"
    one_error_line(softbody(*args, cwd=tmp_path), f"{out / name}")
    assert snapshot(out) == before


def _children(pid: int) -> dict[int, str]:
    """The live child processes of ``pid`` (pid -> command name), from /proc."""
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        name = stat[stat.index("(") + 1 : stat.rindex(")")]
        fields = stat[stat.rindex(")") + 2 :].split()
        if int(fields[1]) == pid and fields[0] != "Z":
            found[int(entry.name)] = name
    return found


def _alive(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text()
    except OSError:
        return False
    return state[state.rindex(")") + 2] != "Z"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")
@pytest.mark.parametrize(
    "signum,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130), (signal.SIGHUP, 129)]
)
def test_signal_removes_temporary_files_and_ffmpeg(tmp_path, signum, code):
    """Issue 19 item 6: SIGTERM left a hidden ``.softbody-run-*`` folder and an orphaned
    ffmpeg; issue 29 item 17: so did SIGHUP (a closed terminal), which now stops a run
    as SIGTERM does. A signal during a run (sent once the temporary folder and ffmpeg exist) now
    ends it with one line and 128 + the signal number, no temporary folder, no ffmpeg
    left running and nothing written."""
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "softbody.cli", "run", "hanging-ball", "--out", str(out),
         "--duration", "5", "--no-gif"],
        cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        # a shell's background job may inherit SIGINT ignored; a user's terminal does not
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # fmt: skip
    try:
        deadline = time.monotonic() + TIMEOUT
        ffmpeg = {}
        while time.monotonic() < deadline and proc.poll() is None:
            ffmpeg = {p: n for p, n in _children(proc.pid).items() if "ffmpeg" in n}
            if ffmpeg and out.exists() and any(out.glob(".softbody-run-*")):
                break
            time.sleep(0.05)
        assert proc.poll() is None and ffmpeg, "the run ended before it could be interrupted"
        proc.send_signal(signum)
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == code, stderr
    assert stderr.splitlines() == [f"softbody: interrupted ({signal.Signals(signum).name})"]
    assert not any(_alive(p) for p in ffmpeg)
    assert list(out.iterdir()) == []


def test_step_guards_refuse_endless_runs(tmp_path):
    """Issue 19 item 2: ``--set render.fps=1e-6`` made one frame of about 10^9 steps (a
    hang) and ``--dt 1e-12`` ran 5e12 steps in silence. Both now stop at once with one
    line: the fps by the scene's bounds, the dt by the step count and the way to allow
    it (``--max-steps``); a frame count above ``--max-frames`` is refused the same way.
    Nothing is written."""
    out = tmp_path / "out"
    base = ("run", "hanging-ball", "--out", str(out), "--no-video", "--no-gif")
    cases = [
        (("--duration", "0.01", "--set", "render.fps=1e-6"), "render.fps: must be >= 0.01"),
        (("--dt", "1e-12",), "--max-steps"),
        (("--duration", "10", "--max-frames", "100"), "300 frames"),
    ]  # fmt: skip
    for args, match in cases:
        result = softbody(*base, *args, cwd=tmp_path, timeout=120)
        one_error_line(result, match)
    assert not out.exists()


def test_blow_up_leaves_no_ffmpeg_running(tmp_path, capfd):
    """Issue 19 items 6 and 10: a run that blows up in the middle left ffmpeg running,
    waiting on its pipe for as long as the error's traceback was kept (an interactive
    session keeps the last one), and its messages went to the terminal. Now the failed
    run kills and reaps ffmpeg before it returns, ffmpeg printed nothing, and nothing
    is written. (The box spins at 3000 rad/s: the walls throw the
    balls to NaN within 50 steps.)"""
    import softbody as sb
    from softbody.run import Outputs, run_scene
    from softbody.scenes import load_scene

    scene = load_scene(
        "bouncing-balls", ["colliders.0.motion.angular_velocity=[0.0, 0.0, 3e3]"]
    )
    out = tmp_path / "out"
    with pytest.raises(sb.SimulationError, match="blew up at step") as info:
        run_scene(scene, out, integrator="midpoint", duration=0.5, outputs=Outputs(gif=False))
    # the traceback is still held (as an interactive session's last error is): ffmpeg
    # must be gone all the same, not just when the writer happens to be collected
    assert info.traceback
    assert not any("ffmpeg" in name for name in _children(os.getpid()).values())
    # stderr holds the progress lines only (ffmpeg's inherited stderr held its messages)
    err = capfd.readouterr().err.splitlines()
    assert err and all(re.fullmatch(r" *[\d.]+% t = [\d.]+ s", line) for line in err), err
    assert list(out.iterdir()) == []


def test_out_must_be_a_folder(tmp_path):
    """``--out`` naming an existing file: one line saying so; the file is untouched."""
    target = tmp_path / "notes.txt"
    target.write_text("mine")
    result = softbody(
        "run", "hanging-ball", "--out", str(target), "--duration", "0.01", cwd=tmp_path
    )
    one_error_line(result, "exists and is not a folder")
    assert target.read_text() == "mine"


def test_run_scene_refuses_a_users_file(tmp_path):
    """The library call (not just the CLI) checks targets too: a user's file where an
    output goes raises OutputError (a ValueError) naming it, and writes nothing."""
    from softbody.io.outputs import OutputError
    from softbody.run import Outputs, run_scene
    from softbody.scenes import load_scene

    out = tmp_path / "out"
    out.mkdir()
    (out / "hanging-ball-plots.png").write_bytes(b"mine")
    with pytest.raises(OutputError, match="hanging-ball-plots.png already exists"):
        run_scene(
            load_scene("hanging-ball"), out, duration=0.01, outputs=Outputs(video=False, gif=False)
        )
    assert snapshot(out) == {"hanging-ball-plots.png": b"mine"}
    assert os.listdir(out) == ["hanging-ball-plots.png"]


def test_two_runs_never_write_one_folder_at_once(tmp_path):
    """Two runs into one folder would each remove or replace the other's files half way
    (issue 19 item 6: one run's outputs per folder): while one run holds the folder, a
    second stops with one line and writes nothing."""
    import fcntl

    out = tmp_path / "out"
    out.mkdir()
    fd = os.open(out, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # what a run in progress holds
        result = softbody(
            "run", "hanging-ball", "--out", str(out), "--duration", "0.01", "--no-video",
            cwd=tmp_path,
        )  # fmt: skip
    finally:
        os.close(fd)
    one_error_line(result, "another softbody run is writing to this folder")
    assert list(out.iterdir()) == []


def test_failed_ffmpeg_is_one_line(tmp_path):
    """Issue 19 item 10: when ffmpeg fails (here: its output folder does not exist, as
    after a full disk or a removed folder), imageio's error carried ffmpeg's command
    line and output over many lines. softbody's writer raises one line with ffmpeg's
    own reason, and leaves no ffmpeg running."""
    import numpy as np

    from softbody.render.video import VideoWriter

    writer = VideoWriter(tmp_path / "missing" / "x.mp4", 30.0, gif=False)
    with pytest.raises(RuntimeError) as info:
        for _ in range(100):  # ffmpeg reads a few frames before it opens its output
            writer.append(np.zeros((48, 64, 3), np.uint8))
        writer.close()
    message = str(info.value)
    assert "\n" not in message and "No such file or directory" in message, message
    assert message.startswith("x.mp4: ffmpeg")
    assert not any("ffmpeg" in name for name in _children(os.getpid()).values())


# --- links below --out, forged manifests, failed moves, temporary folders -------------


def _commit(out: Path, files: dict[str, bytes], overwrite: bool = False):
    """Commit ``files`` (relative path -> contents) into ``out`` as a run does: written
    into a fresh temporary folder inside ``out`` and moved in by ``commit``, under the
    folder lock. No simulation: the output-folder code alone, in milliseconds."""
    from softbody.io import outputs

    outputs.prepare(out)
    with outputs.folder_lock(out):
        tmp = Path(tempfile.mkdtemp(prefix=".softbody-run-", dir=out))
        try:
            for rel, data in files.items():
                (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
                (tmp / rel).write_bytes(data)
            return outputs.commit(tmp, out, list(files), overwrite=overwrite)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)


def _quick_run(out: Path, **outputs) -> dict:
    """``run_scene`` of the hanging ball for 0.01 s (in this process), no video, no GIF."""
    from softbody.run import Outputs, run_scene
    from softbody.scenes import load_scene

    overwrite = outputs.pop("overwrite", False)
    return run_scene(
        load_scene("hanging-ball"),
        out,
        duration=outputs.pop("duration", 0.01),
        outputs=Outputs(video=False, gif=False, **outputs),
        overwrite=overwrite,
    )


@pytest.mark.parametrize("at", [True, False], ids=["dir_fd", "lstat-walk"])
def test_meshes_folder_behind_a_link_is_never_written_through(tmp_path, monkeypatch, at):
    """Review, defect 1a: after ``--meshes obj`` the user moved the frames away and left a
    link in their place (``mv out/NAME-meshes keep && ln -s keep out/NAME-meshes``). A
    link below ``--out`` is never followed: a run without meshes leaves it and what it
    points to alone, and one that would write frames there stops with one line, with
    ``--overwrite`` too, before moving anything. Checked with the ``dir_fd`` calls and
    with the lstat walk used where a platform lacks them."""
    from softbody.io import outputs

    monkeypatch.setattr(outputs, "_AT", at, raising=False)
    out, keep = tmp_path / "out", tmp_path / "keep"
    _quick_run(out, meshes="obj", duration=0.05)
    assert len(list((out / "hanging-ball-meshes").iterdir())) > 1
    (out / "hanging-ball-meshes").rename(keep)
    (out / "hanging-ball-meshes").symlink_to(keep, target_is_directory=True)
    kept = snapshot(keep)
    _quick_run(out, overwrite=True)
    assert snapshot(keep) == kept and (out / "hanging-ball-meshes").is_symlink()
    before = snapshot(out)
    with pytest.raises(outputs.OutputError, match="hanging-ball-meshes is not a folder"):
        _quick_run(out, meshes="obj", overwrite=True)
    assert snapshot(keep) == kept and snapshot(out) == before
    # a link swapped in for a file of the run's: not replaced, not written through
    (out / "hanging-ball-plots.png").unlink()
    (out / "hanging-ball-plots.png").symlink_to(keep / "frame_00000.obj")
    with pytest.raises(outputs.OutputError, match="is not a file softbody can replace"):
        _quick_run(out, overwrite=True)
    assert snapshot(keep) == kept


def _forge_manifest(out: Path, files: dict[str, Path]) -> None:
    """Write a manifest ``softbody-run.json`` in ``out`` in the format softbody once
    wrote, listing each path with the real size and SHA-256 of the file it names
    (``files``: listed path -> file)."""
    items = [
        {"path": rel, "size": len(data), "sha256": hashlib.sha256(data).hexdigest()}
        for rel, data in ((rel, f.read_bytes()) for rel, f in files.items())
    ]
    (out / "softbody-run.json").write_text(json.dumps({"format": "softbody-run/1",
                                                       "files": items}))  # fmt: skip


def test_forged_manifest_deletes_nothing(tmp_path):
    """Issue 29 item 9: a ``softbody-run.json`` shipped in a repository, listing
    ``README.md`` and ``.git/HEAD`` with their real sizes and hashes, made
    ``softbody run ... --out .`` delete them (ownership rested on a file anyone can
    write). A run now deletes nothing, and replaces only its own file names: with and
    without ``--overwrite`` every file of the repository is unchanged, the manifest
    included."""
    repo = tmp_path / "repo"
    (repo / ".git").mkdir(parents=True)
    (repo / "README.md").write_text("# my project\n")
    (repo / ".git" / "HEAD").write_text("ref: refs/heads/main\n")
    _forge_manifest(repo, {"README.md": repo / "README.md", ".git/HEAD": repo / ".git/HEAD"})
    before = snapshot(repo)
    for overwrite in (False, True):
        _quick_run(repo, overwrite=overwrite)
        files = snapshot(repo)
        assert {k: files[k] for k in before} == before
        assert sorted(files.keys() - before.keys()) == ONE_RUN


def test_users_folder_named_like_a_temporary_one_is_kept(tmp_path):
    """Issue 29 item 9: a folder named like a run's temporary folder (``.softbody-run-``
    and 8 characters, as ``tempfile.mkdtemp`` names them) was deleted, recursively, with
    the user's files in it, by the next run into that folder. A run removes only the
    temporary folder it made itself: such a folder, its files, and a link of such a name
    (and what it points to) all stay."""
    out, elsewhere = tmp_path / "out", tmp_path / "elsewhere"
    mine = out / ".softbody-run-k3j_9x0q"
    (mine / "meshes").mkdir(parents=True)
    (mine / "meshes" / "frame_00000.obj").write_text("v 0 0 0\n")
    (mine / "notes.txt").write_text("mine")
    elsewhere.mkdir()
    (elsewhere / "f.txt").write_text("mine too")
    (out / ".softbody-run-zzzzzzzz").symlink_to(elsewhere, target_is_directory=True)
    before = snapshot(out)
    _quick_run(out)
    files = snapshot(out)
    assert {k: files[k] for k in before} == before
    assert sorted(files.keys() - before.keys()) == ONE_RUN
    assert snapshot(elsewhere) == {"f.txt": b"mine too"}
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == [
        ".softbody-run-k3j_9x0q",
        ".softbody-run-zzzzzzzz",
    ]


@pytest.mark.parametrize("call", [1, 2, 3])
def test_failed_move_leaves_whole_files(tmp_path, monkeypatch, call):
    """A move that fails half way (a full disk, an I/O error) raises; each file in
    ``--out`` is then whole: the earlier run's version or this run's, never a part,
    and nothing is deleted. A later ``--overwrite`` run ends with exactly its files."""
    from softbody.io import outputs

    out = tmp_path / "out"
    _commit(out, {"a.txt": b"a1", "b.txt": b"b1", "m/f0.obj": b"m1"})
    calls = []
    real = os.replace

    def fail(src, *args, **kwargs):
        calls.append(src)
        if len(calls) == call:
            raise OSError(errno.EIO, "Input/output error")
        return real(src, *args, **kwargs)

    with monkeypatch.context() as m:
        m.setattr(outputs.os, "replace", fail)
        with pytest.raises(OSError, match="Input/output error"):
            _commit(out, {"a.txt": b"a2", "b.txt": b"b2", "m/f0.obj": b"m2"}, overwrite=True)
    files = snapshot(out)
    new = {"a.txt": b"a2", "b.txt": b"b2", "m/f0.obj": b"m2"}
    old = {"a.txt": b"a1", "b.txt": b"b1", "m/f0.obj": b"m1"}
    assert files.keys() == new.keys()
    assert all(files[k] in (old[k], new[k]) for k in files), files
    assert [k for k in sorted(files) if files[k] == new[k]] == sorted(new)[: call - 1]
    done = _commit(out, {"b.txt": b"b3", "c.txt": b"c3"}, overwrite=True)
    assert [p.name for p in done.replaced] == ["b.txt"]
    assert snapshot(out) == {"a.txt": files["a.txt"], "b.txt": b"b3", "c.txt": b"c3",
                             "m/f0.obj": files["m/f0.obj"]}  # fmt: skip
    assert not any(p.name.startswith(".") for p in out.iterdir())


@pytest.mark.parametrize("links", [True, False], ids=["hard-link", "no-hard-links"])
def test_a_file_that_appears_during_the_run_is_not_replaced(tmp_path, monkeypatch, links):
    """Without ``--overwrite`` a file is added with a hard link, which fails on a name
    that exists: a file created under one of the run's names after the check (by
    another program) is not replaced, and the run stops with one line naming it. On a
    file system without hard links (EPERM), a fresh check right before the rename."""
    from softbody.io import outputs

    if not links:

        def no_links(*args, **kwargs):
            raise OSError(errno.EPERM, "Operation not permitted")

        monkeypatch.setattr(outputs.os, "link", no_links)
        done = _commit(tmp_path / "other", {"x.txt": b"x", "m/y.txt": b"y"})
        assert snapshot(tmp_path / "other") == {"x.txt": b"x", "m/y.txt": b"y"}
        assert [p.name for p in done.written] == ["m", "x.txt"] and done.replaced == []
    out = tmp_path / "out"
    real = outputs.check_targets

    def then_a_file_appears(*args, **kwargs):
        result = real(*args, **kwargs)
        (out / "b.txt").write_bytes(b"another program's")
        return result

    monkeypatch.setattr(outputs, "check_targets", then_a_file_appears)
    with pytest.raises(outputs.OutputError, match="b.txt appeared while the run was writing"):
        _commit(out, {"a.txt": b"a", "b.txt": b"b"})
    assert (out / "b.txt").read_bytes() == b"another program's"
