"""Relocalisation asks the vocabulary first: a view of an old place ranks that place's keyframe first."""
from __future__ import annotations

import cv2
import numpy as np

from tests.worker.slam.synthetic_room import pose, render
from worker.slam.camera import Camera
from worker.slam.presets import get_preset
from worker.slam.run.parts import build_slam
from worker.slam.tracking.relocalization import relocalisation_candidates, vocabulary_candidates

CAM = Camera(525.0, 525.0, 319.5, 239.5, 5000.0, name="synthetic")


def test_the_vocabulary_ranks_the_revisited_place_first():
    yaws = np.linspace(0, 240, 49)  # a slow turn: keyframes of many different walls
    cfg = get_preset("orb-only", {"tracking": {"keyframe_max_frames": 4}})
    parts = build_slam(CAM, cfg)
    for i, yaw in enumerate(yaws):
        rgb, depth = render(pose([0.0, 0.0, 0.0], yaw, -5))
        res = parts.tracker.track(i, i / 30, rgb, depth)
        assert res.ok
        if res.keyframe is not None:
            parts.mapper.process(res.keyframe)
            parts.tracker.on_map_updated(res)
    kfs = parts.map.keyframes
    assert len(kfs) > 8
    db = parts.tracker.places
    assert db is not None
    rgb, _ = render(pose([0.05, 0.0, 0.0], 32.0, -5))  # back near yaw 32, a little to the side
    feats = parts.tracker.extractor.extract(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY))
    best = vocabulary_candidates(parts.map, db, feats.desc)
    assert len(db) == len(kfs)  # the database caught up with the map
    assert best and abs(yaws[kfs[best[0]].frame_index] - 32.0) <= 20.0
    order = relocalisation_candidates(parts.map, 5, None, db, feats.desc)
    assert order[: len(best)] == best  # the vocabulary's candidates are tried first
    assert len(set(order)) == len(order) and set(range(len(kfs) - 5, len(kfs))) <= set(order)  # then the recent
