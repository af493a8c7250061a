"""The `cpu-real` recipe (issue 20): bonn_crowd_dev and the held-out 7-Scenes frames can never be trained on,
CCP bystanders are no certain negatives, hard negatives carry no person, teachers are averaged, and the preset
trains end to end on a small copy of its data."""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.worker.slam.segmentation.test_msnet_model import TINY
from worker.slam.errors import ConfigError
from worker.slam.segmentation.msnet.checkpoint import load_model
from worker.slam.segmentation.train.augment import IGNORE
from worker.slam.segmentation.train.config import load_train_config, presets
from worker.slam.segmentation.train.data import build_training_data, check_allowed, expand
from worker.slam.segmentation.train.datasets import Instance, load_mask_folder
from worker.slam.segmentation.train.mixture import MixtureDataset, SoftSet
from worker.slam.segmentation.train.trainer import train


def _images(folder: Path, names: list[str], shape=(120, 160)) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(len(names))
    out = []
    for name in names:
        cv2.imwrite(str(folder / name), rng.integers(0, 255, (*shape, 3), dtype=np.uint8))
        out.append(folder / name)
    return out


def _fake_shared(root: Path) -> Path:
    """The folders `cpu-real` reads, with a few random images each (masks: a standing box)."""
    _images(root / "data" / "7scenes_redkitchen" / "data", [f"frame-{i:06d}.color.jpg" for i in (0, 10, 950)])
    ccp = root / "data" / "ccp_persons"
    _images(ccp / "images", [f"{i:04d}.jpg" for i in range(1, 13)], (160, 100))
    (ccp / "masks").mkdir()
    for i in range(1, 13):
        m = np.zeros((160, 100), np.uint8)
        m[20:150, 30:70] = 255
        cv2.imwrite(str(ccp / "masks" / f"{i:04d}.png"), m)
    coco = root / "data" / "coco128_seg"
    _images(coco / "images", [f"{i:03d}.jpg" for i in range(10)])
    (coco / "labels").mkdir()
    for i in range(10):
        (coco / "labels" / f"{i:03d}.txt").write_text("0 0.2 0.2 0.5 0.2 0.5 0.9 0.2 0.9\n")
    _images(root / "data" / "bonn_crowd_dev" / "rgb", ["1.jpg"])
    return root


def test_bonn_crowd_dev_is_forbidden_whatever_the_config_says(tmp_path: Path) -> None:
    shared = _fake_shared(tmp_path / "shared")
    for name in ("cpu-real-mnv2", "cpu-real-mnv2-neg", "cpu-real", "cpu-real-tum-ft", "cpu-tum", "cpu", "smoke"):
        cfg = replace(presets()[name], shared_dir=str(shared), forbidden=())  # even with an emptied list
        with pytest.raises(ConfigError, match="forbidden"):
            expand(cfg, ("{shared}/data/bonn_crowd_dev/rgb/*.jpg",))
        with pytest.raises(ConfigError, match="forbidden"):
            build_training_data(replace(cfg, model=TINY, teacher=None, extra_teachers=(),
                                        target_frames=("{shared}/data/bonn_crowd_dev/rgb/*.jpg",)))
    bonn_as_masks = replace(presets()["cpu-real"], shared_dir=str(shared), model=TINY,
                            mask_dirs=(("{shared}/data/bonn_crowd_dev", "person"),))
    (shared / "data" / "bonn_crowd_dev" / "images").mkdir()
    (shared / "data" / "bonn_crowd_dev" / "masks").mkdir()
    _images(shared / "data" / "bonn_crowd_dev" / "images", ["a.jpg"])
    cv2.imwrite(str(shared / "data" / "bonn_crowd_dev" / "masks" / "a.png"), np.zeros((120, 160), np.uint8))
    with pytest.raises(ConfigError, match="forbidden"):
        build_training_data(replace(bonn_as_masks, teacher=None, extra_teachers=()))


def test_cpu_real_holds_out_the_last_7scenes_frames(tmp_path: Path) -> None:
    shared = _fake_shared(tmp_path / "shared")
    cfg = load_train_config("cpu-real", shared_dir=str(shared))
    assert [p.name for p in expand(cfg, cfg.backgrounds)] == ["frame-000000.color.jpg", "frame-000010.color.jpg"]
    with pytest.raises(ConfigError, match="forbidden"):
        check_allowed(cfg, [shared / "data" / "7scenes_redkitchen" / "data" / "frame-000950.color.jpg"])
    assert cfg.extra_teachers and cfg.mask_dirs and cfg.p_negative > 0 and cfg.mask_test_fraction >= 0.2


