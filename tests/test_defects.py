"""Issue 29 item 17, smaller defects: each is now a one-line error (naming the key, the
file or the port) or works, and never a traceback, garbage output or a silent no-op."""

from __future__ import annotations

import json
import math
import re
import tomllib

import numpy as np
import pytest

from softbody.cli import main
from softbody.scenes import SceneError, load_scene

#: a short, small scene for runs that must get as far as writing files
SMALL = """\
name = "small"
[simulation]
integrator = "velocity_verlet"
dt = 0.001
duration = 0.05
[render]
width = 32
height = 24
[[bodies]]
mesh = { shape = "icosphere", subdivisions = 1, radius = 0.5 }
position = [0.0, 1.0, 0.0]
mass = 1.0
stiffness = 30.0
gas = 1.0
"""


def _cli(argv: list[str], capsys) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def _one_error_line(err: str) -> str:
    """The single ``softbody: error: ...`` line of stderr (nothing else on it)."""
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("softbody: error: "), err
    return lines[0]


# -- 2 and 11: derived quantities beyond float64, standard JSON ---------------------------
@pytest.mark.parametrize(
    "override,match",
    [
        # 1e308 kg: infinite gravitational energy in the summary (``Infinity``, not JSON)
        ("bodies.0.mass=1e308", r"^bodies\.0\.mass: 1e\+308 kg over 162 particles"),
        # 1e-308 kg: denormal particle masses, LAPACK's DLASCL lines in the estimate
        ("bodies.0.mass=1e-308", r"^bodies\.0\.mass: 1e-308 kg over 162 particles"),
        ("bodies.1.velocity=[0, 1e200, 0]", r"^bodies\.1: the initial kinetic energy"),
        ("simulation.gravity=[0, -1e300, 0]", r"^bodies\.0: the initial gravitational energy"),
        ("bodies.2.gas.nrt=1e300", r"^bodies\.2: the initial gas energy .* bodies\.2\.gas$"),
    ],
)
def test_values_whose_derived_quantities_overflow_are_refused(override, match):
    """Reference: float64's normal range (about 1e-308 to 1e308). A particle mass or an
    initial energy whose square or reciprocal leaves it (outside 1e-150 to 1e150) is
    refused when the scene is loaded, before any run or LAPACK call, naming the key.
    Before, ``mass = 1e308`` ran and wrote ``Infinity`` into the summary and 1e-308
    failed in the eigenvalue solver."""
    with pytest.raises(SceneError, match=match):
        load_scene("hanging-ball", [override])


def test_tiny_mass_is_one_line_without_lapack_chatter(tmp_path, capfd):
    """``mass = 1e-308`` on the command line: one error line naming the key, nothing else
    on stderr or stdout (no numpy overflow warning, no LAPACK "DLASCL" lines)."""
    code = main(["run", "hanging-ball", "--out", str(tmp_path), "--set", "bodies.0.mass=1e-308"])
    out, err = capfd.readouterr()
    assert code == 2
    assert "bodies.0.mass" in _one_error_line(err)
    assert "DLASCL" not in out + err and not list(tmp_path.iterdir())


def test_summary_is_standard_json_with_null_for_non_finite():
    """Reference: RFC 8259 has no NaN or Infinity. The summary writer maps them to null
    (nested in tables and lists) and writes with ``allow_nan=False``."""
    from softbody.run import _finite_or_null

    summary = {"a": math.inf, "b": [1.0, np.float64(-np.inf), {"c": math.nan}], "d": "x"}
    clean = _finite_or_null(summary)
    assert clean == {"a": None, "b": [1.0, None, {"c": None}], "d": "x"}
    text = json.dumps(clean, allow_nan=False)

    def refuse(name):
        raise AssertionError(f"non-standard JSON constant {name}")

    assert json.loads(text, parse_constant=refuse) == clean


