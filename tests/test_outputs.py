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

from softbody.io.outputs import MANIFEST

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
    ``meshes/`` (any existing folder named like an output). Now the run refuses, with
    one line naming the folder, and the project folder is unchanged."""
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
    before = snapshot(tmp_path)
    result = softbody(
        "run", "scene.toml", "--out", ".", "--meshes", "obj", "--duration", "0.01",
        "--no-video", "--no-gif", cwd=tmp_path,
    )  # fmt: skip
    one_error_line(result, "meshes exists and softbody did not write it")
    assert snapshot(tmp_path) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["meshes", "scene.toml"]


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
    assert MANIFEST in names and len(names) == 5
    assert all(not n.startswith(".") and "/" not in n and "\n" not in n for n in names)


def test_second_run_leaves_no_stale_outputs(tmp_path):
    """Issue 19 item 6: a second run with fewer outputs left the first run's GIF and
    ``meshes/`` beside its own summary. The folder now holds exactly the second run's
    files, listed in the manifest."""
    out = tmp_path / "out"
    first = softbody(
        "run", "hanging-ball", "--out", str(out), "--duration", "0.05", "--no-video",
        "--meshes", "ply", cwd=tmp_path,
    )  # fmt: skip
    assert first.returncode == 0, first.stderr
    assert (out / "hanging-ball.gif").is_file() and (out / "meshes/frame_00002.ply").is_file()
    second = softbody(
        "run", "hanging-ball", "--out", str(out), "--duration", "0.01", "--no-video",
        "--no-gif", cwd=tmp_path,
    )  # fmt: skip
    assert second.returncode == 0, second.stderr
    assert sorted(p.name for p in out.iterdir()) == [
        "hanging-ball-last-frame.png",
        "hanging-ball-plots.png",
        "hanging-ball-summary.json",
        MANIFEST,
    ]


@pytest.mark.parametrize("case", ["foreign", "edited", "foreign-in-meshes"])
def test_files_softbody_did_not_write_are_never_overwritten(tmp_path, case):
    """A user's file named like an output (``out/hanging-ball.gif`` not written by
    softbody), or one of ours the user has edited since, is never overwritten: the
    run stops with one line naming it, before writing anything. A user's file put in a
    ``meshes/`` folder that softbody wrote survives a run that drops the meshes."""
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
            (out / "meshes" / "notes.txt").write_text("my notes")
    before = snapshot(out)
    result = softbody(*args, cwd=tmp_path)
    if case == "foreign-in-meshes":
        assert result.returncode == 0, result.stderr
        assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*")) == [
            "hanging-ball-last-frame.png",
            "hanging-ball-plots.png",
            "hanging-ball-summary.json",
            "hanging-ball.gif",
            "meshes",
            "meshes/notes.txt",
            MANIFEST,
        ]
        assert (out / "meshes" / "notes.txt").read_text() == "my notes"
        return
    match = "did not write it" if case == "foreign" else "changed since softbody wrote it"
    one_error_line(result, match)
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
@pytest.mark.parametrize("signum,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_signal_removes_temporary_files_and_ffmpeg(tmp_path, signum, code):
    """Issue 19 item 6: SIGTERM left a hidden ``.softbody-run-*`` folder and an orphaned
    ffmpeg. A signal during a run (sent once the temporary folder and ffmpeg exist) now
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
        (("--duration", "10", "--max-frames", "100"), "304 frames"),
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
    with pytest.raises(OutputError, match="hanging-ball-plots.png exists"):
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


# --- symlinks below --out, interrupted commits, stale temporary folders --------------


def _commit(out: Path, files: dict[str, bytes]) -> list[Path]:
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
            return outputs.commit(tmp, out)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)


def _listed(out: Path) -> list[str]:
    """The paths the manifest in ``out`` lists."""
    return sorted(item["path"] for item in json.loads((out / MANIFEST).read_text())["files"])