def test_ccp_bystanders_are_ignored_and_negatives_carry_no_person(tmp_path: Path) -> None:
    shared = _fake_shared(tmp_path / "shared")
    items = load_mask_folder(shared / "data" / "ccp_persons", "person")[:1]
    soft = np.zeros((1, 40, 25, 3), np.uint8)  # the teacher's grid over the 160x100 photo
    soft[..., 0] = 255
    soft[:, 5:35, 1:6] = (0, 255, 0)  # a bystander at the left edge, outside the labelled mask
    cfg = replace(presets()["cpu-real"], model=TINY, p_labelled=1.0, p_negative=0.0, samples_per_epoch=8)
    ds = MixtureDataset(cfg, items, soft, SoftSet([], None), [])
    hard = [ds[i]["hard"].numpy() for i in range(8)]
    assert all((h == 1).any() for h in hard) and any((h == IGNORE).sum() > 50 for h in hard)
    without = MixtureDataset(cfg, [replace(items[0], partial=False)], soft, SoftSet([], None), [])
    assert sum(int((without[i]["hard"].numpy() == IGNORE).sum()) for i in range(8)) < \
        sum(int((h == IGNORE).sum()) for h in hard)
    bgs = sorted((shared / "data" / "7scenes_redkitchen" / "data").glob("*.jpg"))[:2]
    bg_soft = np.zeros((2, 30, 40, 3), np.uint8)
    bg_soft[..., 0] = 128
    bg_soft[..., 1] = 127  # the teacher half-sees a person in a people-free frame
    people = [c for c in build_training_data(replace(cfg, shared_dir=str(shared), teacher=None,
                                                     extra_teachers=())).train.cutouts if c.label == 1]
    neg = replace(cfg, p_labelled=0.0, p_negative=1.0)
    ds = MixtureDataset(neg, items, soft, SoftSet(bgs, bg_soft), people)
    for i in range(8):
        s = ds[i]
        assert not (s["hard"].numpy() == 1).any() and float(s["soft"][1].max()) == 0.0


@pytest.mark.realdata
def test_teachers_are_averaged_on_the_first_ones_grid(shared: Path, tmp_path: Path) -> None:
    from worker.slam.segmentation.train.teacher_cache import ensemble_soft_labels, soft_labels

    images = sorted((shared / "data" / "ccp_persons" / "images").glob("*.jpg"))[:2]
    first, second = shared / "models" / "deeplabv3_257_mv_gpu.tflite", shared / "models" / "selfie_segmentation.tflite"
    classes = ("background", "person", "chair")
    a = np.asarray(soft_labels(first, images, classes, tmp_path))
    b = np.asarray(soft_labels(second, images, classes, tmp_path, grid=a.shape[1:3]))
    mean = ensemble_soft_labels([first, second], images, classes, tmp_path)
    assert mean.shape == a.shape and b.shape == a.shape
    assert np.abs(mean.astype(int) - (a.astype(int) + b.astype(int)) / 2).max() <= 1
    assert (b[..., 2] == 0).all() and (a[..., 1] > 127).mean() > 0.1  # selfie has no chair; both see the person


def test_cpu_real_trains_end_to_end_on_a_small_copy(tmp_path: Path) -> None:
    shared = _fake_shared(tmp_path / "shared")
    cfg = replace(load_train_config("cpu-real", shared_dir=str(shared)), model=TINY, teacher=None,
                  extra_teachers=(), epochs=1, samples_per_epoch=8, batch_size=4, workers=0, threads=1,
                  time_budget_min=None, out_dir=str(tmp_path / "run"), bn_recalibration_stride=1)
    data = build_training_data(cfg)
    assert len(data.held_out) >= 2 + 2 and data.val  # COCO every 5th, CCP's test share; a validation split
    model, meta = load_model(train(cfg, progress=False))
    assert model.cfg == TINY and meta["train_config"]["mask_dirs"]
    record = json.loads((tmp_path / "run" / "metrics.jsonl").read_text().splitlines()[-1])
    assert record["val_split"] == "val" and np.isfinite(record["loss"])


def test_person_free_photos_are_drawn_as_often_as_their_weight_says(tmp_path: Path) -> None:
    """`person_free_weight` w: a labelled image without people is drawn w times as often as one with people; 1 keeps
    the uniform draw of the older recipes (the same samples for the same seed)."""
    shared = _fake_shared(tmp_path / "shared")
    people = load_mask_folder(shared / "data" / "ccp_persons", "person")[:3]
    empty = [replace(people[0], mask=None, instances=(), partial=False)]  # a photo of anything else
    polygons = replace(empty[0], instances=(Instance("chair", ()), Instance("person", ())))
    assert people[0].labels == {"person"} and not empty[0].labels and polygons.labels == {"chair", "person"}
    cfg = replace(presets()["cpu-real"], model=TINY, p_labelled=1.0, p_negative=0.0, samples_per_epoch=4000)
    uniform = MixtureDataset(cfg, people + empty, None, SoftSet([], None), [])
    assert uniform.labelled_p is None
    assert [uniform._pick_labelled(np.random.default_rng(i)) for i in range(20)] == \
        [int(np.random.default_rng(i).integers(4)) for i in range(20)]
    weighted = MixtureDataset(replace(cfg, person_free_weight=3.0), people + empty, None, SoftSet([], None), [])
    assert weighted.labelled_p is not None and np.allclose(weighted.labelled_p, [1 / 6, 1 / 6, 1 / 6, 1 / 2])
    draws = [weighted._pick_labelled(np.random.default_rng([0, 0, i])) for i in range(4000)]
    assert abs(np.mean(np.asarray(draws) == 3) - 0.5) < 0.03
    assert load_train_config("cpu-real-mnv2-neg").person_free_weight > 1
