"""Pipeline stage: mark the potentially dynamic pixels of each frame (the network, or the sequence's truth masks).

Its mask goes to culling, which judges the marked objects by geometry (`worker.slam.dynamic.stage`); the network's
class map goes on too (`FrameInputs.class_labels`: previews colour by class), and the share of the frames each
class covered is the stage's summary in metrics.json (`class_share.ClassShares`).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from formats.catalog import STAGE_CONTRACTS
from worker.slam.camera import Camera
from worker.slam.config import PipelineConfig, valid
from worker.slam.errors import SequenceFormatError
from worker.slam.io.sequence import Frame
from worker.slam.segmentation.base import SegmenterConfig, make_segmenter
from worker.slam.segmentation.class_share import ClassShares, pixel_counts
from worker.slam.stages import ClassLabels, FrameInputs, StageContext


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


class Segmented(NamedTuple):
    """`SegmentationStage.prepare`'s result: the frame's classes, its potentially dynamic pixels (H, W) bool and
    each class's pixel count (K,) int64, all from the RGB alone."""

    classes: ClassLabels
    mask: np.ndarray
    counts: np.ndarray


class SegmentationStage:
    contract = STAGE_CONTRACTS["segmentation"]
    name = contract.name

    def __init__(self, config: PipelineConfig, camera: Camera) -> None:
        cfg: SegmentationStageConfig = config.section("segmentation")
        self.backend = cfg.segmenter.backend
        self.segmenter = make_segmenter(cfg.segmenter) if cfg.source == "network" else None
        self.recent: deque[np.ndarray] = deque(maxlen=cfg.memory_frames)  # the network's last masks
        self.shares: ClassShares | None = None  # the network's classes per frame, from its first frame

    def prepare(self, frame: Frame) -> Segmented | None:
        """The network's classes and potentially dynamic pixels: from the RGB alone, so the pipeline may run it
        ahead on another thread. None for the truth source (read in `process`: it needs the run's truth)."""
        if self.segmenter is None:
            return None
        res = self.segmenter.segment(frame.rgb)
        return Segmented(ClassLabels(res.labels, res.classes, res.dynamic_classes), res.dynamic_mask(),
                         pixel_counts(res.labels, len(res.classes)))

    def _remembered(self, mask: np.ndarray) -> np.ndarray:
        """The network's `mask` (H, W) bool or'ed with the last `memory_frames` ones, which it joins."""
        if not self.recent.maxlen:
            return mask
        out = np.logical_or.reduce([mask, *self.recent])
        self.recent.append(mask)
        return out

    def process(self, frame: Frame, inputs: FrameInputs, ctx: StageContext) -> FrameInputs:
        if self.segmenter is None:
            if ctx.truth is None:
                raise SequenceFormatError("segmentation.source 'truth' needs a sequence with truth/ masks",
                                          path=ctx.sequence.root if ctx.sequence is not None else None)
            mask = ctx.truth.mask(frame.index)
        else:
            got = inputs.prepared.get(self.name)
            seg = got if isinstance(got, Segmented) else self.prepare(frame)
            assert seg is not None
            if self.shares is None:
                self.shares = ClassShares(seg.classes.classes, seg.classes.dynamic_classes)
            self.shares.add(seg.counts)
            inputs.class_labels = seg.classes
            mask = self._remembered(seg.mask)
        inputs.potentially_dynamic = mask
        inputs.info["potentially_dynamic_fraction"] = float(mask.mean())
        return inputs

    def summary(self) -> dict:
        """The source; for the network its backend, classes, the potentially dynamic ones and the classes' mean
        share of the frames (`ClassShares.summary`: the network's own masks, before `memory_frames` widens them)."""
        if self.segmenter is None:
            return {"source": "truth"}
        shares = self.shares or ClassShares(self.segmenter.classes, self.segmenter.dynamic_classes)
        return {"source": "network", "backend": self.backend, "classes": list(shares.classes),
                "dynamic_classes": list(shares.dynamic), "frames": shares.frames, **shares.summary()}
