"""The evaluation against truth, fed with the stages' outputs (not run by the stages)."""
from __future__ import annotations

import numpy as np
import pytest

from tests.worker.slam.test_truth import _write_tiny
from worker.slam.features.types import Features
from worker.slam.run.metrics import with_truth
from worker.slam.run.truth_observer import TruthObserver
from worker.slam.stages import FrameInputs
from worker.slam.truth import load_truth


def _features(uv: np.ndarray) -> Features:
    n = len(uv)
    return Features(uv.astype(np.float32), np.zeros(n, np.int32), np.ones(n, np.float32),
                    np.zeros((n, 32), np.uint8), np.ones(n, np.float32))


def test_scores_culling_on_compared_frames_and_every_restoration(tmp_path):
    frames = _write_tiny(tmp_path)
    obs = TruthObserver(load_truth(tmp_path))
    for i, (_, _, ids, bg, _) in enumerate(frames):
        ys, xs = np.nonzero(ids)
        uv = np.r_[np.c_[xs[:4], ys[:4]], [[5.0, 5.0]]]
        inputs = FrameInputs(dynamic_mask=ids > 0, extracted=_features(uv))
        if i > 0:  # the first frame: culling compared nothing
            inputs.culled = np.array([True, True, True, False, False])
        if i == 1:  # restored in `process`
            inputs.restored_rgb, inputs.restored_depth = bg, np.full(ids.shape, 1.0, np.float32)
        obs.frame(i, inputs)
    deferred = FrameInputs(restored_rgb=frames[2][3], restored_depth=np.full(frames[2][2].shape, 1.0, np.float32))
    obs.restored(2, deferred, frames[2][2] > 0)  # a deferred restoration, when it completes
    s = obs.summaries(["segmentation", "culling", "restoration"])
    assert s["culling"]["frames_scored"] == {"mask": 2, "restoration": 0} and s["culling"]["mask_iou"] == 1.0
    assert s["culling"]["feature_precision"] == 1.0 and s["culling"]["feature_recall"] == pytest.approx(3 / 4)
    assert "restoration_psnr" not in s["culling"]
    assert s["restoration"]["frames_scored"] == 2 and s["restoration"]["restoration_psnr"] == 100.0
    assert s["restoration"]["restoration_depth_median_m"] is not None
    assert set(obs.summaries(["culling"])) == {"culling"}


def test_no_restoration_no_restoration_entry_and_the_truth_entry_goes_last(tmp_path):
    _write_tiny(tmp_path)
    obs = TruthObserver(load_truth(tmp_path))
    obs.frame(0, FrameInputs())
    truth = obs.summaries(["culling", "restoration"])
    assert set(truth) == {"culling"}
    merged = with_truth({"culling": {"a": 1, "b": 2}, "restoration": {"c": 3}}, truth)
    assert list(merged["culling"]) == ["a", "b", "truth"] and merged["restoration"] == {"c": 3}
