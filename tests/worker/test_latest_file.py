"""The newest content is written on the writer thread; content superseded while a write runs is skipped; a failed
write is reported and the next content still written; closing writes what is pending."""
from __future__ import annotations

import threading

from worker.latest_file import LatestFile


def test_the_newest_content_wins_and_closing_writes_what_is_pending() -> None:
    written: list[tuple[bytes, str]] = []
    first_started, release = threading.Event(), threading.Event()

    def write(data: bytes) -> None:
        if data == b"1":
            first_started.set()
            assert release.wait(30)
        written.append((data, threading.current_thread().name))

    f = LatestFile(write, lambda exc: None, name="writer")
    f.put(lambda: b"1")
    assert first_started.wait(30)
    f.put(lambda: b"2")  # superseded before the writer is free
    f.put(lambda: b"3")
    release.set()
    f.close()
    assert written == [(b"1", "writer"), (b"3", "writer")]


def test_a_failed_write_is_reported_and_the_next_one_written() -> None:
    errors: list[Exception] = []
    written: list[bytes] = []
    failed = threading.Event()

    def write(data: bytes) -> None:
        if data == b"bad":
            raise OSError("disk full")
        written.append(data)

    def on_error(exc: Exception) -> None:
        errors.append(exc)
        failed.set()

    f = LatestFile(write, on_error)
    f.put(lambda: b"bad")
    assert failed.wait(30)
    f.put(lambda: b"good")
    f.close()
    assert [str(e) for e in errors] == ["disk full"] and written == [b"good"]
