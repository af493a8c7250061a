"""Segmentation metrics (IoU, mIoU, per-class and mean pixel accuracy) and latency of any Segmenter."""
from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import asdict, dataclass

import numpy as np

from formats.class_palette import class_overlay
from worker.slam.segmentation.base import Segmenter

IGNORE = 255


def confusion(pred: np.ndarray, gt: np.ndarray, num_classes: int) -> np.ndarray:
    """(K, K) int64 counts, rows = ground truth, columns = prediction; gt == 255 is ignored."""
    valid = gt != IGNORE
    idx = gt[valid].astype(np.int64) * num_classes + pred[valid].astype(np.int64)
    return np.bincount(idx, minlength=num_classes * num_classes).reshape(num_classes, num_classes)


@dataclass(frozen=True)
class SegmentationMetrics:
    classes: tuple[str, ...]
    iou: dict[str, float | None]
    """Per-class IoU; None when the class appears in neither ground truth nor prediction."""
    pixel_acc: dict[str, float | None]
    """Per-class pixel accuracy (recall); None when the class is absent from the ground truth."""
    miou: float
    """Mean IoU over classes with a defined IoU."""
    mpa: float
    """Mean pixel accuracy over classes present in the ground truth."""
    images: int
    latency_ms: float | None = None
    """Mean wall-clock time of `segment` per image, when measured."""

    def to_dict(self) -> dict:
        return asdict(self)


def metrics_from_confusion(cm: np.ndarray, classes: tuple[str, ...], images: int = 0,
                           latency_ms: float | None = None) -> SegmentationMetrics:
    tp = np.diag(cm).astype(np.float64)
    gt_sum, pred_sum = cm.sum(1).astype(np.float64), cm.sum(0).astype(np.float64)
    union = gt_sum + pred_sum - tp
    iou = {c: (float(tp[k] / union[k]) if union[k] > 0 else None) for k, c in enumerate(classes)}
    acc = {c: (float(tp[k] / gt_sum[k]) if gt_sum[k] > 0 else None) for k, c in enumerate(classes)}
    ious = [v for v in iou.values() if v is not None]
    accs = [v for v in acc.values() if v is not None]
    return SegmentationMetrics(classes, iou, acc, float(np.mean(ious)) if ious else 0.0,
                               float(np.mean(accs)) if accs else 0.0, images, latency_ms)


def align_labels(pred_labels: np.ndarray, pred_classes: tuple[str, ...], classes: tuple[str, ...]) -> np.ndarray:
    """Re-index a prediction into `classes`; classes the evaluation lacks count as background (index 0)."""
    lut = np.array([classes.index(c) if c in classes else 0 for c in pred_classes], dtype=np.uint8)
    return lut[pred_labels]


def evaluate_segmenter(segmenter: Segmenter, samples: Iterable[tuple[np.ndarray, np.ndarray]],
                       classes: tuple[str, ...]) -> SegmentationMetrics:
    """samples: (rgb (H, W, 3) uint8, gt (H, W) uint8 indices into `classes`, 255 = ignore)."""
    cm = np.zeros((len(classes), len(classes)), dtype=np.int64)
    n, seconds = 0, 0.0
    for rgb, gt in samples:
        t0 = time.perf_counter()
        result = segmenter.segment(rgb)
        seconds += time.perf_counter() - t0
        cm += confusion(align_labels(result.labels, result.classes, classes), gt, len(classes))
        n += 1
    return metrics_from_confusion(cm, classes, n, 1000.0 * seconds / n if n else None)


def agreement(a: np.ndarray, b: np.ndarray, label: int) -> float:
    """IoU between two predictions' masks of one class (how well a student agrees with its teacher)."""
    ma, mb = a == label, b == label
    union = np.logical_or(ma, mb).sum()
    return float(np.logical_and(ma, mb).sum() / union) if union else 1.0


def measure_latency(segmenter: Segmenter, frames: list[np.ndarray], warmup: int = 3, repeats: int = 1) -> float:
    """Median milliseconds per `segment` call over the frames (after a warm-up)."""
    for f in frames[:warmup]:
        segmenter.segment(f)
    times = []
    for _ in range(repeats):
        for f in frames:
            t0 = time.perf_counter()
            segmenter.segment(f)
            times.append(time.perf_counter() - t0)
    return 1000.0 * float(np.median(times))


def labelled_samples(items, classes: tuple[str, ...]):
    """(rgb, gt) pairs from `train.datasets.LabelledImage`s, for `evaluate_segmenter`."""
    from worker.slam.io.images import read_rgb
    from worker.slam.segmentation.train.datasets import semantic_mask

    for item in items:
        yield read_rgb(item.image), semantic_mask(item, classes)


def tum_person_mask(mask: np.ndarray) -> np.ndarray:
    """The walking_xyz reference mask in ../shared marks people with 0 and everything else with 1
    (checked visually); returns (H, W) bool, True = person."""
    return mask == 0


def overlay(rgb: np.ndarray, labels: np.ndarray, classes: tuple[str, ...], alpha: float = 0.5) -> np.ndarray:
    """RGB uint8 visualisation: every non-background class in its palette colour (`formats.class_palette`)."""
    return class_overlay(rgb, labels, classes, classes, alpha=alpha)
