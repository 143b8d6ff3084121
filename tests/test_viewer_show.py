"""``softbody.viewer.show`` from a script or a notebook (issue 29, item 2): it prints the
URL with its token, ``block=False`` returns a handle at once, and ``close()`` frees the
port. Reference: Jupyter's server prints its URL with the token; a closed server no
longer listens (its port can be bound again)."""

from __future__ import annotations

import http.client
import socket

import pytest

import softbody as sb

pytest.importorskip("viser")


def balloon() -> sb.Model:
    """A ball built in Python (no scene file) over a ground plane."""
    builder = sb.ModelBuilder()
    builder.add_soft_body(
        sb.icosphere(1, radius=0.3, center=(0.0, 0.5, 0.0)),
        mass=1.0, stiffness=400.0, damping=0.5, gas=300.0,
    )  # fmt: skip
    builder.add_collider(sb.ColliderPlane())
    return builder.finalize()


def status(port: int, path: str) -> int:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        conn.request("GET", path)
        return conn.getresponse().status
    finally:
        conn.close()


def listening(port: int) -> bool:
    """Whether something still listens on 127.0.0.1:port (a fresh bind fails)."""
    probe = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # TIME_WAIT is no listener
    try:
        probe.bind(("127.0.0.1", port))
        probe.listen(1)
        return False
    except OSError:
        return True
    finally:
        probe.close()


def test_show_prints_the_url_and_close_frees_the_port(capsys):
    """show(model, block=False) returns at once with a running viewer on loopback; it
    printed ``viewer.url``, which carries the token; the page answers 200 on that URL
    and 403 without the token; close() stops the server: the port can be bound again,
    and a second close() is harmless."""
    from softbody.viewer import show

    viewer = show(balloon(), port=0, block=False)
    try:
        printed = capsys.readouterr().out
        port = viewer.port
        token = viewer.url.partition("?token=")[2]
        assert viewer.url == f"http://127.0.0.1:{port}/?token={token}" and len(token) >= 32
        assert viewer.url in printed
        assert status(port, f"/?token={token}") == 200
        assert status(port, "/") == 403
        assert listening(port)
        assert viewer.url in viewer._repr_html_()
    finally:
        viewer.close()
    assert viewer.closed and not listening(port)
    viewer.close()
    assert "closed" in repr(viewer)


def test_show_quiet_prints_nothing_and_with_closes(capsys):
    """quiet=True prints nothing on start (viser itself says "Server stopped" when it
    stops); leaving a ``with`` block closes the viewer."""
    from softbody.viewer import show

    with show(balloon(), port=0, block=False, quiet=True) as viewer:
        port = viewer.port
        assert listening(port)
        assert capsys.readouterr().out == ""
    assert viewer.closed and not listening(port)


def test_a_script_that_forgets_close_exits_cleanly(tmp_path):
    """A script that starts a viewer with block=False and ends without close() exits at
    once with status 0, and the viewer is stopped on the way out: no nanobind "leaked
    instances" report of the objects its simulation thread still held."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    script = tmp_path / "script.py"
    script.write_text(
        "import softbody as sb\n"
        "from softbody.viewer import show\n"
        "b = sb.ModelBuilder()\n"
        "b.add_soft_body(sb.icosphere(1, radius=0.3, center=(0, 0.5, 0)), mass=1.0,\n"
        "                stiffness=400.0, damping=0.5, gas=300.0)\n"
        "viewer = show(b.finalize(), port=0, block=False)\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(Path(sb.__file__).parents[1]), os.environ.get("PYTHONPATH", "")])}  # fmt: skip
    proc = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=60, env=env
    )
    assert proc.returncode == 0, proc.stderr
    assert "?token=" in proc.stdout
    assert "leaked" not in proc.stderr, proc.stderr
