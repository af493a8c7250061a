"""Culling compares with the past frame the run's history holds `lag_frames` back; it keeps no frames itself."""
from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from worker.slam.camera import PRESETS
from worker.slam.dynamic import stage as culling_stage
from worker.slam.dynamic.stage import CullingStage
from worker.slam.history import FrameHistory, PastFrame
from worker.slam.io.sequence import Frame
from worker.slam.presets import get_preset
from worker.slam.stages import FrameInputs, StageContext


def _frame(i: int) -> Frame:
    rng = np.random.default_rng(1)
    grey = cv2.GaussianBlur(rng.integers(0, 255, (480, 640), dtype=np.uint8), (5, 5), 0)
    return Frame(i, i / 30, np.repeat(grey[..., None], 3, axis=2), np.full((480, 640), 2.0, np.float32))


def test_culling_reads_the_history_and_keeps_none(monkeypatch):
    config = get_preset("geometry-only", {"culling.lag_frames": 2})
    camera = PRESETS["tum3"]
    stage = CullingStage(config, camera)
    assert stage.history_frames == 2
    ctx = StageContext(camera, config, None, T_WC_pred=np.eye(4))
    first = stage.process(_frame(0), FrameInputs(), ctx)
    assert first.extracted is not None and len(first.extracted) and first.culled is None
    again = stage.process(_frame(1), FrameInputs(), ctx)  # an empty history again: nothing to compare with
    assert again.culled is None and stage.summary()["frames_compared"] == 0
    history = FrameHistory(3)
    for i in range(3):
        history.append(PastFrame(i, i / 30, _frame(i).rgb, np.full((480, 640), 1.0 + i, np.float32),
                                 extracted=first.extracted, T_WC=np.eye(4)))
    compared_with: list[float] = []
    real = culling_stage.cull_frame

    def spy(*args, **kwargs):
        compared_with.append(float(args[8][0, 0]))  # the past frame's depth
        return real(*args, **kwargs)

    monkeypatch.setattr(culling_stage, "cull_frame", spy)
    out = stage.process(_frame(3), FrameInputs(), replace(ctx, history=history.view()))
    assert compared_with == [2.0]  # frame 1: `lag_frames` back, not the oldest held
    assert out.culled is not None and out.extracted is not None and out.culled.shape == (len(out.extracted),)
    assert stage.summary()["frames_compared"] == 1
