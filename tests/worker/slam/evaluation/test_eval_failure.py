"""An evaluation that fails numerically is an EvaluationError saying why (never numpy's LinAlgError), so the
pipeline keeps the run's trajectory, map and other metrics and reports ATE/RPE as unavailable."""
from __future__ import annotations

import json

import numpy as np
import pytest

from tests.worker.slam.evaluation.test_metrics import _random_walk
from tests.worker.slam.synthetic_room import trajectory, write_sequence
from worker.slam.errors import EvaluationError
from worker.slam.evaluation import metrics
from worker.slam.io.sequence import Sequence
from worker.slam.io.trajectory import Trajectory
from worker.slam.pipeline import run_pipeline
from worker.slam.presets import get_preset


def test_a_non_finite_estimate_is_an_evaluation_error_not_an_svd_failure():
    gt = _random_walk()
    poses = gt.poses.copy()
    poses[5, :3, 3] = np.nan  # was: numpy.linalg.LinAlgError "SVD did not converge"
    with pytest.raises(EvaluationError, match="non-finite poses") as info:
        metrics.evaluate(gt, Trajectory(gt.timestamps, poses))
    assert info.value.detail == {"reason": "non_finite_poses"}


def test_poses_too_far_apart_give_no_infinite_metrics():
    gt = _random_walk()
    far = gt.poses.copy()
    far[:, :3, 3] *= 1e200  # was: an ATE of inf, which no JSON column stores
    with pytest.raises(EvaluationError):
        metrics.evaluate(Trajectory(gt.timestamps, far), gt)


def test_the_run_keeps_its_outputs_when_evaluation_fails(tmp_path, monkeypatch):
    seq = write_sequence(tmp_path / "room", trajectory(12, yaw_span_deg=10))

    def fail(*_a, **_k):
        raise np.linalg.LinAlgError("SVD did not converge")

    monkeypatch.setattr(metrics, "relative_pose_error", fail)
    res = run_pipeline(Sequence(seq), get_preset("orb-only"), tmp_path / "out")
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert "SVD did not converge" in m["evaluation_error"] and "ate" not in m
    assert m["frames"] == 12 and m["dense_points"] > 0 and res.tracked.all()
    for name in ("trajectory.txt", "keyframes.txt", "map.ply", "config.json"):
        assert (tmp_path / "out" / name).is_file(), name
