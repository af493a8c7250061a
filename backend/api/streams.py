"""How many event streams each client may hold open at once (a tab per running job is normal; hundreds
are not). Counted per client address in the app's state, released when a stream ends however it ends."""

from __future__ import annotations

import threading
from collections import Counter
from dataclasses import dataclass

from backend.api.errors import ApiError


class TooManyStreams(ApiError):
    code = "too_many_streams"
    http_status = 429


@dataclass
class StreamSlot:
    """One open stream of ``client``; ``release`` is idempotent."""

    limits: StreamLimits
    client: str
    released: bool = False

    def release(self) -> None:
        if not self.released:
            self.released = True
            self.limits.release(self.client)


class StreamLimits:
    """At most ``per_client`` open streams per client key (thread-safe: streams end on any thread)."""

    def __init__(self, per_client: int) -> None:
        self.per_client = per_client
        self._open: Counter[str] = Counter()
        self._lock = threading.Lock()

    def acquire(self, client: str) -> StreamSlot:
        with self._lock:
            if self._open[client] >= self.per_client:
                raise TooManyStreams(
                    f"this client already has {self.per_client} event streams open; close one first",
                    {"max_streams_per_client": self.per_client},
                )
            self._open[client] += 1
        return StreamSlot(self, client)

    def release(self, client: str) -> None:
        with self._lock:
            self._open[client] -= 1
            if self._open[client] <= 0:
                del self._open[client]

    def open_count(self, client: str) -> int:
        with self._lock:
            return self._open[client]
