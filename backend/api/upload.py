"""Streaming a multipart upload to a sink: the archive never sits in memory.

Starlette's own form parser spools files to the system temp dir; this one hands the ``file`` part to a
sink of our choosing (:class:`storage.ingest.stream.ArchiveSink`: unpacks a .tar.gz on the fly, writes
anything else into the data dir's staging area), in large blocks written off the event loop, and stops
at ``max_bytes``.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from typing import Protocol

import anyio
from python_multipart.exceptions import FormParserError
from python_multipart.multipart import MultipartParser, parse_options_header
from starlette.concurrency import run_in_threadpool
from starlette.requests import ClientDisconnect, Request

from storage.errors import InvalidInput, PayloadTooLarge, RequestTimeout

WRITE_BLOCK = 4 << 20
MAX_FIELD_BYTES = 64 * 1024
MAX_FIELDS = 20


@dataclass
class UploadedForm:
    fields: dict[str, str] = field(default_factory=dict)
    filename: str | None = None
    file_bytes: int = 0
    sha256: str = ""
    """Hex SHA-256 of the file part's bytes as they arrived (what duplicate detection compares)."""


class Sink(Protocol):
    """Takes the file part's bytes in order, in large blocks (called in a worker thread)."""

    def write(self, block: bytes) -> None: ...


class _Receiver:
    """python-multipart callbacks: ``file`` goes to the sink in blocks; small text fields are kept."""

    def __init__(self, file_field: str, max_bytes: int) -> None:
        self.file_field = file_field
        self.max_bytes = max_bytes
        self.form = UploadedForm()
        self.buffer = bytearray()
        self._header_field = bytearray()
        self._header_value = bytearray()
        self._headers: dict[str, str] = {}
        self._name: str | None = None
        self._is_file = False
        self._value = bytearray()

    def on_part_begin(self) -> None:
        self._headers = {}
        self._name = None
        self._is_file = False
        self._value = bytearray()

    def on_header_field(self, data: bytes, start: int, end: int) -> None:
        self._header_field += data[start:end]

    def on_header_value(self, data: bytes, start: int, end: int) -> None:
        self._header_value += data[start:end]

    def on_header_end(self) -> None:
        key = self._header_field.decode("latin-1").lower()
        # latin-1 keeps the raw bytes (what parse_options_header expects: it re-encodes to latin-1 and
        # failed with a 500 on any other character); names and filenames are decoded as UTF-8 below,
        # which is what browsers send for a non-ASCII file name.
        self._headers[key] = self._header_value.decode("latin-1")
        self._header_field.clear()
        self._header_value.clear()

    def on_headers_finished(self) -> None:
        disposition, options = parse_options_header(self._headers.get("content-disposition", ""))
        if disposition != b"form-data" or b"name" not in options:
            raise InvalidInput("a multipart part has no form-data name")
        self._name = options[b"name"].decode("utf-8", "replace")
        if self._name == self.file_field:
            if self.form.filename is not None:
                raise InvalidInput(f"only one {self.file_field!r} part is allowed")
            self._is_file = True
            self.form.filename = options.get(b"filename", b"").decode("utf-8", "replace")
            if "\x00" in self.form.filename:  # PostgreSQL refuses NUL in text: never let it reach a row
                raise InvalidInput("the file name must not contain NUL characters")
        elif len(self.form.fields) >= MAX_FIELDS:
            raise InvalidInput("too many form fields")

    def on_part_data(self, data: bytes, start: int, end: int) -> None:
        n = end - start
        if self._is_file:
            self.form.file_bytes += n
            if self.form.file_bytes > self.max_bytes:
                raise PayloadTooLarge(
                    f"the upload is larger than {self.max_bytes} bytes", {"max_bytes": self.max_bytes}
                )
            self.buffer += data[start:end]
        else:
            self._value += data[start:end]
            if len(self._value) > MAX_FIELD_BYTES:
                raise InvalidInput(f"form field {self._name!r} is too long")

    def on_part_end(self) -> None:
        if not self._is_file and self._name is not None:
            value = self._value.decode("utf-8", "replace")
            if "\x00" in value or "\x00" in self._name:
                raise InvalidInput(f"form field {self._name[:40]!r} must not contain NUL characters")
            self.form.fields[self._name] = value


async def receive_upload(
    request: Request, sink: Sink, *, file_field: str, max_bytes: int, max_seconds: float = math.inf
) -> UploadedForm:
    """Parse the multipart body of ``request``, handing the ``file_field`` part's bytes to ``sink``.

    The whole body must arrive within ``max_seconds`` (:class:`RequestTimeout` otherwise), however steadily
    it trickles: the connection's idle timeout only catches a body that stops."""
    ctype, options = parse_options_header(request.headers.get("content-type", ""))
    if ctype != b"multipart/form-data" or b"boundary" not in options:
        raise InvalidInput("the upload must be multipart/form-data", {"content_type": ctype.decode("latin-1")})
    length = request.headers.get("content-length")
    # isascii: str.isdigit() accepts "²" (a latin-1 header byte) that int() then refuses
    declared = int(length) if length and length.isascii() and length.isdigit() else None
    if declared is not None and declared > max_bytes + MAX_FIELDS * MAX_FIELD_BYTES:
        raise PayloadTooLarge(f"the upload is larger than {max_bytes} bytes", {"max_bytes": max_bytes})
    rx = _Receiver(file_field, max_bytes)
    callbacks = {
        name: getattr(rx, name)
        for name in (
            "on_part_begin",
            "on_part_data",
            "on_part_end",
            "on_header_field",
            "on_header_value",
            "on_header_end",
            "on_headers_finished",
        )
    }
    try:  # python-multipart refuses boundaries over 256 characters (RFC 2046 allows 70) here, not in write()
        parser = MultipartParser(options[b"boundary"], callbacks)  # type: ignore[arg-type]
    except (FormParserError, ValueError) as exc:
        detail = {"boundary_length": len(options[b"boundary"])}
        raise InvalidInput(f"unusable multipart boundary: {exc}", detail) from None
    digest = hashlib.sha256()

    def write(block: bytes) -> None:  # in a worker thread: hashing 4 MiB would stall the event loop
        digest.update(block)
        sink.write(block)

    try:
        with anyio.fail_after(max_seconds if math.isfinite(max_seconds) else None):
            async for chunk in request.stream():
                parser.write(chunk)
                if len(rx.buffer) >= WRITE_BLOCK:
                    block = bytes(rx.buffer)
                    rx.buffer.clear()
                    await run_in_threadpool(write, block)
        parser.finalize()
    except TimeoutError:
        raise RequestTimeout(
            f"the upload did not arrive within {max_seconds:g} s", {"max_seconds": max_seconds}
        ) from None
    except ClientDisconnect:
        raise InvalidInput("the client disconnected during the upload") from None
    except FormParserError as exc:
        raise InvalidInput(f"malformed multipart body: {exc}") from None
    if rx.buffer:
        await run_in_threadpool(write, bytes(rx.buffer))
    if rx.form.filename is None:
        raise InvalidInput(f"the form needs a {file_field!r} file part")
    rx.form.sha256 = digest.hexdigest()
    return rx.form
