"""A local web server for one page: bound to 127.0.0.1 only (never another interface), on a free port
unless one is asked for, answering ``GET /`` with the page and 404 to anything else. It serves bytes it
holds in memory: no file on disk is ever read through it.
"""

from __future__ import annotations

import errno
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from roarmctl.errors import InputError

HOST = "127.0.0.1"
PATHS = ("/", "/index.html")


class ViewServer:
    """Serve ``page`` (UTF-8 HTML bytes) at ``http://127.0.0.1:PORT/``; ``port`` 0 picks a free one.

    ``serve_forever()`` blocks until ``close()`` or an exception in the calling thread (Ctrl-C reaches it
    as ``KeyboardInterrupt``); ``requests`` counts the pages served.
    """

    def __init__(self, page: bytes, port: int = 0) -> None:
        if not 0 <= port <= 65535:
            raise InputError(f"--port: {port} is not a TCP port", "use 1 to 65535, or 0 for a free one")
        self.page = page
        self.requests = 0
        server = self

        class Handler(BaseHTTPRequestHandler):
            def _head(self, code: int, length: int) -> None:
                self.send_response(code)
                self.send_header("Content-Type", "text/html; charset=utf-8" if code == 200 else "text/plain; charset=utf-8")
                self.send_header("Content-Length", str(length))
                self.send_header("Cache-Control", "no-store")
                self.send_header("X-Content-Type-Options", "nosniff")
                self.end_headers()

            def do_GET(self) -> None:  # noqa: N802 (http.server's name)
                if self.path.split("?", 1)[0] in PATHS:
                    server.requests += 1
                    self._head(200, len(server.page))
                    self.wfile.write(server.page)
                else:
                    body = b"not found\n"
                    self._head(404, len(body))
                    self.wfile.write(body)

            def do_HEAD(self) -> None:  # noqa: N802
                ok = self.path.split("?", 1)[0] in PATHS
                self._head(200 if ok else 404, len(server.page) if ok else 0)

            def log_message(self, format: str, *args: object) -> None:  # the library never prints
                pass

        try:
            self.httpd = ThreadingHTTPServer((HOST, port), Handler)
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise InputError(f"--port {port}: already in use on {HOST}", "pick another port, or 0 for a free one") from None
            raise InputError(f"--port {port}: cannot listen on {HOST} ({exc.strerror})", "pick a port above 1023, or 0") from None
        self.httpd.daemon_threads = True

    @property
    def port(self) -> int:
        """The TCP port it listens on."""
        return int(self.httpd.server_address[1])

    @property
    def url(self) -> str:
        """``http://127.0.0.1:PORT/``."""
        return f"http://{HOST}:{self.port}/"

    def serve_forever(self) -> None:
        """Answer requests until ``close()`` or an exception (Ctrl-C) in this thread."""
        self.httpd.serve_forever(poll_interval=0.2)

    def close(self) -> None:
        """Stop listening (idempotent)."""
        self.httpd.server_close()
