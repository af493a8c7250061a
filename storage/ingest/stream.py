"""Where an upload's bytes go while they arrive: a .tar.gz is unpacked on the fly, anything else is
written to a file and unpacked afterwards (a zip's directory is at its end).

Unpacking on the fly writes the data once instead of twice (archive + files) and overlaps network and
disk: the upload is accepted about as fast as it arrives. A bounded queue between the receiver and the
unpacking thread keeps memory flat (at most ``QUEUE_BLOCKS`` blocks in flight) and pushes back on the
client when the disk is slower than the network.
"""

from __future__ import annotations

import queue
import threading
from pathlib import Path
from typing import IO

from storage.faults import disk_full, insufficient_storage
from storage.ingest.archive import Limits, Unpacked, unpack_tar_stream

QUEUE_BLOCKS = 4
_EOF = b""


class _BlockReader:
    """A read-only file fed block by block from another thread."""

    def __init__(self) -> None:
        self.blocks: queue.Queue[bytes] = queue.Queue(maxsize=QUEUE_BLOCKS)
        self.current = memoryview(b"")
        self.consumed = 0
        self.eof = False

    def readable(self) -> bool:
        return True

    def read(self, n: int = -1) -> bytes:
        out = bytearray()
        while (n < 0 or len(out) < n) and not self.eof:
            if not self.current:
                block = self.blocks.get()
                if block is _EOF or not block:
                    self.eof = True
                    break
                self.current = memoryview(block)
            take = len(self.current) if n < 0 else min(n - len(out), len(self.current))
            out += self.current[:take]
            self.current = self.current[take:]
        self.consumed += len(out)
        return bytes(out)


class ArchiveSink:
    """Receives an upload's bytes in order (``write``), then ``close()`` says what is in ``staging``.

    After ``close()``: either ``staging/"archive"`` (to unpack) or ``staging/"unpacked"`` (done).
    Errors of the on-the-fly unpacking surface from ``write``/``close`` as the ingest errors they are.
    """

    def __init__(self, staging: Path, limits: Limits) -> None:
        self.staging = staging
        self.limits = limits
        self.bytes = 0
        self.unpacked: Unpacked | None = None
        self._file: IO[bytes] | None = None
        self._reader: _BlockReader | None = None
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    @property
    def streaming(self) -> bool:
        return self._reader is not None

    def write(self, block: bytes) -> None:
        try:
            self._write(block)
        except OSError as exc:
            if disk_full(exc):
                raise insufficient_storage("receiving the upload") from exc
            raise

    def _write(self, block: bytes) -> None:
        if not block:
            return
        if self._file is None and self._reader is None:
            self._start(block)
        self.bytes += len(block)
        if self._file is not None:
            self._file.write(block)
            return
        assert self._reader is not None and self._thread is not None
        while True:
            self._raise_if_failed()
            try:
                self._reader.blocks.put(block, timeout=0.2)
                return
            except queue.Full:
                if not self._thread.is_alive():
                    self._raise_if_failed()
                    raise RuntimeError("the unpacking thread stopped") from None

    def close(self) -> None:
        if self._file is not None:
            try:
                self._file.close()  # flushes the last buffered bytes
            except OSError as exc:
                if disk_full(exc):
                    raise insufficient_storage("receiving the upload") from exc
                raise
            return
        if self._reader is None:  # nothing arrived
            (self.staging / "archive").touch()
            return
        assert self._thread is not None
        while self._thread.is_alive():
            try:
                self._reader.blocks.put(_EOF, timeout=0.2)
                break
            except queue.Full:
                continue
        self._thread.join()
        self._raise_if_failed()

    def abort(self) -> None:
        """Stop the unpacking thread (the caller removes ``staging``)."""
        if self._file is not None:
            self._file.close()
        if self._reader is not None and self._thread is not None:
            while self._thread.is_alive():
                try:  # drain so the thread sees the end instead of blocking on a full queue
                    self._reader.blocks.get_nowait()
                except queue.Empty:
                    pass
                try:
                    self._reader.blocks.put_nowait(_EOF)
                except queue.Full:
                    pass
                self._thread.join(0.05)

    def _start(self, first: bytes) -> None:
        if first[:2] == b"\x1f\x8b" or first[257:262] == b"ustar":
            self._reader = _BlockReader()
            dest = self.staging / "unpacked"
            dest.mkdir()
            self._thread = threading.Thread(target=self._unpack, args=(dest,), name="unpack", daemon=True)
            self._thread.start()
        else:
            self._file = open(self.staging / "archive", "wb")  # noqa: SIM115 - closed in close()/abort()

    def _unpack(self, dest: Path) -> None:
        assert self._reader is not None
        reader = self._reader
        try:
            self.unpacked = unpack_tar_stream(reader, dest, self.limits, lambda: reader.consumed)  # type: ignore[arg-type]
            while not reader.eof:  # trailing padding after the tar's end: drain it
                reader.read(1 << 20)
        except BaseException as exc:  # handed to the receiving side by write()/close()
            self._error = exc

    def _raise_if_failed(self) -> None:
        if self._error is not None:
            if disk_full(self._error):
                raise insufficient_storage("unpacking the upload") from self._error
            raise self._error
