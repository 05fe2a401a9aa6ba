"""A local web server for one page: bound to 127.0.0.1 only (never another interface), on a free port
unless one is asked for, answering ``GET /?token=TOKEN`` with the page. It serves bytes it holds in memory:
no file on disk is ever read through it.

Only the user's browser may read the page. Any web page the user visits can send requests to 127.0.0.1 and,
through a name of its own that resolves to 127.0.0.1 (DNS rebinding), read the answers as its own origin;
so (as Jupyter does) the server answers only a request whose ``Host`` is ``127.0.0.1:PORT`` or
``localhost:PORT`` and whose URL carries the unguessable token of the URL the command printed; anything
else gets 403 or 404 without the page. A connection is served by one of at most ``MAX_CONNECTIONS``
threads (more are closed at once) and closed after ``TIMEOUT`` s without a request; a client that hangs
up early is not an error.
"""

from __future__ import annotations

import errno
import hmac
import secrets
import socket
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any
from urllib.parse import parse_qs, urlsplit

from roarmctl.checks import Bound, check_options
from roarmctl.errors import InputError

HOST = "127.0.0.1"
PATHS = ("/", "/index.html")
#: Connections served at once; a browser opens a few, a page that floods the port gets no more threads.
MAX_CONNECTIONS = 16
#: Seconds a connection may stay silent (reading its request, or sending the page to a reader that stalls).
TIMEOUT = 10.0

VIEW_BOUNDS: dict[str, Bound] = {
    "port": Bound(0, 65535, whole=True),  # TCP port on 127.0.0.1; 0: a free one
    "timeout": Bound(0.0, 3600.0, strict_lo=True),  # s a connection may stay silent
    "max_connections": Bound(1, 1024, whole=True),  # connections served at once
}


@dataclass(frozen=True)
class ViewOptions:
    """How the view's page is served: ``port`` (0: a free one), ``timeout`` (s a silent connection is kept) and
    ``max_connections`` (served at once). Checks its own fields when made (``VIEW_BOUNDS``): a port out of
    0..65535, a NaN, infinite or negative time, a wrong type raise ``OptionError`` naming the field."""

    port: int = 0
    timeout: float = TIMEOUT
    max_connections: int = MAX_CONNECTIONS

    def __post_init__(self) -> None:
        check_options(self, VIEW_BOUNDS)
#: What a client that hangs up or stalls raises in its connection's thread: its own business, not an error.
HANGUPS = (ConnectionError, TimeoutError, socket.timeout)


