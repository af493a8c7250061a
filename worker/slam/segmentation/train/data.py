"""Assemble the training data a TrainConfig describes: labelled sets, held-out split, backgrounds, cut-outs,
teacher soft labels (cached)."""
from __future__ import annotations

import glob
from dataclasses import dataclass
from pathlib import Path

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


def find_backgrounds(cfg: TrainConfig) -> list[Path]:
    paths: list[Path] = []
    for pattern in cfg.backgrounds:
        paths += sorted(Path(p) for p in glob.glob(str(cfg.path(pattern))))
    return paths[::max(cfg.background_stride, 1)]


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
    train, held = split_holdout(items, cfg.holdout_every) if cfg.holdout_every > 1 else (items, [])
    backgrounds = find_backgrounds(cfg)
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
    dataset = MixtureDataset(cfg, train, None if train_soft is None else np.asarray(train_soft),
                             SoftSet(backgrounds, None if bg_soft is None else np.asarray(bg_soft)),
                             build_cutouts(cfg, train) + build_cutouts(cfg, load_distractors(cfg, train)))
    return TrainingData(dataset, held)