def _forge_manifest(out: Path, files: dict[str, Path]) -> None:
    """Write a manifest in ``out`` (the format softbody has always written) listing each
    path with the size and hash of the file it names (``files``: listed path -> file)."""
    items = [
        {"path": rel, "size": len(data), "sha256": hashlib.sha256(data).hexdigest()}
        for rel, data in ((rel, f.read_bytes()) for rel, f in files.items())
    ]
    (out / MANIFEST).write_text(json.dumps({"format": "softbody-run/1", "files": items}))


def _quick_run(out: Path, **outputs) -> dict:
    """``run_scene`` of the hanging ball for 0.01 s (in this process), no video, no GIF."""
    from softbody.run import Outputs, run_scene
    from softbody.scenes import load_scene

    return run_scene(
        load_scene("hanging-ball"),
        out,
        duration=outputs.pop("duration", 0.01),
        outputs=Outputs(video=False, gif=False, **outputs),
    )


def test_meshes_moved_behind_a_link_are_not_deleted(tmp_path):
    """Review, defect 1a: after ``--meshes obj`` the user moved ``out/meshes`` away and
    left a link in its place (``mv out/meshes keep && ln -s keep out/meshes``); the next
    run without ``--meshes`` deleted every ``keep/frame_*.obj`` through the link (only
    the last path component was checked for a link). Files reached through a link below
    ``--out`` are not ours: nothing outside ``out`` is deleted, the link stays, and a run
    that would write meshes through it stops with one line before moving anything."""
    from softbody.io.outputs import OutputError

    out, keep = tmp_path / "out", tmp_path / "keep"
    _quick_run(out, meshes="obj", duration=0.05)
    assert len(list((out / "meshes").iterdir())) > 1
    (out / "meshes").rename(keep)
    (out / "meshes").symlink_to(keep, target_is_directory=True)
    kept = snapshot(keep)
    _quick_run(out)
    assert snapshot(keep) == kept
    assert (out / "meshes").is_symlink()
    assert _listed(out) == [
        "hanging-ball-last-frame.png",
        "hanging-ball-plots.png",
        "hanging-ball-summary.json",
    ]
    before = snapshot(out)
    with pytest.raises(OutputError, match="meshes is not a folder softbody wrote"):
        _quick_run(out, meshes="obj")
    assert snapshot(keep) == kept and snapshot(out) == before


@pytest.mark.parametrize("at", [True, False], ids=["dir_fd", "lstat-walk"])
@pytest.mark.parametrize("case", ["link", "deep-link", "link-write", "parent", "absolute"])
def test_forged_manifest_never_reaches_outside_out(tmp_path, monkeypatch, case, at):
    """Review, defect 1b: a downloaded project folder holding a link ``home -> ~`` and a
    forged ``softbody-run.json`` listing ``home/.bashrc`` with that file's hash made
    ``softbody run s.toml --out .`` delete ``~/.bashrc``. A manifest path through a
    link (at any depth) is not ours: it is neither deleted nor written through (a run
    writing there stops with one line); one naming ``../x`` or an absolute path makes
    the manifest not one softbody wrote. Checked with the ``dir_fd`` calls and with
    the lstat walk used where a platform lacks them."""
    from softbody.io import outputs

    monkeypatch.setattr(outputs, "_AT", at, raising=False)
    home, out = tmp_path / "home", tmp_path / "project"
    home.mkdir()
    out.mkdir()
    bashrc = home / ".bashrc"
    bashrc.write_text("export PATH=~/bin:$PATH\n")
    if case == "deep-link":
        (out / "a").mkdir()
        (out / "a" / "b").symlink_to(home, target_is_directory=True)
        listed = "a/b/.bashrc"
    else:
        (out / "home").symlink_to(home, target_is_directory=True)
        listed = {"parent": "../home/.bashrc", "absolute": str(bashrc)}.get(case, "home/.bashrc")
    _forge_manifest(out, {listed: bashrc})
    before = snapshot(tmp_path)
    files = {"s-summary.json": b"{}"}
    if case == "link-write":  # a new file in the folder the manifest says is ours
        files["home/run.sh"] = b"echo owned\n"
    match = {"link-write": "home is not a folder", "parent": "not a manifest softbody wrote"}
    match["absolute"] = match["parent"]
    if case in match:
        with pytest.raises(outputs.OutputError, match=match[case]):
            _commit(out, files)
        assert snapshot(tmp_path) == before
    else:
        _commit(out, files)
        assert _listed(out) == ["s-summary.json"]
    assert bashrc.read_text() == "export PATH=~/bin:$PATH\n"
    assert snapshot(home) == {".bashrc": bashrc.read_bytes()}


