"""The project's one exception root, and the errors formats raise.

:class:`VtdError` is the root every error raised on purpose derives from: the service's (``storage.errors``),
the pipeline's (``worker.slam.errors``) and the ones here. Each has a stable machine-readable ``code``, a
``message`` for people and an optional JSON-able ``detail``; the api maps them to HTTP errors, the worker to
a failed job, the CLI to an exit code. formats is the ground floor, so every layer may import it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


class VtdError(Exception):
    """Root of every error the project raises on purpose: ``code``, ``message`` and ``detail``."""

    code: str = "error"

    def __init__(self, message: str, detail: Any = None) -> None:
        super().__init__(message)
        self.message = message
        self.detail = detail


class FormatError(VtdError, ValueError):
    """A file does not follow its format. ``message`` is bare; ``path`` and ``line`` say where, when known,
    so each caller names the file its own way (the api relative to the upload, the worker as given).
    Storage maps it to InvalidInput (a 4xx), the worker to SequenceFormatError."""

    code = "invalid_format"

    def __init__(self, message: str, *, path: Path | str | None = None, line: int | None = None) -> None:
        where = "" if path is None else (f"{path}:{line}: " if line is not None else f"{path}: ")
        super().__init__(where + message, {"path": None if path is None else str(path), "line": line})
        self.message = message
        self.path = path
        self.line = line


class SpecError(VtdError, ValueError):
    """A setting or camera value breaks its spec (``formats.settings_check``, ``formats.camera_spec``).
    ``detail`` names the field (``{"field", "min", "max", "value"}`` or the like); the api answers it as
    InvalidInput (422), the worker as ConfigError or CameraError, each keeping the message."""

    code = "invalid_input"
