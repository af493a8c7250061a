"""A run with a multi-class segmenter: previews coloured by class, the class figures and per-class truth recall."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from formats import artifacts
from worker.slam.io.sequence import Sequence
from worker.slam.pipeline import run_pipeline
from worker.slam.presets import get_preset
from worker.slam.run.previews import PreviewPicker
from worker.slam.segmentation.classes import DEFAULT_DYNAMIC, VOC_CLASSES
from worker.slam.synth.generator import SynthConfig, generate_synthetic


def test_attached_images_join_the_previews_a_frame_brings_later() -> None:
    picker = PreviewPicker(0, 14, count=1)  # wants frame 7
    one = np.zeros((2, 2, 3), np.uint8)
    assert not picker.wants(6) and picker.wants(7)
    picker.attach(7, {"rgb": one, "classes": one})
    assert picker.claim(7)
    picker.keep(7, {"restored": one + 1, "rgb": one + 2})
    assert set(picker.kept[7]) == {"rgb", "classes", "restored"} and picker.kept[7]["rgb"][0, 0, 0] == 2
    picker.keep(8, {})  # nothing to keep: no entry
    assert 8 not in picker.kept and not picker.attached


def test_a_run_with_the_21_class_teacher_colours_previews_and_reports_classes(shared, tmp_path) -> None:
    root = tmp_path / "seq"
    generate_synthetic(root, SynthConfig(frames=14, people=2, trajectory="walk", seed=3,
                                         shared_dir=tmp_path / "noshared"))
    cfg = get_preset("no-restoration", {"segmentation": {"segmenter": {
        "backend": "tflite-teacher", "model_path": str(shared / "models/deeplabv3_257_mv_gpu.tflite"),
        "full_voc": True}}})
    out = tmp_path / "out"
    run_pipeline(Sequence(root), cfg, out)
    m = json.loads((out / artifacts.METRICS).read_text())
    seg = m["segmentation"]
    assert seg["source"] == "network" and seg["backend"] == "tflite-teacher" and seg["frames"] == 14
    assert seg["classes"] == list(VOC_CLASSES) and seg["dynamic_classes"] == list(DEFAULT_DYNAMIC)
    assert set(seg["class_share"]) <= set(DEFAULT_DYNAMIC)
    assert {e["name"] for e in seg["legend"]} == set(seg["class_share"]) | set(seg["other_class_share"])
    recall = seg["truth"]["recall_by_class"]  # the synthetic walkers are people
    assert set(recall) == {"person"} and recall["person"]["pixels"] > 0 and 0 <= recall["person"]["recall"] <= 1
    assert set(m["culling"]["truth"]["mask_recall_by_class"]) == {"person"}
    coloured = sorted(out.glob("frame_*_classes.jpg"))
    assert coloured, "class previews are written without restoration too"
    named = artifacts.parse_frame_image(coloured[0].name)
    assert named is not None and named[1] == "classes"
    rgb, classes = (cv2.imread(str(out / artifacts.frame_image(named[0], k))) for k in ("rgb", "classes"))
    assert rgb is not None and classes is not None and rgb.shape == classes.shape


@pytest.mark.parametrize("names", [["vehicle"], []])
def test_a_job_that_marks_no_people_leaves_them_unmarked(shared, tmp_path, names) -> None:
    root = tmp_path / "seq"
    generate_synthetic(root, SynthConfig(frames=4, people=2, trajectory="walk", seed=3,
                                         shared_dir=tmp_path / "noshared"))
    cfg = get_preset("no-restoration", {"segmentation": {"segmenter": {
        "backend": "tflite-teacher", "model_path": str(shared / "models/deeplabv3_257_mv_gpu.tflite"),
        "full_voc": True, "dynamic_classes": names}}})
    m = run_pipeline(Sequence(root), cfg).metrics
    assert "person" not in m["segmentation"]["dynamic_classes"]
    assert m["segmentation"]["truth"]["recall_by_class"]["person"]["recall"] == 0.0