class ViewServer:
    """Serve ``page`` (UTF-8 HTML bytes) at ``url`` (``http://127.0.0.1:PORT/?token=TOKEN``) as ``options`` say
    (``ViewOptions``: the port, 0 a free one; the time (s) each connection may stay silent and their number).

    ``serve_forever()`` blocks until ``close()`` or an exception in the calling thread (Ctrl-C reaches it
    as ``KeyboardInterrupt``); ``requests`` counts the pages served, ``refused`` the requests answered 403,
    ``dropped`` the connections closed because ``max_connections`` were open; ``errors`` holds one line per
    unexpected failure in a connection's thread (nothing is printed: the library never prints).
    """

    def __init__(self, page: bytes, options: ViewOptions | None = None) -> None:
        options = options or ViewOptions()
        port, timeout, max_connections = options.port, options.timeout, options.max_connections
        self.page = page
        self.token = secrets.token_urlsafe(32)  # 256 bits, as Jupyter's
        self.requests = self.refused = self.dropped = 0
        self.errors: list[str] = []
        self.slots = threading.BoundedSemaphore(max_connections)  # one per connection being served
        self.on_poll: Callable[[], None] | None = None
        server, idle = self, timeout

        class Handler(BaseHTTPRequestHandler):
            timeout = idle  # StreamRequestHandler sets it on the socket: a silent client is let go

            def _send(self, code: int, body: bytes, head_only: bool = False) -> None:
                self.send_response(code)
                self.send_header("Content-Type", "text/html; charset=utf-8" if code == 200 else "text/plain; charset=utf-8")
                self.send_header("Content-Length", str(len(body)))
                self.send_header("Cache-Control", "no-store")
                self.send_header("X-Content-Type-Options", "nosniff")
                self.send_header("Referrer-Policy", "no-referrer")  # the token stays out of other sites' logs
                self.end_headers()
                if not head_only:
                    self.wfile.write(body)

            def _answer(self, head_only: bool) -> None:
                url = urlsplit(self.path)
                if not server.host_allowed(self.headers.get("Host")):
                    server.refused += 1
                    self._send(403, b"forbidden: this server answers only http://127.0.0.1:PORT/ and localhost:PORT\n",
                               head_only)
                elif url.path not in PATHS:
                    self._send(404, b"not found\n", head_only)
                elif not server.token_matches(parse_qs(url.query).get("token", [""])[0]):
                    server.refused += 1
                    self._send(403, b"forbidden: open the URL roarmctl printed (it holds the token)\n", head_only)
                else:
                    server.requests += not head_only
                    self._send(200, server.page, head_only)

            def do_GET(self) -> None:  # noqa: N802 (http.server's name)
                self._answer(head_only=False)

            def do_HEAD(self) -> None:  # noqa: N802
                self._answer(head_only=True)

            def log_message(self, format: str, *args: object) -> None:  # the library never prints
                pass

        class Server(ThreadingHTTPServer):
            daemon_threads = True
            # connections waiting to be accepted (socketserver's default is 5): a burst beyond the backlog has each
            # extra client's connect retried by its kernel after a second or more, before the bound above can answer
            request_queue_size = 128

            def process_request(self, request: Any, client_address: Any) -> None:
                if not server.slots.acquire(blocking=False):
                    server.dropped += 1
                    self.shutdown_request(request)
                    return
                try:
                    super().process_request(request, client_address)
                except Exception:  # the thread could not start (RuntimeError): its slot is still ours to give back
                    server.slots.release()
                    raise
                # Not on a KeyboardInterrupt: Ctrl-C can land in Thread.start()'s wait for the thread it has already
                # started, which gives the slot back itself. Releasing it here too made the bounded semaphore raise
                # ValueError in place of the Ctrl-C, socketserver took that for the request's error, and the view
                # served on, deaf to every later Ctrl-C (seen under load).

            def process_request_thread(self, request: Any, client_address: Any) -> None:
                try:
                    super().process_request_thread(request, client_address)
                finally:
                    server.slots.release()

            def service_actions(self) -> None:  # once a poll of the loop (serve_forever's poll_interval)
                super().service_actions()
                if server.on_poll is not None:
                    server.on_poll()

            def handle_error(self, request: Any, client_address: Any) -> None:
                exc = sys.exc_info()[1]
                if not isinstance(exc, HANGUPS):
                    server.errors.append(f"{type(exc).__name__}: {exc}"[:200])

        try:
            self.httpd = Server((HOST, port), Handler)
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise InputError(f"{port} is already in use on {HOST}", "pick another port, or 0 for a free one",
                                 option="port") from None
            raise InputError(f"cannot listen on {HOST}:{port} ({exc.strerror})", "pick a port above 1023, or 0",
                             option="port") from None

    @property
    def port(self) -> int:
        """The TCP port it listens on."""
        return int(self.httpd.server_address[1])

    @property
    def url(self) -> str:
        """``http://127.0.0.1:PORT/?token=TOKEN``: the only URL that gets the page."""
        return f"http://{HOST}:{self.port}/?token={self.token}"

    def host_allowed(self, host: str | None) -> bool:
        """Whether a request's ``Host`` header names this server as the user's browser does: ``127.0.0.1:PORT``
        or ``localhost:PORT`` (any other name may be a site's, resolved to 127.0.0.1 by DNS rebinding)."""
        if host is None:
            return False
        return host.strip().lower() in (f"{HOST}:{self.port}", f"localhost:{self.port}")

    def token_matches(self, given: str) -> bool:
        """Whether ``given`` is the token (compared in constant time)."""
        return hmac.compare_digest(given.encode("utf-8", "replace"), self.token.encode())

    def serve_forever(self, on_poll: Callable[[], None] | None = None) -> None:
        """Answer requests until ``close()`` or an exception (Ctrl-C) in this thread; ``on_poll`` is called every
        0.2 s between requests (what it raises ends the serving: the CLI checks for a stop there)."""
        self.on_poll = on_poll
        self.httpd.serve_forever(poll_interval=0.2)

    def close(self) -> None:
        """Stop listening (idempotent)."""
        self.httpd.server_close()
