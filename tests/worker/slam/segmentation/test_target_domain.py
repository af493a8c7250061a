"""Target-domain distillation: teacher-labelled target frames in the sample stream, the cut-outs taken from
them, the validation split carved out of the training images, and the guard that keeps the test frame out."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.worker.slam.segmentation.test_msnet_model import TINY
from worker.slam.errors import ConfigError
from worker.slam.segmentation.train.augment import IGNORE
from worker.slam.segmentation.train.config import load_train_config, presets
from worker.slam.segmentation.train.data import build_training_data, expand, target_cutouts
from worker.slam.segmentation.train.mixture import MixtureDataset, SoftSet


def _frames(folder: Path, n: int = 3) -> list[Path]:
    folder.mkdir(parents=True)
    rng = np.random.default_rng(2)
    out = []
    for i in range(n):
        p = folder / f"{i}.png"
        cv2.imwrite(str(p), rng.integers(0, 255, (120, 160, 3), dtype=np.uint8))
        out.append(p)
    return out


def _teacher_soft(n: int) -> np.ndarray:
    """(n, 30, 40, 3) uint8: a confident person block, an unsure band, confident background elsewhere."""
    soft = np.zeros((n, 30, 40, 3), np.uint8)
    soft[..., 0] = 255
    soft[:, 5:28, 10:22] = (0, 255, 0)
    soft[:, :, 30:34] = (128, 127, 0)
    return soft


def test_target_samples_keep_teacher_people_and_ignore_unsure_pixels(tmp_path: Path) -> None:
    frames = _frames(tmp_path / "target")
    cfg = replace(presets()["smoke"], model=TINY, p_target=1.0, samples_per_epoch=4)
    ds = MixtureDataset(cfg, [], None, SoftSet([], None), [], SoftSet(frames, _teacher_soft(3)))
    s = ds[1]
    hard, soft = s["hard"].numpy(), s["soft"].numpy()
    assert (hard == 1).any() and (hard == IGNORE).any()
    assert (soft[1][hard == 1] > 0.8).all()  # person probability is kept on target frames
    assert s["kd_mask"].sum() > 0


def test_target_cutouts_come_from_teacher_person_masks(tmp_path: Path) -> None:
    frames = _frames(tmp_path / "target", 2)
    cfg = replace(presets()["smoke"], model=TINY)
    cuts = target_cutouts(cfg, SoftSet(frames, _teacher_soft(2)))
    assert len(cuts) == 2 and all(c.label == 1 for c in cuts)
    assert cuts[0].mask.shape[0] > 80  # 23 of 30 teacher rows, scaled to 120 image rows


def test_forbidden_test_folder_is_rejected(tmp_path: Path) -> None:
    _frames(tmp_path / "shared" / "data" / "tum_frames" / "fr3_walking_xyz", 1)
    cfg = replace(presets()["smoke"], shared_dir=str(tmp_path / "shared"),
                  target_frames=("{shared}/data/tum_frames/*/*.png",))
    with pytest.raises(ConfigError, match="forbidden"):
        expand(cfg, cfg.target_frames)


def test_cpu_tum_preset_trains_on_halfsphere_only_and_validates_on_a_carve_out() -> None:
    cfg = load_train_config("cpu-tum")
    assert cfg.val_every > 1 and cfg.p_target > 0
    assert all("walking_halfsphere" in t for t in cfg.target_frames)
    assert any("walking_xyz" in f for f in cfg.forbidden)


def test_validation_split_is_carved_from_training_images(tmp_path: Path) -> None:
    root = tmp_path / "data"
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    for i in range(12):
        cv2.imwrite(str(root / "images" / f"{i:02d}.png"), np.full((60, 80, 3), 10 * i, np.uint8))
        (root / "labels" / f"{i:02d}.txt").write_text("0 0.2 0.2 0.6 0.2 0.6 0.9 0.2 0.9\n")
    cfg = replace(presets()["smoke"], model=TINY, yolo_dirs=(str(root),), backgrounds=(), holdout_every=4,
                  val_every=3)
    data = build_training_data(cfg)
    train = {str(i.image) for i in data.train.labelled}
    val, held = {str(i.image) for i in data.val}, {str(i.image) for i in data.held_out}
    assert len(held) == 3 and len(val) == 3 and len(train) == 6
    assert not (train & val) and not (train & held) and not (val & held)
    assert data.selection == data.val