def test_a_run_summary_parses_as_strict_json(tmp_path, capsys):
    """A run's summary parses with every non-standard constant refused."""
    scene = tmp_path / "small.toml"
    scene.write_text(SMALL)
    out = tmp_path / "out"
    code, _, err = _cli(["run", str(scene), "--out", str(out), "--no-video", "--no-gif"], capsys)
    assert code == 0, err

    def refuse(name):
        raise AssertionError(f"non-standard JSON constant {name}")

    summary = json.loads((out / "small-summary.json").read_text(), parse_constant=refuse)
    assert summary["frames"] == 3


def test_plots_draw_infinite_and_overflowing_series(tmp_path):
    """Reference: matplotlib cannot scale an axis spanning -1e308 to 1e308 or infinity
    ("arange: cannot compute length" after the whole run, before). Such values are left
    out of the lines as gaps and the figure is written."""
    from softbody.render.plots import plot_bounding_volumes, plot_time_series

    t = np.linspace(0.0, 1.0, 4)
    big = np.array([1.0, 1e308, np.inf, 2.0])
    series = {
        "volume": np.ones((4, 1)),
        "pressure": np.ones((4, 1)),
        "kinetic": big[:, None],
        "total": np.array([1e308, -1e308, 1.0, np.inf]),
    }
    plot_time_series(tmp_path / "p.png", t, series, ["a"], "x")
    volumes = {m: big for m in ("exact", "bounding_box")}
    plot_bounding_volumes(tmp_path / "b.png", t, volumes, "a")
    assert (tmp_path / "p.png").stat().st_size > 0 and (tmp_path / "b.png").stat().st_size > 0


# -- 1: nesting bounded before the TOML parser, 6: a byte order mark -----------------------
def test_dotted_key_50000_deep_is_refused_in_bounded_memory(tmp_path):
    """A 100 KB scene file holding one dotted key of 50,000 parts took over 8 GB in
    Python's TOML parser (memory quadratic in the key's length). It is refused before
    parsing, naming the file and line, in a child limited to 2 GiB of address space
    (a regression fails there with a MemoryError instead of taking the machine down)."""
    import resource
    import subprocess
    import sys

    path = tmp_path / "deep.toml"
    path.write_text('name = "deep"\n' + ".".join(["a"] * 50_000) + " = 1\n")
    assert path.stat().st_size > 99_000

    def limit_memory():
        resource.setrlimit(resource.RLIMIT_AS, (2 * 1024**3, 2 * 1024**3))

    result = subprocess.run(
        [sys.executable, "-m", "softbody.cli", "run", str(path), "--out", str(tmp_path / "o")],
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=limit_memory,
    )
    assert result.returncode == 2, result.stderr[-2000:]
    assert result.stderr == (
        f"softbody: error: {path}: line 2: a dotted key of more than 64 parts "
        "(a scene needs a few)\n"
    )


@pytest.mark.parametrize(
    "text,what",
    [
        ("x = " + "[" * 5000 + "]" * 5000, "arrays or tables nested more than 64 deep"),
        ("x = " + "{a = " * 5000 + "1" + "}" * 5000, "arrays or tables nested more than 64 deep"),
        ('"q".' * 65 + "z = 1", "a dotted key of more than 64 parts"),
    ],
)
def test_deep_arrays_tables_and_quoted_keys_are_one_line(tmp_path, text, what):
    """Nested arrays or inline tables 5,000 deep raised RecursionError inside the parser
    (a message naming no file); quoted key parts count as parts. Each is refused with
    the file, the line and the reason."""
    path = tmp_path / "s.toml"
    path.write_text("# a comment [[[[ with brackets and a.b.c.d dots\n" + text + "\n")
    with pytest.raises(SceneError, match=f"^{path}: line 2: {re.escape(what)}"):
        load_scene(path)


