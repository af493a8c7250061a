"""Pipeline stage: mark the potentially dynamic pixels of each frame (the network, or the sequence's truth masks).

Its mask goes to culling, which judges the marked objects by geometry (`worker.slam.dynamic.stage`).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from formats.catalog import STAGE_CONTRACTS
from worker.slam.camera import Camera
from worker.slam.config import PipelineConfig, valid
from worker.slam.errors import SequenceFormatError
from worker.slam.io.sequence import Frame
from worker.slam.segmentation.base import SegmenterConfig, make_segmenter
from worker.slam.stages import FrameInputs, StageContext


@dataclass
class SegmentationStageConfig:
    """Which network marks potentially dynamic pixels."""

    segmenter: SegmenterConfig = field(default_factory=lambda: SegmenterConfig(threads=1))
    """One inference thread by default: on a small shared CPU more torch threads contend and run far slower.
    Measured: docs/results/settings.md#segmentation-segmenter-threads"""
    source: str = "network"
    """`network` (the segmenter above) or `truth`: the sequence's true dynamic masks (`truth/masks`, from the
    synthetic and augmented generators), an oracle that separates culling's errors from segmentation's."""
    memory_frames: int = valid(1, 0, 30)
    """The network's mask of a frame also marks what it marked in the previous this-many frames (0 = off): a
    person the network misses in one frame stays marked, and geometry still judges every segment.
    Measured: docs/results/settings.md#segmentation-memory_frames"""

    def __post_init__(self) -> None:
        if self.source not in ("network", "truth"):
            raise ValueError(f"segmentation.source must be 'network' or 'truth', not {self.source!r}")


class SegmentationStage:
    contract = STAGE_CONTRACTS["segmentation"]
    name = contract.name

    def __init__(self, config: PipelineConfig, camera: Camera) -> None:
        cfg: SegmentationStageConfig = config.section("segmentation")
        self.segmenter = make_segmenter(cfg.segmenter) if cfg.source == "network" else None
        self.recent: deque[np.ndarray] = deque(maxlen=cfg.memory_frames)  # the network's last masks

    def prepare(self, frame: Frame) -> np.ndarray | None:
        """The network's potentially dynamic pixels, bool (H,W): from the RGB alone, so the pipeline may run it
        ahead on another thread. None for the truth source (read in `process`: it needs the run's truth)."""
        return None if self.segmenter is None else self.segmenter.segment(frame.rgb).dynamic_mask()

    def _remembered(self, mask: np.ndarray | None) -> np.ndarray | None:
        """The network's `mask` (H, W) bool or'ed with the last `memory_frames` ones, which it joins."""
        if mask is None or not self.recent.maxlen:
            return mask
        out = np.logical_or.reduce([mask, *self.recent])
        self.recent.append(mask)
        return out

    def process(self, frame: Frame, inputs: FrameInputs, ctx: StageContext) -> FrameInputs:
        mask = inputs.prepared.get(self.name)
        if self.segmenter is None:
            if ctx.truth is None:
                raise SequenceFormatError("segmentation.source 'truth' needs a sequence with truth/ masks",
                                          path=ctx.sequence.root if ctx.sequence is not None else None)
            mask = ctx.truth.mask(frame.index)
        else:
            mask = self._remembered(mask if isinstance(mask, np.ndarray) else self.prepare(frame))
        assert isinstance(mask, np.ndarray)
        inputs.potentially_dynamic = mask
        inputs.info["potentially_dynamic_fraction"] = float(mask.mean())
        return inputs
