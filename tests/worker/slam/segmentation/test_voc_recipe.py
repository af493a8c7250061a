"""The multi-class recipe's parts (issue 57): 21-class teacher labels, a person network's weights carried into a
VOC network, synthetic people with their exact masks, and held-out sets scored on the potentially dynamic mask."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from cli.msnet_cmd import render_synthetic_rooms
from worker.slam.segmentation.classes import COCO_TO_VOC, DEFAULT_DYNAMIC, VOC_CLASSES, resolve_dynamic
from worker.slam.segmentation.msnet import MsnetConfig, build_msnet
from worker.slam.segmentation.msnet.checkpoint import save_model
from worker.slam.segmentation.train.config import load_train_config
from worker.slam.segmentation.train.datasets import read_mask
from worker.slam.segmentation.train.synthetic import synthetic_people
from worker.slam.segmentation.train.trainer import load_matching

TINY = MsnetConfig(input_size=(64, 96), stem_channels=8, widths=(16, 16, 24), depths=(1, 1, 1), heads=2,
                   embed_dim=16, filters_per_class=4, decoder_layers=1)


def test_person_weights_carry_into_a_voc_network(tmp_path: Path) -> None:
    torch.manual_seed(0)
    person = build_msnet(TINY)
    save_model(tmp_path / "person.pt", person)
    voc = build_msnet(replace(TINY, classes=VOC_CLASSES, dynamic_classes=DEFAULT_DYNAMIC, class_head="presence"))
    fresh = load_matching(voc, tmp_path / "person.pt")
    ours, theirs = voc.state_dict(), person.state_dict()
    assert torch.equal(ours["guidance.embed.weight"], theirs["guidance.embed.weight"])
    assert any(k.startswith("backbone.") for k in ours) and not any(k.startswith("backbone.") for k in fresh)
    assert "enhancement.decoder.queries" in fresh  # one query per class: 21 now, 3 before
    assert "enhancement.decoder.class_head.fc2.weight" in fresh


def test_voc_preset_maps_coco_ids_onto_voc_names() -> None:
    cfg = load_train_config("cpu-voc")
    assert cfg.model.classes == VOC_CLASSES and cfg.model.class_head == "presence"
    assert cfg.yolo_class_ids["person"] == 0 and cfg.yolo_class_ids["motorbike"] == 3
    assert cfg.yolo_class_ids["tvmonitor"] == 62 and len(cfg.yolo_class_ids) == len(COCO_TO_VOC) == 20
    assert len(cfg.class_weights) == len(VOC_CLASSES)
    assert set(cfg.synth_seeds).isdisjoint(range(4))  # the benchmark's synthetic seeds are never trained on


def test_dynamic_groups_resolve_against_a_segmenters_classes() -> None:
    assert resolve_dynamic(["animal", "person"], VOC_CLASSES) == ("bird", "cat", "cow", "dog", "horse", "person",
                                                                   "sheep")
    assert resolve_dynamic(["vehicle", "person"], ("background", "person", "chair")) == ("person",)
    with pytest.raises(Exception, match="unknown potentially dynamic class"):
        resolve_dynamic(["unicorn"], VOC_CLASSES)


def test_synthetic_people_are_exactly_labelled(tmp_path: Path) -> None:
    cfg = replace(load_train_config("cpu-voc"), synth_seeds=(7,), synth_frames=6, synth_stride=3,
                  synth_people=2, cache_dir=str(tmp_path), shared_dir=str(tmp_path / "none"))
    with pytest.raises(Exception, match="is missing"):
        synthetic_people(cfg)
    render_synthetic_rooms(cfg)
    items = synthetic_people(cfg)
    assert [i.image.name for i in items] == ["000000.png", "000003.png"]
    assert all(i.image.is_file() and not i.partial for i in items)
    masks = [read_mask(i) for i in items]
    assert all(m.dtype == np.uint8 and set(np.unique(m)) <= {0, 1} for m in masks)
    assert all(i.size == m.shape for i, m in zip(items, masks, strict=True))  # the room camera's (H, W)
    assert sum(int(m.sum()) for m in masks) > 0  # the walkers are in view
    mtime = items[0].image.stat().st_mtime_ns
    render_synthetic_rooms(cfg)  # rendered once, then read from the cache folder
    assert items[0].image.stat().st_mtime_ns == mtime


@pytest.mark.realdata
def test_teacher_labels_all_21_voc_classes(shared: Path, tmp_path: Path) -> None:
    pytest.importorskip("ai_edge_litert")
    from worker.slam.segmentation.train.teacher_cache import ensemble_soft_labels

    teachers = [shared / "models" / name for name in ("deeplabv3_257_mv_gpu.tflite",
                                                      "deeplabv3_mnv2_pascal_quant.tflite")]
    if not all(t.is_file() for t in teachers):
        pytest.skip("teachers not present")
    images = sorted((shared / "data" / "coco128_seg" / "images").rglob("*.jpg"))[:2]
    soft = ensemble_soft_labels(teachers, images, VOC_CLASSES, tmp_path)
    assert soft.shape[0] == 2 and soft.shape[-1] == len(VOC_CLASSES)
    total = soft.astype(np.int32).sum(-1)
    assert np.abs(total - 255).max() <= 12  # probabilities (rounded to 1/255, averaged over two teachers)
    assert (soft[..., 1:].max(axis=(1, 2)) > 127).any()  # some object class is found
