"""Segmentation stage: marks potentially dynamic pixels. `make_segmenter(SegmenterConfig())` gives MSNET."""
from worker.slam.segmentation.base import (
    SegmentationError,
    SegmentationResult,
    Segmenter,
    SegmenterConfig,
    available_backends,
    make_segmenter,
)

__all__ = ["SegmentationError", "SegmentationResult", "Segmenter", "SegmenterConfig", "available_backends",
           "make_segmenter"]
