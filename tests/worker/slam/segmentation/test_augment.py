"""Copy-paste and the sample stream: labels follow the pasted pixels; samples are functions of their seed."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from tests.worker.slam.segmentation.helpers import tiny_yolo_set
from tests.worker.slam.segmentation.test_msnet_model import TINY
from worker.slam.segmentation.train.augment import Cutout, paste
from worker.slam.segmentation.train.config import presets
from worker.slam.segmentation.train.data import build_training_data


def test_paste_writes_image_and_labels() -> None:
    rng = np.random.default_rng(0)
    rgb = np.zeros((60, 80, 3), np.uint8)
    hard = np.zeros((60, 80), np.uint8)
    soft = np.zeros((60, 80, 3), np.uint8)
    soft[..., 0] = 255
    mask = np.zeros((40, 20), np.uint8)
    mask[5:35, 5:15] = 1
    cut = Cutout(np.full((40, 20, 3), 200, np.uint8), mask, label=1)
    for _ in range(5):
        paste(rng, rgb, hard, soft, cut, (0.5, 0.6))
    person = hard == 1
    assert person.any()
    assert (soft[person] == [0, 255, 0]).all()
    assert rgb[person].mean() > 100 and rgb[hard == 0].mean() < 60


def test_mixture_samples_are_deterministic(tmp_path: Path) -> None:
    root, bg = tiny_yolo_set(tmp_path, 4, "0 0.2 0.1 0.7 0.1 0.7 0.95 0.2 0.95\n2 0.0 0.0 0.6 0.0 0.6 0.9\n")
    cfg = replace(presets()["smoke"], model=TINY, yolo_dirs=(str(root),), backgrounds=(str(bg / "*.color.jpg"),),
                  background_stride=1, holdout_every=0, samples_per_epoch=6, p_labelled=0.5)
    ds = build_training_data(cfg).train
    assert ds.people and ds.distractors  # the class-2 "car" polygons become background cut-outs
    a, b = ds[3], ds[3]
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert a["image"].shape == (3, *TINY.input_size) and a["hard"].shape == TINY.input_size
    assert not torch.equal(ds[3]["image"], ds[3 + len(ds)]["image"])  # another epoch, another sample
