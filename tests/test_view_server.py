"""The view server (issue 40, 5): only the user's browser reads the page. Host headers as a DNS-rebinding page
sends them, the token of the printed URL, clients that hang up or stay silent, a flood of connections."""

from __future__ import annotations

import contextlib
import http.client
import socket
import struct
import threading
import time
from collections.abc import Iterator

import pytest

from roarmctl.viz.web.server import ViewOptions, ViewServer

PAGE = b"<!doctype html><title>plan</title>SECRET-PLAN-BYTES" + b"x" * 1000


@pytest.fixture
def serve() -> Iterator:
    servers: list[tuple[ViewServer, threading.Thread]] = []

    def start(page: bytes = PAGE, **kw) -> ViewServer:
        srv = ViewServer(page, ViewOptions(**kw))
        t = threading.Thread(target=srv.serve_forever, daemon=True)
        t.start()
        servers.append((srv, t))
        return srv

    yield start
    for srv, t in servers:
        # shutdown() waits for the serving loop to see its flag, up to the loop's 0.2 s poll: a connection (closed at
        # once) wakes the loop so it looks now (1.8 s of waiting over this module's tests, most of it in make test-fast)
        stopper = threading.Thread(target=srv.httpd.shutdown)
        stopper.start()
        with contextlib.suppress(OSError):
            socket.create_connection(srv.httpd.server_address[:2], timeout=5).close()
        stopper.join(30)
        srv.close()
        t.join(30)


def _until(cond, what: str, limit: float = 60.0) -> None:
    """Wait for ``cond()``: a hang detector (the limit is never a figure under test)."""
    end = time.monotonic() + limit
    while not cond():
        if time.monotonic() > end:
            pytest.fail(f"{what}: not within {limit} s")
        time.sleep(0.02)


def _get(srv: ViewServer, target: str, host: str | None) -> tuple[int, bytes]:
    """A raw HTTP/1.1 request with exactly this Host header (None: none at all)."""
    with socket.create_connection(("127.0.0.1", srv.port), timeout=30) as s:
        head = f"GET {target} HTTP/1.1\r\n" + (f"Host: {host}\r\n" if host is not None else "") + "Connection: close\r\n\r\n"
        s.sendall(head.encode("latin-1"))
        data = b""
        while chunk := s.recv(65536):
            data += chunk
    status = int(data.split(b" ", 2)[1])
    return status, data.split(b"\r\n\r\n", 1)[1]


def _hosts(port: int) -> list[str | None]:
    """Host headers a page elsewhere can make a browser send to 127.0.0.1:PORT (its own name rebound to
    127.0.0.1, other spellings of the loopback address, a wrong port, tricks with suffixes)."""
    return [None, "", f"evil.example:{port}", "evil.example", f"127.0.0.1.nip.io:{port}", f"localhost.evil.example:{port}",
            f"127.0.0.1:{port}.evil.example", f"localhost:{port}@evil.example", "127.0.0.1", "localhost",
            f"127.0.0.1:{port + 1}", f"[::1]:{port}", f"0.0.0.0:{port}", f"127.1:{port}", f"2130706433:{port}",
            f"127.0.0.2:{port}", f"127.0.0.1:{port} evil", f"127.0.0.1:0{port}", f"localhost.:{port}"]


def test_only_host_127_0_0_1_or_localhost_with_the_port_gets_the_page(serve):
    srv = serve()
    good = srv.url.split(f":{srv.port}", 1)[1]  # /?token=...
    for host in (f"127.0.0.1:{srv.port}", f"localhost:{srv.port}", f"LocalHost:{srv.port}"):
        assert _get(srv, good, host) == (200, PAGE), host
    for host in _hosts(srv.port):
        status, body = _get(srv, good, host)
        assert status == 403 and b"SECRET-PLAN" not in body, (host, status, body[:80])
    assert srv.requests == 3 and srv.refused == len(_hosts(srv.port))


def test_the_page_needs_the_token_of_the_printed_url(serve):
    a, b = serve(), serve()
    assert a.token != b.token and len(a.token) >= 32 and a.url.endswith(f"/?token={a.token}")
    host = f"127.0.0.1:{a.port}"
    for target in ("/", "/index.html", "/?token=", f"/?token={b.token}", f"/?token={a.token[:-1]}",
                   f"/?token={a.token}x", f"/?tok={a.token}", f"/?token={a.token.upper()}"):
        status, body = _get(a, target, host)
        assert status == 403 and b"SECRET-PLAN" not in body, (target, status)
    assert _get(a, f"/index.html?token={a.token}", host) == (200, PAGE)
    assert _get(a, f"/etc/passwd?token={a.token}", host)[0] == 404
    c = http.client.HTTPConnection("127.0.0.1", a.port, timeout=30)  # the Host header as a client makes it
    try:
        c.request("GET", a.url.split(str(a.port), 1)[1])
        r = c.getresponse()
        assert r.status == 200 and r.read() == PAGE and r.getheader("Referrer-Policy") == "no-referrer"
    finally:
        c.close()


