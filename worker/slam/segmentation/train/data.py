"""Assemble the training data a TrainConfig describes: labelled sets, held-out split, backgrounds, cut-outs,
teacher soft labels (cached)."""
from __future__ import annotations

import fnmatch
import glob
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from worker.slam.errors import ConfigError
from worker.slam.io.evaluation_only import EVALUATION_ONLY
from worker.slam.io.images import read_rgb
from worker.slam.segmentation.train.augment import Cutout, extract_cutouts
from worker.slam.segmentation.train.config import TrainConfig
from worker.slam.segmentation.train.datasets import (
    LabelledImage,
    hash_split,
    load_coco_json,
    load_mask_folder,
    load_yolo_seg,
    object_masks,
    split_holdout,
)
from worker.slam.segmentation.train.mixture import MixtureDataset, SoftSet
from worker.slam.segmentation.train.synthetic import synthetic_people
from worker.slam.segmentation.train.teacher_cache import ensemble_soft_labels

#: Never trained on, whatever a config says: the evaluation-only sets stand for footage the product has never seen
#: (no training, fine-tuning, checkpoint selection or BN statistics on their frames).
ALWAYS_FORBIDDEN = tuple(f"{{shared}}/data/{name}" for name in EVALUATION_ONLY)


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


def split_mask_dirs(cfg: TrainConfig) -> tuple[list[LabelledImage], list[LabelledImage], list[LabelledImage]]:
    """(train, val, test) of the mask folders (CCP), by `hash_split`; the benchmark's CCP test split."""
    train: list[LabelledImage] = []
    val: list[LabelledImage] = []
    test: list[LabelledImage] = []
    for folder, label in cfg.mask_dirs:
        if label not in cfg.model.classes:
            raise ConfigError(f"mask folder {folder}: class {label!r} is not one of {cfg.model.classes}")
        a, b, c = hash_split(load_mask_folder(cfg.path(folder), label), cfg.mask_test_fraction,
                             cfg.mask_val_fraction, cfg.split_seed)
        train, val, test = train + a, val + b, test + c
    return train, val, test


def split_labelled(cfg: TrainConfig) -> tuple[list[LabelledImage], list[LabelledImage], list[LabelledImage]]:
    """(train, val, held-out test) over all labelled sets: polygon sets by `holdout_every` / `val_every`,
    mask folders by their hash split."""
    items = load_labelled(cfg)
    train, held = split_holdout(items, cfg.holdout_every) if cfg.holdout_every > 1 else (items, [])
    train, val = split_holdout(train, cfg.val_every) if cfg.val_every > 1 else (train, [])
    m_train, m_val, m_test = split_mask_dirs(cfg)
    out = train + m_train, val + m_val, held + m_test
    check_allowed(cfg, [i.image for split in out for i in split])
    return out


def expand(cfg: TrainConfig, patterns: tuple[str, ...]) -> list[Path]:
    """Sorted files matching the globs; refuses any file inside a `forbidden` folder (the test frames)."""
    paths: list[Path] = []
    for pattern in patterns:
        paths += sorted(Path(p) for p in glob.glob(str(cfg.path(pattern))))
    check_allowed(cfg, paths)
    return paths


def check_allowed(cfg: TrainConfig, paths) -> None:
    """Raise ConfigError for any path inside a forbidden folder or matching a forbidden glob."""
    bad = [cfg.path(f).resolve() for f in (*ALWAYS_FORBIDDEN, *cfg.forbidden)]
    for p in paths:
        rp = Path(p).resolve()
        for b in bad:
            if rp == b or b in rp.parents or (glob.has_magic(str(b)) and fnmatch.fnmatch(str(rp), str(b))):
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
        if not item.instances and item.mask is None:
            continue
        cutouts += extract_cutouts(read_rgb(item.image), object_masks(item, classes), min_height=80, min_area=3000)
    return cutouts


def build_training_data(cfg: TrainConfig) -> TrainingData:
    train, val, held = split_labelled(cfg)
    train = train + synthetic_people(cfg)
    backgrounds = find_backgrounds(cfg)
    target_paths = expand(cfg, cfg.target_frames)
    if not train and not backgrounds:
        raise ConfigError("no training data: neither labelled images nor backgrounds were found")
    train_soft = bg_soft = None
    teachers = [cfg.path(t) for t in ((cfg.teacher, *cfg.extra_teachers) if cfg.teacher is not None else ())]
    for t in teachers:
        if not t.is_file():
            raise ConfigError(f"teacher model not found: {t}")
    cache = Path(cfg.cache_dir)
    if teachers:
        if train:
            train_soft = ensemble_soft_labels(teachers, [i.image for i in train], cfg.model.classes, cache)
        if backgrounds:
            bg_soft = ensemble_soft_labels(teachers, backgrounds, cfg.model.classes, cache)
    targets = None
    if target_paths:
        if not teachers:
            raise ConfigError("target_frames need a teacher (they are unlabelled)")
        targets = SoftSet(target_paths, np.asarray(ensemble_soft_labels(teachers, target_paths, cfg.model.classes,
                                                                        cache)))
    cutouts = build_cutouts(cfg, train) + build_cutouts(cfg, load_distractors(cfg, train))
    if targets is not None:
        cutouts += target_cutouts(cfg, targets)
    dataset = MixtureDataset(cfg, train, None if train_soft is None else np.asarray(train_soft),
                             SoftSet(backgrounds, None if bg_soft is None else np.asarray(bg_soft)), cutouts, targets)
    return TrainingData(dataset, held, val, targets)
