"""Who may use the viewer (issue 19, item 8; the ``--port`` hang of item 2).

A real viewer server on a free loopback port, asked with plain HTTP (http.client) and
the ``websockets`` client library, the way a web page in the user's browser (or a
DNS-rebinding page) would ask it. Reference: Jupyter's token, Origin and Host checks.
"""

from __future__ import annotations

import http.client
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

import softbody as sb
from conftest import free_port, start_viewer

pytest.importorskip("viser")

from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect


@pytest.fixture(scope="module")
def viewer():
    """The hanging-ball scene in a viewer on a free loopback port."""
    v = start_viewer()
    yield v
    v.stop()


def token_of(viewer) -> str:
    """The token as the user gets it: from the printed URL."""
    return viewer.url.partition("?token=")[2]


def get(port: int, path: str, headers: dict | None = None) -> http.client.HTTPResponse:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    conn.request("GET", path, headers=headers or {})
    response = conn.getresponse()
    response.body = response.read()
    conn.close()
    return response


def ws(viewer, query: str = "", origin: str | None = "own", cookie: str | None = None):
    """Open a websocket to the viewer as viser's page does (its subprotocol)."""
    import viser

    port = viewer.server.get_port()
    if origin == "own":
        origin = f"http://127.0.0.1:{port}"
    return connect(
        f"ws://127.0.0.1:{port}/{query}",
        origin=origin,
        subprotocols=[f"viser-v{viser.__version__}"],
        additional_headers={"Cookie": cookie} if cookie else None,
        open_timeout=10,
    )


def upgrade(port: int, path: str, headers: dict) -> int:
    """The status of a raw websocket upgrade request with these headers (Host, Origin
    can be anything here, unlike in a websocket client)."""
    import viser

    return get(
        port,
        path,
        {
            "Connection": "Upgrade",
            "Upgrade": "websocket",
            "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ==",
            "Sec-WebSocket-Version": "13",
            "Sec-WebSocket-Protocol": f"viser-v{viser.__version__}",
            **headers,
        },
    ).status


def test_url_carries_a_random_token(viewer):
    """The printed URL is http://127.0.0.1:PORT/?token=T with T long and random (two
    viewers never share one)."""
    from softbody.viewer.guard import Guard

    assert viewer.url.startswith(f"http://127.0.0.1:{viewer.server.get_port()}/?token=")
    assert len(token_of(viewer)) >= 32
    assert Guard(loopback=True).token != Guard(loopback=True).token


def test_page_needs_the_token(viewer):
    """Without the token, or with a wrong one, the page is refused (403, a short plain
    text reason); with it, the page is served and an HttpOnly, SameSite=Strict cookie
    named after the port is set; that cookie alone then serves the page."""
    port = viewer.server.get_port()
    for path in ("/", "/index.html", "/?token=wrong", "/?token="):
        response = get(port, path)
        assert response.status == 403, path
        assert b"token" in response.body
    ok = get(port, f"/?token={token_of(viewer)}")
    assert ok.status == 200 and ok.body
    cookie = ok.getheader("Set-Cookie")
    assert cookie.startswith(f"softbody-viewer-token-{port}={token_of(viewer)};")
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie and "Path=/" in cookie
    name_value = cookie.split(";", 1)[0]
    assert get(port, "/", {"Cookie": name_value}).status == 200
    assert get(port, "/", {"Cookie": f"softbody-viewer-token-{port}=wrong"}).status == 403


def test_host_header_must_name_this_server(viewer):
    """DNS rebinding: a page on evil.example whose name resolves to 127.0.0.1 sends
    Host: evil.example. Bound to loopback, only loopback names with this port pass,
    even with the right token."""
    port, token = viewer.server.get_port(), token_of(viewer)
    for host in (f"evil.example:{port}", "127.0.0.1", f"127.0.0.1:{port + 1}", "x:y:z"):
        assert get(port, f"/?token={token}", {"Host": host}).status == 403, host
    for host in (f"localhost:{port}", f"127.0.0.2:{port}", f"[::1]:{port}"):
        assert get(port, f"/?token={token}", {"Host": host}).status == 200, host


def refused(viewer, **kw) -> int:
    """The HTTP status a websocket handshake got refused with."""
    with pytest.raises(InvalidStatus) as info:
        ws(viewer, **kw).close()
    return info.value.response.status_code


def test_websocket_needs_token_and_own_origin(viewer):
    """Any web page can open a websocket to localhost; the handshake is refused without
    the token (cookie or ?token=), with a wrong one, from another Origin (even with the
    token), without an Origin, and with a foreign Host; with the token and the page's
    own Origin it opens."""
    port, token = viewer.server.get_port(), token_of(viewer)
    assert refused(viewer) == 403
    assert refused(viewer, query="?token=wrong") == 403
    assert refused(viewer, query=f"?token={token}", origin="http://evil.example") == 403
    assert refused(viewer, query=f"?token={token}", origin="null") == 403
    assert refused(viewer, query=f"?token={token}", origin=None) == 403
    assert refused(viewer, cookie=f"softbody-viewer-token-{port}=wrong") == 403
    rebinding = {"Host": f"evil.example:{port}", "Origin": f"http://evil.example:{port}"}
    assert upgrade(port, f"/?token={token}", rebinding) == 403
    own = {"Host": f"127.0.0.1:{port}", "Origin": f"http://127.0.0.1:{port}"}
    assert upgrade(port, f"/?token={token}", own) == 101  # the same request, own host
    # with the token (on the URL, or as the page's cookie) and the page's own Origin,
    # the websocket opens and viser's stream of scene messages arrives
    with ws(viewer, query=f"?token={token}") as conn:
        assert len(conn.recv(timeout=10)) > 16
    with ws(viewer, cookie=f"softbody-viewer-token-{port}={token}") as conn:
        assert len(conn.recv(timeout=10)) > 16


