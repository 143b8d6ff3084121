"""Who may use the viewer: a token, an Origin check and a Host check (as Jupyter does).

viser (the page and websocket server) has no hook for authentication, so the guard is
put in front of its HTTP handler: while one ``viser.ViserServer`` is being built, the
name ``websockets`` in ``viser.infra._infra`` (and only there) is replaced by a proxy
whose ``asyncio.server.serve`` runs :meth:`Guard.check` before viser's own
``process_request``. The proxy is removed again as soon as the server is bound. If the
hook is not reached (viser's internals changed), :func:`start_guarded` stops the server
and refuses to go on: the viewer never serves unprotected.

Rules, per request (the page, its assets and the websocket upgrade alike):

- Host: bound to a loopback address, only ``localhost``, ``127.x.x.x`` and ``[::1]`` with
  the bound port are accepted (a DNS-rebinding page names its own host).
- Page: ``?token=`` equal to the token (constant-time compare) serves the page and sets
  an HttpOnly, SameSite=Strict cookie (its name carries the port: cookies ignore ports);
  a valid cookie serves it; anything else is 403.
- Websocket: the ``Origin`` header must be the server's own origin (``http://`` + Host)
  and the token must come as the cookie or as ``?token=`` on the websocket URL.
"""

from __future__ import annotations

import contextlib
import hmac
import http
import http.cookies
import ipaddress
import secrets
import socket
import sys
import threading
import warnings
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import parse_qs, urlsplit

#: viser versions whose internals the hook was checked against (see pyproject.toml).
VISER_TESTED = ((1, 1), (1, 2))
#: Seconds to wait for viser's server thread to bind before giving up.
START_TIMEOUT = 30.0

_BUILD_LOCK = threading.Lock()


def is_loopback(host: str) -> bool:
    """True if every address ``host`` names is a loopback one (127/8, ::1).

    ``0.0.0.0``, ``::`` and LAN addresses are not; a name that does not resolve is not.
    """
    name = host.strip("[]")
    if name.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        pass
    try:
        infos = socket.getaddrinfo(name, None)
    except OSError:
        return False
    return bool(infos) and all(ipaddress.ip_address(i[4][0]).is_loopback for i in infos)


def _split_host(value: str) -> tuple[str, int | None] | None:
    """(name, port) of a Host header value, or None if it is malformed."""
    try:
        parts = urlsplit("//" + value)
        return (parts.hostname or "", parts.port)
    except ValueError:
        return None


def _loopback_name(name: str) -> bool:
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


@dataclass
class Guard:
    """The token and the checks of one viewer server.

    ``loopback``: the server is bound to a loopback address, so the Host header must name
    one too. ``hooked`` is set once viser's server was started through the guard.
    """

    loopback: bool
    token: str = field(default_factory=lambda: secrets.token_urlsafe(32))
    hooked: bool = False
    server_thread: threading.Thread | None = None
    abandoned: bool = False
    """Set when :func:`start_guarded` gave up: a late start is refused."""
    refused: int = 0
    malformed: int = 0
    """Connections closed because their client sent a message viser could not read."""

    def handle_messages(self, inner: Any) -> Any:
        """viser's websocket handler ``inner``, wrapped: a message it cannot read (not
        msgpack, a text frame, an unknown type, missing fields) ends that client's
        connection with one line on stderr instead of the websockets library's traceback;
        the server and the other clients go on."""

        async def handler(connection: Any) -> None:
            try:
                await inner(connection)
            except Exception as exc:  # what viser raised reading the client's message
                self.malformed += 1
                text = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
                reason = " ".join(text.split())
                reason = reason if len(reason) <= 200 else reason[:197] + "..."
                print(
                    f"softbody view: closed a connection that sent a malformed message "
                    f"({reason})",
                    file=sys.stderr,
                    flush=True,
                )
                with contextlib.suppress(Exception):
                    await connection.close(1007, "malformed message")

        return handler

    def cookie_name(self, port: int) -> str:
        return f"softbody-viewer-token-{port}"

    def _valid(self, candidate: str | None) -> bool:
        if not candidate:
            return False
        return hmac.compare_digest(candidate.encode("utf-8", "replace"), self.token.encode())

    def _cookie_token(self, headers: Any, port: int) -> str | None:
        jar = http.cookies.SimpleCookie()
        for value in headers.get_all("Cookie"):
            with contextlib.suppress(http.cookies.CookieError):
                jar.load(value)
        morsel = jar.get(self.cookie_name(port))
        return morsel.value if morsel is not None else None

    def check(self, connection: Any, request: Any) -> tuple[Any, str | None]:
        """(a 403 response or None, the Set-Cookie value to add to the page or None)."""
        headers = request.headers
        port = int(connection.local_address[1])
        try:
            host = headers["Host"]
        except KeyError:
            return self._refuse(connection, "missing Host header"), None
        except Exception:  # several Host headers
            return self._refuse(connection, "more than one Host header"), None
        split = _split_host(host)
        if split is None:
            return self._refuse(connection, "malformed Host header"), None
        name, host_port = split
        if host_port is None and port == 80:
            host_port = 80  # browsers leave the default port out of Host
        if self.loopback and not (_loopback_name(name) and host_port == port):
            return self._refuse(connection, f"Host {host!r} is not this server"), None
        query = parse_qs(urlsplit(request.path).query)
        url_token = query.get("token", [None])[0]
        cookie_token = self._cookie_token(headers, port)
        authorized = self._valid(url_token) or self._valid(cookie_token)
        upgrade = "websocket" in headers.get("Upgrade", "").lower()
        if upgrade:
            origin = headers.get("Origin", "")
            if origin.lower() != f"http://{host}".lower():
                return self._refuse(connection, f"Origin {origin!r} is not this server"), None
            if not authorized:
                return self._refuse(connection, "missing or wrong token"), None
            return None, None
        if not authorized:
            return self._refuse(
                connection, "missing or wrong token: open the URL that softbody view printed"
            ), None
        cookie = None
        if self._valid(url_token):
            cookie = f"{self.cookie_name(port)}={self.token}; Path=/; HttpOnly; SameSite=Strict"
        return None, cookie

    def _refuse(self, connection: Any, reason: str) -> Any:
        self.refused += 1
        return connection.respond(http.HTTPStatus.FORBIDDEN, f"softbody viewer: {reason}\n")

    def process_request(self, viser_handler: Any):
        """viser's ``process_request`` with the checks run first."""

        def guarded(connection, request):
            refusal, cookie = self.check(connection, request)
            if refusal is not None:
                return refusal
            response = viser_handler(connection, request) if viser_handler else None
            if response is not None and cookie is not None:
                response.headers["Set-Cookie"] = cookie
            return response

        return guarded


