"""The real held-out person sets (issue 20) and pooled person scores of any Segmenter on them.

Sets, all from ../shared and none ever trained on by the `cpu-real` recipe:
- `coco-heldout`: COCO128's held-out split (every `holdout_every`-th image by path, `train.datasets.split_holdout`);
- `ccp-test`: the CCP test split (`train.datasets.hash_split` of the file names); only the main subject is
  labelled, so a bystander a model finds counts against its precision;
- `tum-walking-xyz`: the one walking_xyz frame with its hand-made mask;
- `bonn-crowd`: every n-th bonn_crowd_dev frame against teacher-made references (`reference_masks`);
- `7scenes-empty`: people-free 7-Scenes frames 900-999 (held out of `cpu-real`'s backgrounds): only the share
  of pixels marked potentially dynamic is defined there;
- `davis-movers`: davis_movers_dev (evaluation only), every frame of its seven clips against the mover's mask
  (cars, riders and their vehicles, a kite-surfer ...): does the potentially-dynamic mask see movers that are not
  only people. Skipped when the folder is absent.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from worker.slam.io.images import read_rgb
from worker.slam.segmentation.base import Segmenter
from worker.slam.segmentation.evaluate import tum_person_mask
from worker.slam.segmentation.reference_masks import IGNORE, ReferenceRecipe, reference_masks

#: The 7-Scenes frames held out of `cpu-real`'s backgrounds (its `forbidden` list names the same files).
EMPTY_FRAMES = "data/7scenes_redkitchen/data/frame-0009*.color.jpg"
BONN_TEACHER = "models/deeplabv3_mnv2_pascal_quant.tflite"


@dataclass(frozen=True)
class EvalImage:
    image: Path
    truth: Callable[[], np.ndarray] | None
    """Loads (H, W) uint8: 1 person, 0 not, 255 ignore; None = a people-free frame (all 0)."""


@dataclass(frozen=True)
class HeldOutSet:
    name: str
    images: tuple[EvalImage, ...]
    note: str
    scored: str = "person"
    """Which predicted mask is scored: "person", or "dynamic" (every potentially dynamic class: the movers of
    davis_movers_dev, and what a people-free frame must not mark)."""


@dataclass(frozen=True)
class PersonScores:
    """Person pixels pooled over a set's images (ignored pixels left out)."""

    images: int
    iou: float | None
    """None on a people-free set, like recall; precision is None also when nothing is marked."""
    precision: float | None
    recall: float | None
    marked: float
    """Share of the scored pixels predicted person."""
    ms_median: float
    """Median wall-clock ms of one `segment` call over the set's images."""


def _labelled(item, classes: tuple[str, ...]) -> Callable[[], np.ndarray]:
    """Person pixels of a labelled image (a chair drawn in front of a person hides it, as in the labels)."""
    from worker.slam.segmentation.train.datasets import semantic_mask

    person = classes.index("person")
    return lambda: (semantic_mask(item, classes) == person).astype(np.uint8)


def _png(path: Path, convert: Callable[[np.ndarray], np.ndarray]) -> Callable[[], np.ndarray]:
    def load() -> np.ndarray:
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise FileNotFoundError(f"cannot read mask {path}")
        return convert(img)
    return load


def build_sets(shared: Path, cache_dir: Path, bonn_every: int = 10) -> list[HeldOutSet]:
    """The held-out sets; COCO and CCP splits are those of the `cpu-real` training preset (shared_dir = shared).
    Bonn references are made (once, cached in `cache_dir`) with the int8 DeepLabV3 at 513."""
    from worker.slam.segmentation.train.config import load_train_config
    from worker.slam.segmentation.train.data import load_labelled, split_mask_dirs
    from worker.slam.segmentation.train.datasets import split_holdout

    cfg = load_train_config("cpu-real", shared_dir=str(shared))
    coco = split_holdout(load_labelled(cfg), cfg.holdout_every)[1]
    ccp = split_mask_dirs(cfg)[2]
    xyz = shared / "data" / "tum_frames" / "fr3_walking_xyz"
    xyz_rgb, xyz_mask = next(xyz.glob("rgb_*.png")), next(xyz.glob("person_mask_*.png"))
    bonn = sorted((shared / "data" / "bonn_crowd_dev" / "rgb").glob("*.jpg"))[::bonn_every]
    refs = reference_masks(bonn, ReferenceRecipe(shared / BONN_TEACHER), cache_dir)
    empty = sorted(shared.glob(EMPTY_FRAMES))
    return [
        HeldOutSet("coco-heldout", tuple(EvalImage(i.image, _labelled(i, cfg.model.classes)) for i in coco),
                   f"COCO128 every {cfg.holdout_every}th image by path"),
        HeldOutSet("ccp-test", tuple(EvalImage(i.image, _labelled(i, cfg.model.classes)) for i in ccp),
                   f"CCP hash split, {cfg.mask_test_fraction:.0%} test"),
        HeldOutSet("tum-walking-xyz", (EvalImage(xyz_rgb, _png(xyz_mask, lambda m: tum_person_mask(m)
                                                               .astype(np.uint8))),),
                   "hand-made mask"),
        HeldOutSet("bonn-crowd", tuple(EvalImage(f, _png(r, lambda m: m)) for f, r in zip(bonn, refs)),
                   f"every {bonn_every}th frame, references: {Path(BONN_TEACHER).stem} at 513, 3 px ignore band"),
        HeldOutSet("7scenes-empty", tuple(EvalImage(f, None) for f in empty), "people-free frames 900-999",
                   scored="dynamic"),
        *_davis(shared),
    ]


def _davis(shared: Path) -> list[HeldOutSet]:
    """davis_movers_dev as one set (its masks: 255 the moving object), or none when it is absent."""
    frames = sorted((shared / "data" / "davis_movers_dev").glob("*/images/*.jpg"))
    if not frames:
        return []
    items = tuple(EvalImage(f, _png(f.parent.parent / "masks" / f"{f.stem}.png", lambda m: (m > 127).astype(np.uint8)))
                  for f in frames)
    return [HeldOutSet("davis-movers", items, f"{len(frames)} frames of 7 clips, the mover's mask (evaluation only)",
                       scored="dynamic")]


def score_set(segmenter: Segmenter, held: HeldOutSet) -> PersonScores:
    inter = pred_n = true_n = valid_n = 0
    times = []
    for item in held.images:
        rgb = read_rgb(item.image)
        t0 = time.perf_counter()
        result = segmenter.segment(rgb)
        pred = result.dynamic_mask() if held.scored == "dynamic" else result.class_mask("person")
        times.append(time.perf_counter() - t0)
        truth = item.truth() if item.truth is not None else np.zeros(pred.shape, np.uint8)
        if truth.shape != pred.shape:
            raise ValueError(f"{item.image}: truth {truth.shape} vs prediction {pred.shape}")
        valid = truth != IGNORE
        p, t = pred & valid, (truth == 1) & valid
        inter += int((p & t).sum())
        pred_n, true_n, valid_n = pred_n + int(p.sum()), true_n + int(t.sum()), valid_n + int(valid.sum())
    if true_n == 0:  # a people-free set: only the marked share means anything
        return PersonScores(len(held.images), None, None, None, pred_n / valid_n if valid_n else 0.0,
                            1000.0 * float(np.median(times)) if times else float("nan"))
    return PersonScores(len(held.images), inter / (pred_n + true_n - inter), inter / pred_n if pred_n else None,
                        inter / true_n, pred_n / valid_n if valid_n else 0.0,
                        1000.0 * float(np.median(times)) if times else float("nan"))
