"""The api's HTTP connection limits, as a uvicorn h11 protocol (uvicorn has header size limits but no
header or body timeouts, and answers oversized headers with a 400 and an immediate close that the
client sees as a TCP reset).

- Headers: at most :data:`MAX_HEADER_BYTES`; beyond, a 431 and a lingering close (the rest of what
  the client sends is read and dropped for :data:`LINGER_S`, so it reads the answer, not a reset).
- Slow headers (slowloris): a request's headers must arrive within :data:`HEADER_TIMEOUT_S` of its
  first byte, else 408 and close. The timer stops once the headers are in, a WebSocket upgrade included
  (the socket then belongs to the WebSocket protocol: a 408 written into it would kill a live session).
- Slow bodies: a request whose body stops arriving for :data:`BODY_IDLE_TIMEOUT_S` (while the api is
  waiting for it, not while it pushes back) loses its connection; the upload is cleaned up as a disconnect.
Idle keep-alive connections close after uvicorn's ``timeout_keep_alive``.
"""

from __future__ import annotations

import asyncio
from typing import Any

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

MAX_HEADER_BYTES = 64 * 1024
HEADER_TIMEOUT_S = 10.0
BODY_IDLE_TIMEOUT_S = 60.0
LINGER_S = 2.0
KEEP_ALIVE_S = 5


class _Connection(h11.Connection):
    """Remembers the status h11 suggests for the last protocol error (431 for oversized headers)."""

    error_hint = 400

    def next_event(self) -> Any:
        try:
            return super().next_event()
        except h11.RemoteProtocolError as exc:
            self.error_hint = exc.error_status_hint
            raise


class LimitedH11Protocol(H11Protocol):
    """Pass as ``uvicorn.Config(http=LimitedH11Protocol, h11_max_incomplete_event_size=MAX_HEADER_BYTES)``."""

    header_timeout_s = HEADER_TIMEOUT_S
    body_idle_timeout_s = BODY_IDLE_TIMEOUT_S

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.conn: _Connection = _Connection(
            h11.SERVER, self.config.h11_max_incomplete_event_size or MAX_HEADER_BYTES
        )
        self._timer: asyncio.TimerHandle | None = None
        self._discarding = False

    def data_received(self, data: bytes) -> None:
        if self._discarding:  # after a refusal: drain, so the client reads our answer
            return
        waiting_headers = self.cycle is None or self.cycle.response_complete
        if waiting_headers and self._timer is None:
            self._arm(self.header_timeout_s, self._headers_too_slow)
        super().data_received(data)
        if self.cycle is not None and not self.cycle.response_complete:
            if self.cycle.more_body and not self._discarding:
                self._arm(self.body_idle_timeout_s, self._body_too_slow)  # re-armed by every chunk
            else:
                self._disarm()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        super().connection_lost(exc)

    def send_400_response(self, msg: str) -> None:
        if self.conn.error_hint == 431:
            self._refuse(431, "Request Header Fields Too Large", b"the request's headers are too large")
        else:
            super().send_400_response(msg)

    def handle_websocket_upgrade(self, event: h11.Request) -> None:
        self._disarm()  # the headers are complete; from here the transport is the WebSocket protocol's
        super().handle_websocket_upgrade(event)

    def _arm(self, delay: float, callback: Any) -> None:
        self._disarm()
        self._timer = self.loop.call_later(delay, callback)

    def _disarm(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _headers_too_slow(self) -> None:
        self._timer = None
        if self.transport.get_protocol() is not self:  # upgraded: not ours to answer any more
            return
        if self.cycle is None or self.cycle.response_complete:
            self._refuse(408, "Request Timeout", b"the request's headers did not arrive in time")

    def _body_too_slow(self) -> None:
        self._timer = None
        if self.cycle is not None and self.cycle.more_body and not self.flow.read_paused:
            self.logger.info("closing a connection whose request body stalled for %s s", self.body_idle_timeout_s)
            self.transport.close()

    def _refuse(self, status: int, reason: str, body: bytes) -> None:
        """Answer on the raw transport (h11's state may be broken), then linger before closing."""
        self._disarm()
        if self.transport.is_closing():
            return
        head = (f"HTTP/1.1 {status} {reason}\r\ncontent-type: text/plain; charset=utf-8\r\n"
                f"content-length: {len(body)}\r\nconnection: close\r\n\r\n").encode()
        self.transport.write(head + body)
        self._discarding = True
        self.loop.call_later(LINGER_S, self.transport.close)