def test_a_client_that_hangs_up_early_prints_nothing(serve, capfd):
    """A reader that resets the connection while an 8 MB page is sent: no traceback, no line on the terminal."""
    srv = serve(b"y" * (8 * 1024 * 1024))
    target = srv.url.split(str(srv.port), 1)[1]
    for _ in range(20):
        s = socket.create_connection(("127.0.0.1", srv.port), timeout=30)
        s.sendall(f"GET {target} HTTP/1.1\r\nHost: 127.0.0.1:{srv.port}\r\n\r\n".encode())
        s.recv(100)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))  # close with a reset
        s.close()
    _until(lambda: srv.requests == 20 and srv.slots._value == 16, "the 20 connections ended")  # noqa: SLF001
    out, err = capfd.readouterr()
    assert out == "" and err == "" and srv.errors == [], err[-2000:]


def test_connections_are_bounded_in_number(serve):
    """200 connections that never send a request: 4 threads serve 4 of them, the others are closed at once."""
    before = threading.active_count()
    srv = serve(max_connections=4, timeout=120)
    idle = [socket.create_connection(("127.0.0.1", srv.port), timeout=30) for _ in range(200)]
    try:
        _until(lambda: srv.dropped == 196, "the connections over the bound were closed")
        assert threading.active_count() <= before + 1 + 4  # the serving thread and at most 4 connections
        assert idle[-1].recv(10) == b""  # closed by the server
    finally:
        for s in idle:
            s.close()


def test_a_silent_connection_is_let_go_after_its_timeout(serve):
    """4 connections that never send a request hold every thread until their timeout; then the browser's request
    is served (without the timeout it would wait forever)."""
    before = threading.active_count()
    srv = serve(max_connections=4, timeout=0.3)
    idle = [socket.create_connection(("127.0.0.1", srv.port), timeout=30) for _ in range(4)]
    try:
        _until(lambda: srv.slots._value == 0, "the 4 connections were taken")  # noqa: SLF001
        _until(lambda: threading.active_count() <= before + 1, "the silent connections were let go")
        assert [s.recv(10) for s in idle] == [b""] * 4
        assert _get(srv, srv.url.split(str(srv.port), 1)[1], f"127.0.0.1:{srv.port}") == (200, PAGE)
    finally:
        for s in idle:
            s.close()


@pytest.mark.parametrize("value", [1e-3, 1.0])
def test_timeouts_and_bounds_are_whatever_the_caller_gives(serve, value):
    srv = serve(timeout=value, max_connections=1)
    assert srv.slots._value == 1  # noqa: SLF001


def test_generated_host_headers_get_the_page_only_when_they_name_this_server(serve):
    """Hypothesis-made Host headers (the fuzz suite's generator for the view server): the page only for the two
    spellings of this server, 403 without the page otherwise; the server keeps answering throughout."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    srv = serve()
    good = srv.url.split(f":{srv.port}", 1)[1]
    allowed = {f"127.0.0.1:{srv.port}", f"localhost:{srv.port}"}
    pieces = st.sampled_from(["127.0.0.1", "localhost", "LOCALHOST", "evil.example", ":", str(srv.port),
                              str(srv.port + 1), ".", "@", " ", "[::1]", "0", "\t"])
    hosts = st.lists(pieces, min_size=0, max_size=5).map("".join) | st.text(
        st.characters(min_codepoint=33, max_codepoint=126), max_size=30)

    @settings(max_examples=150, derandomize=True, database=None, deadline=None,
              suppress_health_check=list(HealthCheck))
    @given(host=hosts)
    def one(host):
        status, body = _get(srv, good, host)
        ok = host.strip().lower() in allowed
        assert (status, body == PAGE) == ((200, True) if ok else (403, False)), (host, status)

    one()


def test_ctrl_c_while_a_connection_thread_starts_stops_the_view(monkeypatch):
    """Ctrl-C can land in ``Thread.start()``'s wait for a connection's thread that has already started (seen under
    load: ``roarmctl view`` then served on, deaf to every later Ctrl-C). It must reach the caller of the server's loop,
    and the connection's slot must be given back exactly once."""
    srv = ViewServer(PAGE, ViewOptions(max_connections=2))
    srv.httpd.timeout = 60  # handle_request's wait for the client below: a hang detector
    got: list[tuple[int, bytes]] = []
    client = threading.Thread(target=lambda: got.append(_get(srv, f"/?token={srv.token}", f"127.0.0.1:{srv.port}")),
                              daemon=True)
    client.start()
    real_start = threading.Thread.start

    def start_then_ctrl_c(thread: threading.Thread) -> None:
        real_start(thread)
        thread.join(60)  # the page is served and the slot given back before the Ctrl-C lands
        raise KeyboardInterrupt

    monkeypatch.setattr(threading.Thread, "start", start_then_ctrl_c)
    try:
        with pytest.raises(KeyboardInterrupt):
            srv.httpd.handle_request()
    finally:
        monkeypatch.undo()
        srv.close()
    client.join(60)
    assert got and got[0][0] == 200 and b"SECRET-PLAN-BYTES" in got[0][1]
    assert srv.errors == []
    assert [srv.slots.acquire(blocking=False) for _ in range(3)] == [True, True, False]  # both slots free, no third