def test_nesting_guard_leaves_ordinary_toml_alone():
    """Reference: the TOML spec's examples. Floats (``1.5`` reads like a 2-part key),
    dates, dots and brackets inside strings (one line, multi-line, literal) and comments,
    and a 64-part key parse as before."""
    from softbody.scenes.loader import parse_toml

    text = (
        "a = [1.5, 2.5, 3.5, 4.5]\nd = 1979-05-27T07:32:00.999\n"
        's = "' + "x." * 500 + '[[[["\n'
        "m = '''\n" + "{" * 200 + "\n'''\n"
        "# " + "[" * 200 + "\n" + ".".join(["k"] * 64) + " = 1\n"
    )
    data = parse_toml(text, "t")
    assert data["a"] == [1.5, 2.5, 3.5, 4.5] and data["s"].endswith("[[[[")
    node = data
    for _ in range(63):
        node = node["k"]
    assert node == {"k": 1}


def test_deep_override_is_refused():
    """``--set`` values are TOML too: an array 1,000 deep is refused naming the key."""
    with pytest.raises(SceneError, match=r"^override 'bodies.0.position': line 1: arrays"):
        load_scene("hanging-ball", ["bodies.0.position=" + "[" * 1000])


def test_scene_file_with_a_byte_order_mark_loads(tmp_path):
    """Reference: TOML is UTF-8 and a BOM is no character of the document (Windows
    editors write one). A scene file starting with EF BB BF was "not valid TOML"; it
    loads as the same file without it."""
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + SMALL.encode())
    assert load_scene(path).name == "small"
    assert load_scene(path).data == tomllib.loads(SMALL)


def test_sweep_file_with_a_byte_order_mark_is_a_sweep_file(tmp_path):
    """A sweep file with a BOM is still recognised as one (it was taken for a scene)."""
    from softbody.sweep.spec import is_sweep_file

    path = tmp_path / "sweep.toml"
    path.write_bytes(b'\xef\xbb\xbfscene = "hanging-ball"\n[vary]\n"bodies.0.mass" = [1, 2]\n')
    assert is_sweep_file(path)


# -- 5: a directory or a FIFO where a file goes --------------------------------------------
def _special(tmp_path, kind: str, name: str):
    import os

    path = tmp_path / name
    if kind == "directory":
        path.mkdir()
        return path, "is a directory, not a file"
    os.mkfifo(path)
    return path, r"not a regular file \(a FIFO\)"


@pytest.mark.parametrize("kind", ["directory", "fifo"])
@pytest.mark.parametrize("name", ["scene.toml", "scene"])
def test_scene_path_that_is_a_directory_or_fifo_says_so(tmp_path, capsys, kind, name):
    """A scene path that is a directory or a FIFO said "no such scene file". It now says
    what it is, and a FIFO is never opened (the command returns; a read would block)."""
    path, what = _special(tmp_path, kind, name)
    code, _, err = _cli(["run", str(path), "--out", str(tmp_path / "o")], capsys)
    assert code == 2
    assert re.fullmatch(f"softbody: error: {re.escape(str(path))}: {what}", _one_error_line(err))


@pytest.mark.parametrize("kind", ["directory", "fifo"])
def test_mesh_and_info_path_that_is_a_directory_or_fifo_says_so(tmp_path, capsys, kind):
    """The same for ``softbody info`` and a scene's mesh file."""
    path, what = _special(tmp_path, kind, "mesh.obj")
    code, _, err = _cli(["info", str(path)], capsys)
    assert code == 2
    assert re.fullmatch(f"softbody: error: {re.escape(str(path))}: {what}", _one_error_line(err))
    scene = tmp_path / "s.toml"
    scene.write_text(
        SMALL.replace('shape = "icosphere", subdivisions = 1, radius = 0.5', 'file = "mesh.obj"')
    )
    with pytest.raises(ValueError, match=f": {re.escape(str(path))}: {what}$"):
        load_scene(scene)


