"""The pipeline's exception tree, under the project's root :class:`formats.errors.VtdError`. Converted to a
failed job in the worker and an exit code in the CLI."""
from __future__ import annotations

from pathlib import Path

from formats.errors import VtdError


class SlamError(VtdError):
    """Root of every error the pipeline raises on purpose. `code` is stable and machine-readable."""

    code = "slam_error"
    detail: dict

    def __init__(self, message: str, *, detail: dict | None = None) -> None:
        super().__init__(message, detail or {})


class SequenceFormatError(SlamError):
    """A sequence folder or one of its files is malformed. Names the file and, where known, the line."""

    code = "invalid_sequence"

    def __init__(self, message: str, *, path: Path | str | None = None, line: int | None = None) -> None:
        where = ""
        if path is not None:
            where = f"{path}:{line}: " if line is not None else f"{path}: "
        super().__init__(where + message, detail={"path": str(path) if path else None, "line": line})
        self.path = path
        self.line = line


class TrajectoryFormatError(SequenceFormatError):
    """A TUM trajectory file is malformed."""

    code = "invalid_trajectory"


class CameraError(SlamError):
    """Unknown camera preset or invalid intrinsics."""

    code = "invalid_camera"


class ConfigError(SlamError):
    """A pipeline configuration value is invalid."""

    code = "invalid_config"


class EvaluationError(SlamError):
    """Trajectories cannot be compared (e.g. too few associated poses)."""

    code = "evaluation_failed"


class TrackingFailed(SlamError):
    """No frame of a run was tracked: there is no trajectory to write or score. The message says why, as far
    as the run can tell (no image features, no valid depth, ...)."""

    code = "tracking_failed"
