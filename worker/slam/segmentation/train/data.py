"""Assemble the training data a TrainConfig describes: labelled sets, held-out split, backgrounds, cut-outs,
teacher soft labels (cached)."""
from __future__ import annotations

import glob
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from worker.slam.errors import ConfigError
from worker.slam.io.images import read_rgb
from worker.slam.segmentation.train.augment import Cutout, extract_cutouts
from worker.slam.segmentation.train.config import TrainConfig
from worker.slam.segmentation.train.datasets import (
    LabelledImage,
    instance_mask,
    load_coco_json,
    load_yolo_seg,
    split_holdout,
)
from worker.slam.segmentation.train.mixture import MixtureDataset, SoftSet
from worker.slam.segmentation.train.teacher_cache import soft_labels


@dataclass(frozen=True)
class TrainingData:
    train: MixtureDataset
    held_out: list[LabelledImage]
    """The test split (every `holdout_every`-th image); validated on only when there is no `val` split."""
    val: list[LabelledImage] = field(default_factory=list)
    """Validation split carved out of the training images (`val_every`), used for selection."""
    targets: SoftSet | None = None
    """Target-domain training frames with teacher probabilities (for the training-set agreement figure)."""

    @property
    def selection(self) -> list[LabelledImage]:
        return self.val or self.held_out


def load_labelled(cfg: TrainConfig) -> list[LabelledImage]:
    classes = cfg.model.classes
    ids = {i: name for name, i in cfg.yolo_class_ids.items() if name in classes}
    items: list[LabelledImage] = []
    for d in cfg.yolo_dirs:
        items += load_yolo_seg(cfg.path(d), ids)
    names = {k: v for k, v in cfg.coco_names.items() if v in classes}
    for ann, img_dir in cfg.coco_json:
        items += load_coco_json(cfg.path(ann), cfg.path(img_dir), names)
    return items


def expand(cfg: TrainConfig, patterns: tuple[str, ...]) -> list[Path]:
    """Sorted files matching the globs; refuses any file inside a `forbidden` folder (the test frames)."""
    paths: list[Path] = []
    for pattern in patterns:
        paths += sorted(Path(p) for p in glob.glob(str(cfg.path(pattern))))
    check_allowed(cfg, paths)
    return paths


def check_allowed(cfg: TrainConfig, paths) -> None:
    bad = [cfg.path(f).resolve() for f in cfg.forbidden]
    for p in paths:
        rp = Path(p).resolve()
        for b in bad:
            if rp == b or b in rp.parents:
                raise ConfigError(f"{p} is inside a forbidden (test) folder {b}; it must not be trained on")


def find_backgrounds(cfg: TrainConfig) -> list[Path]:
    return expand(cfg, cfg.backgrounds)[::max(cfg.background_stride, 1)]


def target_cutouts(cfg: TrainConfig, targets: SoftSet) -> list[Cutout]:
    """Person cut-outs from the teacher's person masks on the target frames (one per connected component)."""
    if targets.soft is None or "person" not in cfg.model.classes:
        return []
    p = cfg.model.classes.index("person")
    out: list[Cutout] = []
    for path, soft in zip(targets.images, targets.soft):
        rgb = read_rgb(path)
        prob = cv2.resize(np.ascontiguousarray(soft[..., p]), (rgb.shape[1], rgb.shape[0]),
                          interpolation=cv2.INTER_LINEAR)
        n, comp = cv2.connectedComponents((prob > 127).astype(np.uint8))
        out += extract_cutouts(rgb, [((comp == i).astype(np.uint8), p) for i in range(1, n)], min_height=80,
                               min_area=3000)
    return out


DISTRACTOR = "__distractor__"


def load_distractors(cfg: TrainConfig, train: list[LabelledImage]) -> list[LabelledImage]:
    """Instances of every other YOLO class in the training images, to be pasted as background."""
    ours = set(cfg.yolo_class_ids.values())
    others = {i: DISTRACTOR for i in range(1000) if i not in ours}
    keep = {str(i.image) for i in train}
    items: list[LabelledImage] = []
    for d in cfg.yolo_dirs:
        items += [i for i in load_yolo_seg(cfg.path(d), others) if str(i.image) in keep]
    return items


def build_cutouts(cfg: TrainConfig, items: list[LabelledImage]) -> list[Cutout]:
    """Cut-outs from the training split only (never from held-out images); distractors get label 0."""
    classes = cfg.model.classes
    cutouts: list[Cutout] = []
    for item in items:
        if not item.instances:
            continue
        rgb = read_rgb(item.image)
        masks = [(instance_mask(i, item.size), classes.index(i.label) if i.label in classes else 0)
                 for i in item.instances]
        cutouts += extract_cutouts(rgb, masks, min_height=80, min_area=3000)
    return cutouts


def build_training_data(cfg: TrainConfig) -> TrainingData:
    items = load_labelled(cfg)
    check_allowed(cfg, [i.image for i in items])
    train, held = split_holdout(items, cfg.holdout_every) if cfg.holdout_every > 1 else (items, [])
    train, val = split_holdout(train, cfg.val_every) if cfg.val_every > 1 else (train, [])
    backgrounds = find_backgrounds(cfg)
    target_paths = expand(cfg, cfg.target_frames)
    if not train and not backgrounds:
        raise ConfigError("no training data: neither labelled images nor backgrounds were found")
    train_soft = bg_soft = None
    if cfg.teacher is not None:
        teacher = cfg.path(cfg.teacher)
        if not teacher.is_file():
            raise ConfigError(f"teacher model not found: {teacher}")
        cache = Path(cfg.cache_dir)
        if train:
            train_soft = soft_labels(teacher, [i.image for i in train], cfg.model.classes, cache)
        if backgrounds:
            bg_soft = soft_labels(teacher, backgrounds, cfg.model.classes, cache)
    targets = None
    if target_paths:
        if cfg.teacher is None:
            raise ConfigError("target_frames need a teacher (they are unlabelled)")
        targets = SoftSet(target_paths, np.asarray(soft_labels(cfg.path(cfg.teacher), target_paths,
                                                               cfg.model.classes, Path(cfg.cache_dir))))
    cutouts = build_cutouts(cfg, train) + build_cutouts(cfg, load_distractors(cfg, train))
    if targets is not None:
        cutouts += target_cutouts(cfg, targets)
    dataset = MixtureDataset(cfg, train, None if train_soft is None else np.asarray(train_soft),
                             SoftSet(backgrounds, None if bg_soft is None else np.asarray(bg_soft)), cutouts, targets)
    return TrainingData(dataset, held, val, targets)
