"""The segmentation stage's contract: a `Segmenter` protocol, its result type, its config and a factory.

Backends are imported lazily by the factory so that choosing `tflite-teacher` never imports torch and choosing
`msnet` never imports ai-edge-litert.
"""
from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Protocol, runtime_checkable

import numpy as np
from numba import njit

from worker.slam.config import valid
from worker.slam.errors import ConfigError, SlamError
from worker.slam.segmentation.classes import DYNAMIC_GROUPS
from worker.slam.segmentation.dynamic_names import DYNAMIC_NAMES, resolve_for_segmenter


class SegmentationError(SlamError):
    """A segmenter got an input it cannot process, or its model file is unusable."""

    code = "segmentation_failed"


@dataclass(frozen=True)
class SegmentationResult:
    """Per-pixel classes of one frame, at the input frame's resolution."""

    labels: np.ndarray
    """(H, W) uint8 index into `classes` (argmax of `probs` when present)."""
    classes: tuple[str, ...]
    """Class names; index 0 is the background."""
    dynamic_classes: tuple[str, ...]
    """Classes the pipeline treats as potentially dynamic (a subset of `classes`)."""
    probs: np.ndarray | None = None
    """(H, W, K) float32 per-class probabilities summing to 1, or None for label-only backends."""

    def class_mask(self, name: str) -> np.ndarray:
        """(H, W) bool mask of one class; all False when the backend does not know the class."""
        if name not in self.classes:
            return np.zeros(self.labels.shape, dtype=bool)
        return self.labels == self.classes.index(name)

    def dynamic_mask(self) -> np.ndarray:
        """(H, W) bool mask of every potentially dynamic class."""
        table = np.zeros(256, bool)  # a lookup per label: a third of np.isin's time on a VGA frame
        table[[self.classes.index(c) for c in self.dynamic_classes if c in self.classes]] = True
        return np.take(table, self.labels)


def labels_of(probs: np.ndarray) -> np.ndarray:
    """(H, W) uint8 labels from (H, W, K) class scores: `probs.argmax(-1)` (the first of equal maxima, the first
    NaN if any), compiled: numpy's argmax over so short an axis took ~2 ms per VGA frame."""
    return _argmax_last(np.ascontiguousarray(probs))


@njit(cache=True, nogil=True)
def _argmax_last(probs):
    h, w, k = probs.shape
    out = np.zeros((h, w), np.uint8)
    for y in range(h):
        for x in range(w):
            best = probs[y, x, 0]
            if best != best:  # NaN: numpy's argmax returns the first one
                continue
            for c in range(1, k):
                v = probs[y, x, c]
                if v != v:
                    out[y, x] = c
                    break
                if v > best:
                    best = v
                    out[y, x] = c
    return out


@runtime_checkable
class Segmenter(Protocol):
    """Anything that turns an RGB frame into a `SegmentationResult`."""

    classes: tuple[str, ...]
    dynamic_classes: tuple[str, ...]

    def segment(self, rgb: np.ndarray) -> SegmentationResult:
        """rgb: (H, W, 3) uint8, RGB order. Returns labels (and probabilities) at (H, W)."""
        ...


