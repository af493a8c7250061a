"""The one error formats raise; storage maps it to InvalidInput (a 4xx), the worker to SequenceFormatError."""

from __future__ import annotations

from pathlib import Path


class FormatError(ValueError):
    """A file does not follow its format. ``message`` is bare; ``path`` and ``line`` say where, when known,
    so each caller names the file its own way (the api relative to the upload, the worker as given)."""

    def __init__(self, message: str, *, path: Path | str | None = None, line: int | None = None) -> None:
        where = "" if path is None else (f"{path}:{line}: " if line is not None else f"{path}: ")
        super().__init__(where + message)
        self.message = message
        self.path = path
        self.line = line
