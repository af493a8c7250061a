"""Issue 61's must: a bag written from bonn_crowd_dev (ROS 1 and ROS 2, raw and compressed colour) imports to a
sequence that runs to the same trajectory and ATE as the folder itself."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from storage.ingest.bag import import_bag
from tests.storage.ingest.rosbags_write import folder_to_bag

FRAMES = 120  # the empty office and the first people walking in (they enter near frame 80)


def _run(root: Path):
    from worker.slam.camera import camera_from_preset
    from worker.slam.io.sequence import Sequence
    from worker.slam.pipeline import run_pipeline
    from worker.slam.presets import get_preset

    seq = Sequence(root, camera_from_preset("bonn"))
    return run_pipeline(seq, get_preset("no-restoration", {"dense.enabled": False}), max_frames=FRAMES)


@pytest.fixture(scope="module")
def folder_run(bonn_dev: Path):
    return _run(bonn_dev)


@pytest.mark.realdata
@pytest.mark.parametrize(("kind", "colour", "depth_enc"), [("ros1", "compressed", "16UC1"),
                                                           ("mcap", "rgb8", "32FC1"),
                                                           ("sqlite3", "compressed", "32FC1")])
def test_bag_runs_to_the_folders_ate(tmp_path, bonn_dev, folder_run, kind, colour, depth_enc):
    bag = folder_to_bag(bonn_dev, tmp_path / ("bonn.bag" if kind == "ros1" else "bonn_ros2"), FRAMES, depth_enc,
                        kind=kind, colour=colour)
    result = import_bag(bag, tmp_path / "seq")
    assert result.frames == FRAMES and result.gt_poses > FRAMES
    run = _run(tmp_path / "seq")
    ours, theirs = run.trajectory, folder_run.trajectory
    assert len(ours.timestamps) == len(theirs.timestamps) == FRAMES  # every frame tracked in both
    np.testing.assert_allclose(ours.timestamps, theirs.timestamps, atol=1e-6)
    np.testing.assert_allclose(ours.poses, theirs.poses, atol=1e-9)
    assert run.metrics["ate"]["rmse"] == pytest.approx(folder_run.metrics["ate"]["rmse"], rel=1e-6)