# -- 4: an empty --out ----------------------------------------------------------------------
@pytest.mark.parametrize("command", ["run", "sweep"])
def test_empty_out_is_refused(tmp_path, monkeypatch, capsys, command):
    """``--out ""`` (an unset shell variable) wrote into the current folder silently. It
    is refused with one line, and nothing is written in the current folder."""
    monkeypatch.chdir(tmp_path)
    scene = tmp_path / "small.toml"
    scene.write_text(SMALL)
    extra = ["--vary", "bodies.0.mass=1,2", "--workers", "0"] if command == "sweep" else []
    code, _, err = _cli([command, str(scene), "--out", "", *extra], capsys)
    assert code == 2
    assert _one_error_line(err) == (
        "softbody: error: --out '' names no folder; give one (--out . for the current folder)"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["small.toml"]


# -- 7, 8, 9: keys that passed the schema and then failed or did nothing --------------------
@pytest.mark.parametrize(
    "override,expected",
    [
        ("render.width=8000", "render.width: must be <= 4096, got 8000"),
        ("render.height=4097", "render.height: must be <= 4096, got 4097"),
        (
            "render.camera=[2.0, 0.8, 0.0]",
            "render.camera: must differ from render.target (the camera looks from camera to "
            "target; at the target it sees no direction and draws blank frames)",
        ),
        (
            "bodies.0.rotation=[0, 0, 0, 45]",
            "bodies.0.rotation: the axis (its first 3 numbers) must not be zero, got [0, 0, 0, 45]",
        ),
    ],
)
def test_render_size_camera_and_rotation_axis_are_checked(override, expected):
    """``render.width = 8000`` passed the schema (<= 16384) and then failed in the
    renderer (<= 4096) without naming the key; a camera at its target (hanging-ball's is
    [2, 0.8, 0]) rendered blank frames; a rotation about a zero axis was ignored. Each is
    now refused by the schema naming the key."""
    with pytest.raises(SceneError) as info:
        load_scene("hanging-ball", [override])
    assert str(info.value) == expected


def test_rotation_with_zero_angle_and_collider_rotation():
    """A zero axis with a zero angle turns nothing and is accepted; a box collider's
    rotation is checked the same way."""
    assert load_scene("hanging-ball", ["bodies.0.rotation=[0, 0, 0, 0]"])
    with pytest.raises(SceneError, match=r"^colliders\.0\.rotation: the axis"):
        load_scene(
            "hanging-ball",
            ['colliders.0={type="box", half_extents=[1, 1, 1], rotation=[0, 0, 0, 10]}'],
        )


def test_camera_at_its_target_is_an_error_for_the_library():
    """Reference: a look-at basis needs eye != target. ``Camera.basis`` raises instead of
    returning NaN (the blank frames)."""
    from softbody.render.raster import Camera

    with pytest.raises(ValueError, match=r"eye and target are both at \(1.0, 2.0, 3.0\)"):
        Camera(eye=(1.0, 2.0, 3.0), target=(1.0, 2.0, 3.0)).basis()


# -- 3 and 13: the viewer's port and exit status -------------------------------------------
def test_view_on_a_taken_last_port_is_one_line(capsys):
    """``softbody view --port 65535`` with that port taken printed viser's 25-line
    traceback (it moves on to the next port, 65536, and its server thread dies). Now:
    one line naming the port, status 2."""
    import socket

    pytest.importorskip("viser")
    holder = socket.socket()
    try:
        try:
            holder.bind(("127.0.0.1", 65535))
            holder.listen()
        except OSError:
            pass  # taken already, by another program: the case under test all the same
        code, _, err = _cli(["view", "hanging-ball", "--port", "65535"], capsys)
    finally:
        holder.close()
    assert code == 2
    assert _one_error_line(err) == (
        "softbody: error: viewer port 65535 is taken on 127.0.0.1; choose another with "
        "--port (0: any free one)"
    )


def test_taken_port_moves_to_the_next_free_one():
    """A taken port that is not the last still moves on to the next free one, as
    viser does (``--port``'s help promises it)."""
    import socket

    from softbody.viewer.app import _free_port

    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        taken = holder.getsockname()[1]
        if taken == 65535:
            pytest.skip("the system gave the last port")
        assert _free_port("127.0.0.1", taken) > taken
    assert _free_port("127.0.0.1", 0) == 0


@pytest.mark.parametrize("signum,code", [("SIGINT", 130), ("SIGTERM", 143)])
def test_view_exits_with_the_signal_status(tmp_path, signum, code):
    """The CLI promises 128 + the signal's number on Ctrl-C and SIGTERM; ``softbody
    view`` exited 0 (its wait took the signal as the end). It is stopped a second after
    it has printed its URL."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from conftest import free_port

    pytest.importorskip("viser")
    number = getattr(signal, signum)
    proc = subprocess.Popen(
        [sys.executable, "-m", "softbody.cli", "view", "hanging-ball", "--port",
         str(free_port())],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 300
        started = False
        while time.monotonic() < deadline and not started:
            line = proc.stdout.readline()
            if not line:
                break
            started = "in a browser" in line
        assert started, "the viewer did not start"
        time.sleep(1.0)  # into its wait for the signal (not between the print and it)
        proc.send_signal(number)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == code, err
    assert err.splitlines()[-1] == f"softbody: interrupted ({signum})"
    assert "Traceback" not in err


# -- 10: numbers in messages -----------------------------------------------------------------
@pytest.mark.parametrize(
    "argv,expected",
    [
        (
            ["--duration", "1e300"],
            "softbody: error: the run would render 3e+301 frames (1e+300 s at 30 frames per "
            "second), over the limit of 100,000: shorten the duration or lower render.fps (or "
            "raise the limit with --max-frames)",
        ),
        (
            ["--dt", "1e-300", "--max-frames", "9e18"],
            "softbody: error: the run would take 5e+300 steps (150 frames of 3.33e+298 steps "
            "of dt = 1e-300 s), over the limit of 100,000,000: raise dt or render.fps, or "
            "shorten the duration (or raise the limit with --max-steps)",
        ),
    ],
)
def test_absurd_counts_print_compactly(tmp_path, capsys, argv, expected):
    """``--duration 1e300`` printed a 300-digit frame count. Counts past 10^15 are now
    written as 3 significant digits (smaller ones in full, with separators), so the line
    stays readable; hanging-ball is 5 s at 30 fps."""
    code, _, err = _cli(["run", "hanging-ball", "--out", str(tmp_path / "o"), *argv], capsys)
    assert code == 2
    assert _one_error_line(err) == expected


# -- 14: malformed websocket frames from a client holding the token ------------------------
def test_malformed_websocket_frames_are_one_line_each(capfd):
    """An authorised client (token, own Origin) sending frames viser cannot read (not
    msgpack, a text frame, an unknown message type, missing fields, not a table) made
    the websockets library print a traceback for each. Now each closes that client's
    connection with one line on stderr; the simulation and the server go on (a new
    client still connects)."""
    import time

    import msgspec

    pytest.importorskip("viser")
    from conftest import start_viewer
    from test_viewer_input import Client

    viewer = start_viewer()
    try:
        capfd.readouterr()
        frames = [
            b"\x00\x01garbage",
            "hello",
            msgspec.msgpack.encode({"type": "NoSuchMessage", "x": 1}),
            msgspec.msgpack.encode({"type": "ViewerCameraMessage", "wxyz": "x"}),
            msgspec.msgpack.encode([1, 2, 3]),
        ]
        for frame in frames:
            client = Client(viewer)
            client.conn.send(frame)
            deadline = time.monotonic() + 10
            while viewer.guard.malformed < frames.index(frame) + 1:
                assert time.monotonic() < deadline, "the bad frame was not noticed"
                time.sleep(0.05)
            client.close()
        time.sleep(0.3)
        err = capfd.readouterr().err
        assert viewer._thread.is_alive()
        Client(viewer).close()  # the server still takes clients
    finally:
        viewer.stop()
    lines = err.splitlines()
    assert "Traceback" not in err and len(lines) == len(frames), err
    assert all(
        line.startswith("softbody view: closed a connection that sent a malformed message (")
        for line in lines
    ), err