def test_share_tunnel_is_off(viewer):
    """viser's page has a Share button that makes the server open a tunnel to an
    outside relay (share.viser.studio), publishing the viewer on the internet: the
    server no longer listens to that request."""
    from viser import _messages

    handlers = viewer.server._websock_server._incoming_handlers
    assert _messages.ShareUrlRequest not in handlers


def test_library_refuses_a_port_out_of_range_promptly():
    """show(port=99999): viser's server thread died on it (OverflowError) and the caller
    waited forever; now a ValueError naming the port, at once."""
    from softbody.scenes import load_scene
    from softbody.viewer.app import show

    scene = load_scene("hanging-ball")
    sim = sb.Simulator(scene.model, integrator=scene.integrator, dt=scene.dt)
    outcome: list = []

    def attempt():
        try:
            show(scene.model, scene.model.state(), sim, port=99999, block=False).stop()
            outcome.append("started")
        except Exception as exc:
            outcome.append(exc)

    thread = threading.Thread(target=attempt, daemon=True)
    thread.start()
    thread.join(timeout=60)
    assert outcome, "show(port=99999) hung"
    assert isinstance(outcome[0], ValueError) and "99999" in str(outcome[0])


def run_cli(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "softbody.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def test_cli_port_out_of_range_is_a_one_line_error():
    """``softbody view bouncing-balls --port 99999`` hung; now argparse refuses it at
    once: non-zero exit, its last stderr line names --port and the range, no
    traceback."""
    for port in ("99999", "-1", "http"):
        result = run_cli("view", "bouncing-balls", "--port", port)
        assert result.returncode == 2, result.stderr
        last = result.stderr.strip().splitlines()[-1]
        assert last.startswith("softbody view: error: argument --port:"), last
        assert "Traceback" not in result.stderr


def test_cli_warns_when_reachable_from_the_network():
    """``--host 0.0.0.0`` binds every interface: one warning line on stderr says the
    viewer is reachable from the network (the token still guards it). The process is
    stopped with Ctrl-C (SIGINT) as soon as it prints its URL; no traffic is sent."""
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "softbody.cli",
            "view",
            "hanging-ball",
            "--host",
            "0.0.0.0",
            "--port",
            str(free_port()),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    lines = []
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            if "in a browser" in line:  # the URL line
                break
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            _, err = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            _, err = proc.communicate()
    assert any("?token=" in line for line in lines), "".join(lines) + err
    warnings = [line for line in err.splitlines() if line.startswith("softbody: warning:")]
    assert len(warnings) == 1 and "reachable from the network" in warnings[0], err
    assert "Traceback" not in err


def test_a_start_that_times_out_never_serves_later():
    """If viser's server is not bound within the timeout, ``start_guarded`` gives up; a
    build that reaches viser's ``serve`` call after that must meet the guard's refusing
    proxy, not the real ``websockets`` module (which would serve with no checks), and
    viser's module gets its real ``websockets`` back once that build has ended."""
    import viser.infra._infra as infra
    import websockets

    from softbody.viewer.guard import Guard, start_guarded

    late_call: dict = {}

    def slow_factory():
        time.sleep(0.6)  # past the 0.2 s timeout below
        try:
            infra.websockets.asyncio.server.serve(None, "127.0.0.1", 0, process_request=None)
        except RuntimeError as exc:
            late_call["refused"] = str(exc)
        return None

    guard = Guard(loopback=True)
    with pytest.raises(RuntimeError, match="did not start within"):
        start_guarded(slow_factory, guard, timeout=0.2)
    deadline = time.monotonic() + 10
    while infra.websockets is not websockets and time.monotonic() < deadline:
        time.sleep(0.05)
    assert "abandoned" in late_call.get("refused", "")
    assert infra.websockets is websockets


def test_default_port_may_be_left_out_of_host():
    """On port 80 a browser sends ``Host: localhost`` with no port (the scheme's default):
    the Host check takes that as port 80 there, and as a mismatch on any other port."""
    from types import SimpleNamespace

    from websockets.datastructures import Headers

    from softbody.viewer.guard import Guard

    guard = Guard(loopback=True)

    def status(port: int) -> int | None:
        connection = SimpleNamespace(
            local_address=("127.0.0.1", port), respond=lambda code, text: int(code)
        )
        request = SimpleNamespace(path=f"/?token={guard.token}", headers=Headers(Host="localhost"))
        return guard.check(connection, request)[0]

    assert status(80) is None  # served
    assert status(8080) == 403
