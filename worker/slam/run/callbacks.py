"""What a caller hands a run to follow it and stop it."""
from __future__ import annotations

from collections.abc import Callable

from worker.slam.errors import SlamError

ProgressFn = Callable[[int, int, str], None]
"""(frames_done, frames_total, stage) -- stage is 'tracking', 'dense', 'evaluation' or 'writing'."""
CancelFn = Callable[[], bool]
"""Returns True when the job should stop; checked before every frame."""


class PipelineCancelled(SlamError):
    """The run was stopped by its cancellation check."""

    code = "cancelled"
