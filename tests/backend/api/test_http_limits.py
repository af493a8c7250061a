"""Slow and oversized clients against the api's uvicorn protocol (backend.http_limits), on a real server
through raw sockets: >= 1 MB of headers is a 431 the client can read (not a TCP reset), headers that
dribble in are a 408, a body that stalls loses its connection; normal requests are untouched."""
from __future__ import annotations

import socket
import time
from collections.abc import Iterator

import pytest

from backend.app import create_app
from backend.http_limits import MAX_HEADER_BYTES, LimitedH11Protocol
from tests.backend.api.conftest import RecordingQueue
from tests.backend.api.live import serve


class QuickProtocol(LimitedH11Protocol):
    header_timeout_s = 0.5
    body_idle_timeout_s = 0.5


@pytest.fixture
def port(settings) -> Iterator[int]:
    app = create_app(settings, enqueue=RecordingQueue())
    with serve(app, http=QuickProtocol, h11_max_incomplete_event_size=MAX_HEADER_BYTES) as base:
        yield int(base.rsplit(":", 1)[1])


def _exchange(port: int, data: bytes, *, then_wait: bool = False) -> bytes:
    with socket.create_connection(("127.0.0.1", port), timeout=20) as s:
        s.sendall(data)
        out = b""
        while True:
            try:
                chunk = s.recv(65536)
            except ConnectionResetError:
                return out + b"<reset>"
            if not chunk:
                return out
            out += chunk
            if not then_wait and b"\r\n\r\n" in out and b"content-length: 0" not in out.lower():
                return out


def test_a_normal_request_is_untouched(port) -> None:
    out = _exchange(port, b"GET /api/v1/health HTTP/1.1\r\nHost: t\r\nConnection: close\r\n\r\n", then_wait=True)
    assert out.startswith(b"HTTP/1.1 200") and b'"status":"ok"' in out


def test_one_megabyte_of_headers_is_431_not_a_reset(port) -> None:
    big = b"GET /api/v1/health HTTP/1.1\r\nHost: t\r\nX-Big: " + b"a" * (1 << 20) + b"\r\n\r\n"
    out = _exchange(port, big)
    assert out.startswith(b"HTTP/1.1 431"), out[:200]


def test_headers_that_dribble_in_are_408(port) -> None:
    with socket.create_connection(("127.0.0.1", port), timeout=20) as s:
        s.sendall(b"GET /api/v1/health HTTP/1.1\r\n")
        t0 = time.monotonic()
        out = s.recv(65536)
    assert out.startswith(b"HTTP/1.1 408") and time.monotonic() - t0 < 15


def test_a_stalled_body_loses_its_connection(port) -> None:
    head = (b"POST /api/v1/jobs HTTP/1.1\r\nHost: t\r\nContent-Type: application/json\r\n"
            b"Content-Length: 1000\r\n\r\n{\"sequence_id\": ")
    with socket.create_connection(("127.0.0.1", port), timeout=20) as s:
        s.sendall(head)
        try:
            out = s.recv(65536)
        except ConnectionResetError:
            out = b""
    assert not out.startswith(b"HTTP/1.1 2"), out  # closed (or refused), never served


@pytest.fixture
def echo_run(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """A WebSocket echo server standing in for a run's viser server; the api's proxy is pointed at it."""
    import threading

    from websockets.sync.server import serve as ws_serve

    from backend.api import viewer_proxy
    from backend.api.viewer import RunAddress

    def echo(conn) -> None:  # noqa: ANN001 (websockets' ServerConnection)
        for message in conn:
            conn.send(message)

    with ws_serve(echo, "127.0.0.1", 0) as server:
        port = server.socket.getsockname()[1]
        monkeypatch.setattr(viewer_proxy, "open_run", lambda _settings, _job: RunAddress("127.0.0.1", port))
        thread = threading.Thread(target=server.serve_forever, daemon=True)
        thread.start()
        yield
        server.shutdown()


def test_a_websocket_session_outlives_the_header_timeout(port, echo_run) -> None:
    """Issue 60.1: after the upgrade the header timer kept running and wrote a 408 into the live socket
    (the 3D viewer reconnected every 10 s). Held for 6x the header timeout: no close, every echo back."""
    from websockets.sync.client import connect

    hold_s = 6 * QuickProtocol.header_timeout_s
    sent = received = 0
    with connect(f"ws://127.0.0.1:{port}/viewer/job1", open_timeout=10, close_timeout=2) as ws:
        t0 = time.monotonic()
        while time.monotonic() - t0 < hold_s:
            ws.send(f"ping {sent}")
            sent += 1
            assert ws.recv(timeout=5) == f"ping {sent - 1}"
            received += 1
            time.sleep(0.1)
        ws.ping().wait(5)
    assert sent == received and sent > 10
