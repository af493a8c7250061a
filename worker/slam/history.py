"""The run's history of past frames: what the stages produced for each, and its pose once tracked.

The pipeline owns one `FrameHistory`: after a frame's stages ran it appends the frame's record, and when the next
frame's stages start it gives the record the tracker's pose (the last tracked frame's, as the stages see it in
`StageContext.last`). Stages read it through `StageContext.history`, an immutable `HistoryView` taken then; they
keep no copies of their own. Its length is the most any stage declares it reads (`history_frames`: culling's
`lag_frames`, restoration's `selection.reach`).

Records are immutable (a pose is set by replacing the record), so a view taken once never changes: a restoration
deferred past tracking sees its references as they were when it was planned, and the frames after its target as
they were when it was released.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from worker.slam.features.types import Features


@dataclass(frozen=True)
class PastFrame:
    """One frame as the stages left it. Images are the frame's own (H,W), never copied: nothing writes to them."""

    index: int
    timestamp: float
    rgb: np.ndarray
    """uint8 RGB (H,W,3): the raw colour."""
    depth: np.ndarray
    """float32 metres (H,W): the raw depth."""
    extracted: Features | None = None
    """Every keypoint extracted from the frame, before culling (culling compares a later frame with them)."""
    features: Features | None = None
    """The keypoints handed to the tracker (culled)."""
    potentially_dynamic: np.ndarray | None = None
    """bool (H,W): segmentation's potentially dynamic pixels."""
    dynamic: np.ndarray | None = None
    """bool (H,W): the pixels culling judged moving."""
    T_WC: np.ndarray | None = None
    """(4,4) float64 camera-to-world pose the tracker gave the frame; None until it is set and for a lost frame."""

    def moving(self) -> np.ndarray:
        """bool (H,W): `dynamic`, or no pixel when culling marked none."""
        return self.dynamic if self.dynamic is not None else np.zeros(self.depth.shape, bool)


@dataclass(frozen=True)
class HistoryView:
    """The history at one moment: `frames` oldest first, consecutive in stage order."""

    frames: tuple[PastFrame, ...] = ()

    def __len__(self) -> int:
        return len(self.frames)

    def recent(self, n: int) -> tuple[PastFrame, ...]:
        """The last `n` frames (fewer at the start), oldest first."""
        return self.frames[-n:] if n > 0 else ()

    def get(self, index: int) -> PastFrame | None:
        """The record of frame `index`, None when it is not (or no longer) held."""
        return next((f for f in reversed(self.frames) if f.index == index), None)

    def between(self, first: int, last: int) -> list[PastFrame]:
        """The records of frames `first`..`last` (indices, inclusive) that are held, oldest first."""
        return [f for f in self.frames if first <= f.index <= last]


class FrameHistory:
    """The bounded history the run writes (on the pipeline thread only); `view()` is what the stages read."""

    def __init__(self, length: int) -> None:
        self.length = max(0, length)
        self._frames: deque[PastFrame] = deque(maxlen=self.length)

    def __len__(self) -> int:
        return len(self._frames)

    def append(self, frame: PastFrame) -> None:
        """Add the newest frame (the oldest drops out when full)."""
        self._frames.append(frame)

    def set_pose(self, index: int, T_WC: np.ndarray) -> None:
        """Give frame `index` its tracked pose (copied), if it is held and has none yet."""
        for k in range(len(self._frames) - 1, -1, -1):
            f = self._frames[k]
            if f.index == index:
                if f.T_WC is None:
                    self._frames[k] = replace(f, T_WC=T_WC.copy())
                return

    def view(self) -> HistoryView:
        return HistoryView(tuple(self._frames))