@dataclass(frozen=True)
class SegmenterConfig:
    """Which segmenter the pipeline uses and how it runs."""

    backend: str = "msnet"
    """Registered backend name: `msnet` (default, the project's network) or `tflite-teacher`."""
    checkpoint: str | None = None
    """msnet: checkpoint file; None = the shipped `segmentation/weights/msnet_default.pt`."""
    model_path: str | None = None
    """tflite-teacher: a user-supplied .tflite model (DeepLabV3 PASCAL-VOC logits or class map, or a
    one-channel person-probability model such as MediaPipe selfie segmentation)."""
    device: str = "auto"
    """msnet: `auto` (CUDA when present, else CPU), `cpu` or `cuda`."""
    threads: int | None = None
    """CPU threads for inference; None leaves the library default (the process may share cores)."""
    with_probs: bool = False
    """Also return per-class probabilities at full resolution (a resize per class: ~20 ms a VGA frame with 21
    classes). The pipeline needs only the labels, which msnet then upsamples from the classes that win a grid cell
    (`msnet.segmenter.candidate_labels`)."""
    dynamic_classes: tuple[str, ...] | None = field(default=None, metadata={"choices": DYNAMIC_NAMES})
    """The potentially dynamic classes, by class name or group (`person`, `animal`, `vehicle`, `object`; see
    `segmentation.classes.DYNAMIC_GROUPS`), resolved against the backend's classes (`resolve_for_segmenter`: a
    class it does not know is not covered; a name that is neither a group, a VOC nor a COCO class is an error).
    None keeps the backend's default: the checkpoint's own (the shipped 21-class MSNET: `DEFAULT_DYNAMIC`, the
    person, animal and vehicle groups; the earlier person/chair one: person), the teacher's person and chair (with
    `full_voc`: `DEFAULT_DYNAMIC`)."""
    full_voc: bool = False
    """tflite-teacher: all 21 PASCAL VOC classes of a DeepLabV3 model instead of background/person/chair (the
    others counted as background); its default potentially dynamic classes are then `DEFAULT_DYNAMIC`."""
    guided_radius: int = valid(0, 0, 64)
    """msnet: upsample the network's probabilities with a fast guided filter (grey image as guide) of this
    radius, in pixels of its output grid (13 ≈ 32 px at 640x480); 0 = plain bilinear upsampling. Off: the
    masks' borders follow image edges and segmentation scores improve a little, but SLAM gets worse (see
    weights/MODEL_CARD.md, "Guided upsampling")."""
    guided_eps: float = valid(0.01, 1e-06, 10.0)
    """msnet: the guided filter's edge sensitivity (variance of grey levels in [0, 1]); larger = smoother."""

    def __post_init__(self) -> None:
        names = self.dynamic_classes
        if isinstance(names, str):  # "person,vehicle" from a form or a command line
            names = tuple(n.strip() for n in names.split(",") if n.strip())
        if names is not None:
            names = tuple(names)
            unknown = [n for n in names if n not in DYNAMIC_NAMES]
            if unknown:
                raise ValueError(f"unknown potentially dynamic class {unknown[0]!r}: name a group "
                                 f"({', '.join(DYNAMIC_GROUPS)}), a VOC class or a COCO class")
            object.__setattr__(self, "dynamic_classes", names)  # frozen: a list from JSON becomes a tuple
        if self.guided_radius < 0:
            raise ValueError(f"guided_radius must be >= 0, not {self.guided_radius}")
        if not self.guided_eps > 0:
            raise ValueError(f"guided_eps must be > 0, not {self.guided_eps}")

    def to_dict(self) -> dict:
        return asdict(self)


def check_rgb(rgb: np.ndarray) -> None:
    """Cheap entry check shared by the backends."""
    if not isinstance(rgb, np.ndarray) or rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        desc = f"{rgb.dtype} {rgb.shape}" if isinstance(rgb, np.ndarray) else type(rgb).__name__
        raise SegmentationError(f"segmenter expects an RGB uint8 (H, W, 3) image, got {desc}")
    if rgb.shape[0] < 8 or rgb.shape[1] < 8:
        raise SegmentationError(f"image too small to segment: {rgb.shape[1]}x{rgb.shape[0]}")


# name -> "module:factory"; a factory takes a SegmenterConfig and returns a Segmenter.
_BACKENDS = MappingProxyType({
    "msnet": "worker.slam.segmentation.msnet.segmenter:MsnetSegmenter.from_config",
    "tflite-teacher": "worker.slam.segmentation.tflite_teacher:TfliteSegmenter.from_config",
})


def available_backends() -> tuple[str, ...]:
    return tuple(_BACKENDS)


def _resolve(spec: str) -> Callable[[SegmenterConfig], Segmenter]:
    module, _, attr = spec.partition(":")
    obj = importlib.import_module(module)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj  # type: ignore[return-value]


def make_segmenter(config: SegmenterConfig | None = None) -> Segmenter:
    """Build the configured segmenter, its potentially dynamic classes resolved from the config's names and groups.
    Raises ConfigError for an unknown backend, a missing model file or an unknown class name."""
    config = config or SegmenterConfig()
    if config.backend not in _BACKENDS:
        raise ConfigError(f"unknown segmentation backend {config.backend!r}",
                          detail={"available": list(_BACKENDS)})
    for p in (config.checkpoint, config.model_path):
        if p is not None and not Path(p).is_file():
            raise ConfigError(f"segmentation model file not found: {p}", detail={"path": str(p)})
    segmenter = _resolve(_BACKENDS[config.backend])(config)
    if config.dynamic_classes is not None:  # names and groups -> the backend's class names
        segmenter.dynamic_classes = resolve_for_segmenter(config.dynamic_classes, segmenter.classes)
    return segmenter
