"""Small builders shared by the segmentation tests."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import torch


def randomise_batchnorm(model: torch.nn.Module) -> torch.nn.Module:
    """Every BatchNorm2d's statistics and affine parameters moved away from their defaults (so folding or
    copying them is tested), in place; returns `model`."""
    for m in model.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            assert m.running_mean is not None and m.running_var is not None
            m.running_mean.uniform_(-0.5, 0.5)
            m.running_var.uniform_(0.5, 2.0)
            m.weight.data.uniform_(0.5, 1.5)
            m.bias.data.uniform_(-0.2, 0.2)
    return model


def tiny_yolo_set(tmp_path: Path, n: int, labels: str) -> tuple[Path, Path]:
    """(YOLO-seg folder, background folder) of `n` random 160x120 images each, every image labelled `labels`
    (YOLO-seg lines); backgrounds are `*.color.jpg`."""
    root, bg = tmp_path / "data", tmp_path / "bg"
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    bg.mkdir()
    rng = np.random.default_rng(1)
    for i in range(n):
        cv2.imwrite(str(root / "images" / f"{i}.png"), rng.integers(0, 255, (120, 160, 3), dtype=np.uint8))
        (root / "labels" / f"{i}.txt").write_text(labels)
        cv2.imwrite(str(bg / f"{i}.color.jpg"), rng.integers(0, 255, (120, 160, 3), dtype=np.uint8))
    return root, bg
