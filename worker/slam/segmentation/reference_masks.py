"""Reference person masks made by a teacher network, for real frames that have no hand-made masks
(bonn_crowd_dev). They are evaluation references only: cached outside the repository, never trained on.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from worker.slam.io.images import read_rgb

IGNORE = 255


@dataclass(frozen=True)
class ReferenceRecipe:
    """How the reference masks are made; part of the cache key, so a change never reuses old masks."""

    teacher: Path
    """The sharpest teacher: DeepLabV3-MNv2 PASCAL int8 at 513x513, person class."""
    ignore_band_px: int = 3
    """Pixels within this distance of the mask's border are ignored: the teacher's 513-grid edges are no
    finer than that at 640x480, and every model is scored the same way."""
    min_component_px: int = 800
    """Person blobs smaller than this are dropped: on bonn_crowd_dev they were the teacher's specks on chair
    bases and wheels (looked at by eye, MODEL_CARD.md)."""

    def key(self) -> str:
        digest = hashlib.sha1(self.teacher.read_bytes()).hexdigest()[:10]
        return f"{self.teacher.stem}-{digest}-band{self.ignore_band_px}-min{self.min_component_px}"


def with_ignore_band(person: np.ndarray, band_px: int) -> np.ndarray:
    """(H, W) bool person mask -> uint8 reference: 1 person, 0 not, 255 within `band_px` of the border."""
    ref = person.astype(np.uint8)
    if band_px <= 0:
        return ref
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * band_px + 1, 2 * band_px + 1))
    m = person.astype(np.uint8)
    ref[cv2.dilate(m, kernel) != cv2.erode(m, kernel)] = IGNORE
    return ref


def drop_small(person: np.ndarray, min_px: int) -> np.ndarray:
    """(H, W) bool without the 8-connected components of fewer than `min_px` pixels."""
    n, comp, stats, _ = cv2.connectedComponentsWithStats(person.astype(np.uint8), connectivity=8)
    keep = np.flatnonzero(stats[:, cv2.CC_STAT_AREA] >= min_px)
    return np.isin(comp, keep[keep > 0])


def reference_masks(frames: list[Path], recipe: ReferenceRecipe, cache_dir: Path) -> list[Path]:
    """One PNG per frame (1 person, 0 not, 255 ignore) in `cache_dir/<recipe key>/`, made once."""
    folder = cache_dir / recipe.key()
    folder.mkdir(parents=True, exist_ok=True)
    out = [folder / f"{f.stem}.png" for f in frames]
    todo = [(f, o) for f, o in zip(frames, out) if not o.is_file()]
    if todo:
        from worker.slam.segmentation.tflite_teacher import TfliteSegmenter

        teacher = TfliteSegmenter(recipe.teacher, threads=1)
        for frame, path in todo:
            person = drop_small(teacher.segment(read_rgb(frame)).class_mask("person"), recipe.min_component_px)
            tmp = path.with_suffix(".tmp.png")
            cv2.imwrite(str(tmp), with_ignore_band(person, recipe.ignore_band_px))
            tmp.replace(path)  # a crash never leaves a half-written reference behind
    return out
