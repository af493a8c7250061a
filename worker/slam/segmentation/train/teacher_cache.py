"""Teacher soft labels, computed once per (teacher, image list, grid) and cached as uint8 probabilities on disk;
several teachers are averaged on the first one's grid."""
from __future__ import annotations

import hashlib
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from worker.slam.errors import ConfigError
from worker.slam.io.images import read_rgb
from worker.slam.segmentation.classes import VOC_CLASSES


def cache_key(teacher: Path, images: list[Path], grid: tuple[int, int] | None = None, num_classes: int = 3) -> str:
    h = hashlib.sha1(str(teacher.resolve()).encode())
    for p in images:
        h.update(str(p.resolve()).encode())
    size = "" if grid is None else f"-{grid[0]}x{grid[1]}"
    k = "" if num_classes == 3 else f"-k{num_classes}"  # the 3-class caches of earlier runs keep their names
    return f"{teacher.stem}-{len(images)}{size}{k}-{h.hexdigest()[:12]}"


def soft_labels(teacher: Path, images: list[Path], classes: tuple[str, ...], cache_dir: Path,
                threads: int = 1, grid: tuple[int, int] | None = None) -> np.ndarray:
    """(N, h, w, K) uint8 probabilities x 255 over `classes` at the teacher's output grid (the whole image),
    or resampled to `grid` = (h, w).

    Teacher classes missing from `classes` are an error; our classes the teacher lacks get probability 0.
    """
    cache_dir.mkdir(parents=True, exist_ok=True)
    path = cache_dir / f"{cache_key(teacher, images, grid, len(classes))}.npy"
    if path.is_file():
        return np.load(path, mmap_mode="r")
    from worker.slam.segmentation.tflite_teacher import TfliteSegmenter

    # All 21 VOC classes when the model learns them all; else the teacher's person / chair view.
    seg = TfliteSegmenter(teacher, threads=threads, full_voc=set(VOC_CLASSES) <= set(classes))
    missing = set(seg.classes) - set(classes)
    if missing:
        raise ConfigError(f"teacher {teacher.name} predicts classes the model lacks: {sorted(missing)}")
    cols = [classes.index(c) for c in seg.classes]
    out = None
    # disable=None: no bar when stderr is not a terminal (a training log would fill with redraws)
    for i, img in enumerate(tqdm(images, desc=f"teacher {teacher.stem}", unit="img", disable=None)):
        p = seg.predict_probs(read_rgb(img))
        if grid is not None and p.shape[:2] != grid:
            # INTER_AREA takes at most 4 channels at a time (21 for a VOC model)
            p = np.concatenate([cv2.resize(np.ascontiguousarray(p[..., c:c + 4]), (grid[1], grid[0]),
                                           interpolation=cv2.INTER_AREA).reshape(*grid, -1)
                                for c in range(0, p.shape[-1], 4)], axis=-1)
        if out is None:
            out = np.zeros((len(images), *p.shape[:2], len(classes)), dtype=np.uint8)
        out[i][..., cols] = np.clip(np.round(p * 255.0), 0, 255).astype(np.uint8)
    if out is None:
        raise ConfigError("no images to label with the teacher")
    tmp = path.with_suffix(".tmp.npy")
    np.save(tmp, out)
    tmp.replace(path)  # atomic: a crash never leaves a truncated cache behind
    return out


def ensemble_soft_labels(teachers: list[Path], images: list[Path], classes: tuple[str, ...], cache_dir: Path,
                         threads: int = 1) -> np.ndarray:
    """The mean of the teachers' `soft_labels` on the first teacher's grid, (N, h, w, K) uint8. One teacher:
    its own (cached) array, unchanged."""
    first = soft_labels(teachers[0], images, classes, cache_dir, threads)
    if len(teachers) == 1:
        return first
    grid = (int(first.shape[1]), int(first.shape[2]))
    total = np.asarray(first, dtype=np.uint16).copy()
    for teacher in teachers[1:]:
        total += soft_labels(teacher, images, classes, cache_dir, threads, grid)
    return np.round(total / len(teachers)).astype(np.uint8)