class _Namespace:
    """A stand-in for a module: ``overrides`` first, then the real module's names."""

    def __init__(self, real: Any, **overrides: Any):
        self._real = real
        self.__dict__.update(overrides)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._real, name)


def _websockets_proxy(real: Any, guard: Guard) -> _Namespace:
    """``websockets`` as viser's module sees it, with ``asyncio.server.serve`` guarded."""
    real_serve = real.asyncio.server.serve

    def serve(*args: Any, **kwargs: Any) -> Any:
        if guard.abandoned:  # start_guarded gave up waiting: never serve after that
            raise RuntimeError("the viewer's start was abandoned; not serving")
        if "process_request" not in kwargs:
            raise RuntimeError("viser's serve call changed: process_request is not passed")
        kwargs["process_request"] = guard.process_request(kwargs["process_request"])
        if not args or not callable(args[0]):
            raise RuntimeError("viser's serve call changed: the handler is not passed first")
        args = (guard.handle_messages(args[0]), *args[1:])
        guard.hooked = True
        guard.server_thread = threading.current_thread()
        return real_serve(*args, **kwargs)

    server = _Namespace(real.asyncio.server, serve=serve)
    return _Namespace(real, asyncio=_Namespace(real.asyncio, server=server))


def check_viser() -> Any:
    """viser's infra module, after checking that the guard's hook fits this version."""
    import viser
    import viser.infra._infra as infra
    import websockets

    try:
        version = tuple(int(x) for x in viser.__version__.split(".")[:2])
    except ValueError:
        version = (0, 0)
    low, high = VISER_TESTED
    if not (low <= version < high) or getattr(infra, "websockets", None) is not websockets:
        raise RuntimeError(
            f"viser {viser.__version__} is not a version the viewer's access checks support "
            f"(viser >= {low[0]}.{low[1]}, < {high[0]}.{high[1]}); not starting it unprotected"
        )
    return infra


def start_guarded(factory: Any, guard: Guard, timeout: float = START_TIMEOUT) -> Any:
    """Build a viser server with ``factory()`` behind ``guard``; return it.

    Raises RuntimeError if viser's server thread dies or does not bind within
    ``timeout`` seconds (viser itself would wait forever), or if the guard was not
    installed on the server's request path.
    """
    infra = check_viser()
    # viser warns, with a source line, of each client value that does not match its
    # message's types; the viewer checks every value it uses and says so in one line
    warnings.filterwarnings(
        "ignore", message=r"\[viser\] .* does not match annotation", category=UserWarning
    )
    result: dict[str, Any] = {}
    done = threading.Event()

    def build() -> None:
        try:
            result["server"] = factory()
        except BaseException as exc:  # reported to the caller below
            result["error"] = exc
        finally:
            done.set()

    def clean_up_late(real: Any) -> None:
        # the proxy stays in viser's module until the abandoned build ends (a late serve
        # call must meet the refusing proxy, not the real module), then goes
        done.wait()
        with _BUILD_LOCK:
            infra.websockets = real
        if result.get("server") is not None:
            result["server"].stop()

    with _BUILD_LOCK:
        real = infra.websockets
        infra.websockets = _websockets_proxy(real, guard)
        try:
            threading.Thread(target=build, name="softbody-viewer-start", daemon=True).start()
            waited = 0.0
            while not done.wait(0.05):
                waited += 0.05
                thread = guard.server_thread
                # viser's server thread died (e.g. it could not bind), and viser waits for
                # it forever: give up now instead
                dead = thread is not None and not thread.is_alive()
                if dead or waited >= timeout:
                    if not dead:  # the build may still reach viser's serve call
                        guard.abandoned = True
                        threading.Thread(target=clean_up_late, args=(real,), daemon=True).start()
                    raise RuntimeError(
                        "the viewer's server did not start"
                        + (" (its thread stopped)" if dead else f" within {timeout:.0f} s")
                    )
        finally:
            if not guard.abandoned:
                infra.websockets = real
    if "error" in result:
        raise RuntimeError(f"the viewer's server did not start: {result['error']}") from None
    server = result["server"]
    if not guard.hooked:
        server.stop()
        raise RuntimeError(
            "could not install the viewer's access checks in viser; not serving unprotected"
        )
    return server
