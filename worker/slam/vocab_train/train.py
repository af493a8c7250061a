"""Train the ORB vocabulary: images -> the runtime's ORB descriptors -> tree + idf -> .npz, with a summary.

Only images the project may train on (7-Scenes, COCO128, CCP, synthetic renders): folders of the
evaluation-only sequences (DATA.md: bonn_crowd_dev, davis_movers_dev) are refused.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from worker.slam.config import FeatureConfig
from worker.slam.features.orb import OrbExtractor
from worker.slam.features.vocabulary import Vocabulary
from worker.slam.io.evaluation_only import is_evaluation_only
from worker.slam.vocab_train.tree import build_tree, vocabulary_from_tree

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")


@dataclass
class VocabTrainConfig:
    """How the tree is trained (defaults: the shipped vocabulary's recipe)."""

    k: int = 10
    """Children per node."""
    levels: int = 4
    """Depth of the tree: at most k^levels words."""
    max_descriptors: int = 400_000
    """Descriptors clustered (a random subset when the images give more); idf uses all of them."""
    max_iter: int = 15
    """k-majority iterations per node at most."""
    seed: int = 0
    features: FeatureConfig = field(default_factory=FeatureConfig)
    """The runtime's ORB settings, so that training descriptors are the ones tracking extracts."""


@dataclass(frozen=True)
class VocabTrainResult:
    vocabulary: Vocabulary
    n_images: int
    n_descriptors: int
    n_clustered: int
    seconds: float


def image_paths(folders: list[Path], every: int = 1) -> list[Path]:
    """Colour images under `folders` (recursive, sorted; depth maps skipped), every `every`-th of each folder."""
    out: list[Path] = []
    for folder in folders:
        if is_evaluation_only(folder):
            raise ValueError(f"{folder} is evaluation-only data (DATA.md): never train on it")
        if not folder.is_dir():
            raise FileNotFoundError(f"no such folder: {folder}")
        found = sorted(p for p in folder.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES
                       and "depth" not in p.name and "depth" not in p.parent.name)
        out += found[::every]
    return out


def extract_all(paths: list[Path], cfg: FeatureConfig) -> list[np.ndarray]:
    """(N_i, 32) uint8 descriptors of each image, with the runtime's extractor."""
    orb = OrbExtractor(cfg)
    out = []
    for p in paths:
        gray = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        if gray is None:
            log.warning("unreadable image skipped: %s", p)
            continue
        out.append(orb.extract(gray).desc)
    return out


def train_vocabulary(paths: list[Path], cfg: VocabTrainConfig,
                     progress: Callable[[str], None] | None = None) -> VocabTrainResult:
    """The vocabulary of the images at `paths`."""
    t0 = time.perf_counter()
    say = progress or log.info
    say(f"extracting ORB from {len(paths)} images")
    per_image = extract_all(paths, cfg.features)
    pool = np.vstack([d for d in per_image if len(d)])
    rng = np.random.default_rng(cfg.seed)
    sub = pool if len(pool) <= cfg.max_descriptors else pool[rng.choice(len(pool), cfg.max_descriptors,
                                                                        replace=False)]
    say(f"clustering {len(sub)} of {len(pool)} descriptors (k={cfg.k}, L={cfg.levels})")
    centres, children, depth = build_tree(sub, cfg.k, cfg.levels, rng, cfg.max_iter)
    say("idf weights")
    voc = vocabulary_from_tree(centres, children, depth, per_image)
    return VocabTrainResult(voc, len(per_image), len(pool), len(sub), time.perf_counter() - t0)
