"""Serving a stored file: opened before any header is sent, ranges checked before any header is sent.

Starlette's ``FileResponse`` sends its status and ``Content-Length`` and only then opens the file, so a
file the api may not read became a 200 with a length and no body; its range errors are ``text/plain``.
:func:`serve_file` opens the file first (:class:`storage.errors.Unreadable` otherwise: a JSON error) and
answers a range it cannot serve with a 416 in the error shape (``Content-Range: bytes */size``).
"""

from __future__ import annotations

import os
import stat
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
from fastapi import Request
from fastapi.responses import FileResponse
from starlette.exceptions import HTTPException
from starlette.responses import MalformedRangeHeader, RangeNotSatisfiable
from starlette.types import Receive, Scope, Send

from storage.errors import NotFound, Unreadable


class OpenedFileResponse(FileResponse):
    """A ``FileResponse`` over a file descriptor opened beforehand (closed when the response ends)."""

    def __init__(self, fd: int, path: Path, **kwargs: Any) -> None:
        self._fd = fd
        super().__init__(path, stat_result=os.fstat(fd), **kwargs)

    @asynccontextmanager
    async def _open_file(self) -> AsyncIterator[anyio.AsyncFile[bytes]]:
        file = os.fdopen(os.dup(self._fd), "rb")  # each read pass gets its own offset
        try:
            yield anyio.AsyncFile(file)
        finally:
            file.close()

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        try:
            await super().__call__(scope, receive, send)
        finally:
            os.close(self._fd)


def serve_file(
    path: Path, request: Request, *, media_type: str, what: str, missing: NotFound | None = None, **kwargs: Any
) -> FileResponse:
    """``path`` as a response, or the JSON error saying why not. ``what`` names the file in messages;
    ``missing`` is raised when there is no regular file at ``path``."""
    missing = missing or NotFound(f"{what} does not exist")
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    except (FileNotFoundError, NotADirectoryError):
        raise missing from None
    except OSError as exc:  # EACCES across users on shared storage, EIO, …
        raise Unreadable(
            f"the server cannot read {what} ({exc.strerror or exc}); check the data dir's permissions",
            {"errno": exc.errno},
        ) from exc
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise missing
        response = OpenedFileResponse(fd, path, media_type=media_type, **kwargs)
        _check_range(request, response)
    except BaseException:
        os.close(fd)
        raise
    return response


def _check_range(request: Request, response: FileResponse) -> None:
    """Raise the 416 Starlette would answer in text/plain (a malformed range, like ``bytes=5-2``, too)."""
    http_range = request.headers.get("range")
    if http_range is None or response.stat_result is None:
        return
    if_range = request.headers.get("if-range")
    if if_range is not None and not response._should_use_range(if_range):
        return  # the file changed: the whole file is sent, the range does not matter
    size = response.stat_result.st_size
    try:
        FileResponse._parse_range_header(http_range, size)
    except (MalformedRangeHeader, RangeNotSatisfiable) as exc:
        reason = exc.content if isinstance(exc, MalformedRangeHeader) else f"the file has {size} bytes"
        raise HTTPException(416, f"range {http_range[:80]!r} cannot be served: {reason}",
                            headers={"Content-Range": f"bytes */{size}"}) from None