@pytest.mark.parametrize("step,call", [("move", 1), ("move", 2), ("move", 3), ("delete", 1),
                                       ("delete", 2)])  # fmt: skip
def test_interrupted_commit_is_recovered(tmp_path, monkeypatch, step, call):
    """Review, defect 2: the interim manifest written before the moves listed only the
    new hash of a path both runs write, so a commit stopped after some moves (a full
    disk, SIGKILL) left that path holding the old file under a manifest that did not
    accept it: every later run refused it as "changed since softbody wrote it", for
    good. The interim manifest now accepts the old or the new file there: whichever
    move or deletion the commit stops at, the next run accepts the folder and leaves
    exactly its own files."""
    from softbody.io import outputs

    out = tmp_path / "out"
    _commit(out, {"a.txt": b"a1", "b.txt": b"b1", "meshes/f0.obj": b"m1", "x.gif": b"g1"})
    real = {"move": os.replace, "delete": os.unlink}[step]
    calls = []

    def fail(src, *args, **kwargs):
        if not os.fspath(src).rpartition("/")[2].startswith("."):  # not the manifest
            calls.append(src)
            if len(calls) == call:
                raise OSError(errno.ENOSPC, "No space left on device")
        return real(src, *args, **kwargs)

    with monkeypatch.context() as m:
        m.setattr(outputs.os, "replace" if step == "move" else "unlink", fail)
        with pytest.raises(OSError, match="No space left"):
            _commit(out, {"a.txt": b"a2", "b.txt": b"b2", "c.txt": b"c2"})
    assert len(calls) == call
    # moved in order: a.txt, b.txt, c.txt
    assert (out / "b.txt").read_bytes() == (b"b1" if step == "move" and call <= 2 else b"b2")
    _commit(out, {"b.txt": b"b3", "d.txt": b"d3"})
    files = snapshot(out)
    assert files.pop(MANIFEST) and files == {"b.txt": b"b3", "d.txt": b"d3"}
    assert sorted(os.listdir(out)) == ["b.txt", "d.txt", MANIFEST]
    assert _listed(out) == ["b.txt", "d.txt"]


def test_stale_temporary_folder_is_removed(tmp_path):
    """Review, defect 3: a run killed with SIGKILL leaves its ``.softbody-run-*``
    temporary folder (frames, meshes) in ``--out`` for good. The next run, holding the
    folder lock (so no other run can be using it), removes such folders: only real
    folders named exactly as the run's ``tempfile.mkdtemp`` names them; a user's
    ``.softbody-run-notes`` folder or a link with a matching name stays, as does what
    the link points to."""
    out, elsewhere = tmp_path / "out", tmp_path / "elsewhere"
    stale = out / ".softbody-run-k3j_9x0q"
    (stale / "meshes").mkdir(parents=True)
    (stale / "meshes" / "frame_00000.obj").write_text("v 0 0 0\n")
    (stale / "hanging-ball.mp4").write_bytes(b"\0" * 1000)
    (out / ".softbody-run-notes").mkdir()
    (out / ".softbody-run-notes" / "n.txt").write_text("mine")
    elsewhere.mkdir()
    (elsewhere / "f.txt").write_text("mine too")
    (out / ".softbody-run-zzzzzzzz").symlink_to(elsewhere, target_is_directory=True)
    _quick_run(out)
    assert not os.path.lexists(stale)
    assert (out / ".softbody-run-notes" / "n.txt").read_text() == "mine"
    assert (out / ".softbody-run-zzzzzzzz").is_symlink()
    assert snapshot(elsewhere) == {"f.txt": b"mine too"}
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == [
        ".softbody-run-notes",
        ".softbody-run-zzzzzzzz",
    ]
