"""Runs that track nothing fail saying why; runs that lose some frames write only the tracked frames' poses
(TUM tools expect estimated poses only) and say so in metrics.json."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from tests.worker.slam.io.helpers import write_sequence as write_tiny
from tests.worker.slam.synthetic_room import trajectory, write_sequence
from worker.slam.camera import camera_from_preset
from worker.slam.errors import SlamError, TrackingFailed
from worker.slam.io.sequence import Sequence
from worker.slam.io.trajectory import read_tum_trajectory
from worker.slam.pipeline import run_pipeline
from worker.slam.presets import get_preset


def _zero_depth(folder, frames) -> None:
    for i in frames:
        path = folder / f"depth/{i:05d}.png"
        cv2.imwrite(str(path), np.zeros_like(cv2.imread(str(path), cv2.IMREAD_UNCHANGED)))


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    return write_sequence(tmp_path_factory.mktemp("room"), trajectory(10, yaw_span_deg=10))


def test_all_zero_depth_fails_with_the_reason_and_writes_nothing(tmp_path, room):
    import shutil

    seq = shutil.copytree(room, tmp_path / "seq")
    _zero_depth(seq, range(10))
    with pytest.raises(TrackingFailed, match="no frame was tracked: 10 frames .*no feature had a valid depth") as info:
        run_pipeline(Sequence(seq), get_preset("orb-only"), tmp_path / "out")
    assert isinstance(info.value, SlamError) and info.value.code == "tracking_failed"
    assert info.value.detail["frames"] == 10 and info.value.detail["most_features_with_depth"] == 0
    assert not (tmp_path / "out" / "trajectory.txt").exists()


def test_images_too_small_for_orb_fail_saying_so(tmp_path):
    seq = write_tiny(tmp_path / "tiny", n=4, size=(32, 24))
    with pytest.raises(TrackingFailed, match="no frame was tracked: 4 frames of 32x24, and no frame had any ORB"):
        run_pipeline(Sequence(seq, camera_from_preset("tum3")), get_preset("orb-only"))


def test_lost_frames_get_no_pose_and_are_flagged(tmp_path, room):
    import shutil

    seq = shutil.copytree(room, tmp_path / "seq")
    _zero_depth(seq, (0, 1))  # no map can start on them: the first two frames are lost
    res = run_pipeline(Sequence(seq), get_preset("orb-only"), tmp_path / "out")
    assert res.tracked.tolist() == [False, False] + [True] * 8
    stamps = Sequence(seq).timestamps
    written = read_tum_trajectory(tmp_path / "out" / "trajectory.txt")
    assert np.allclose(written.timestamps, stamps[2:], atol=1e-6) and len(res.trajectory) == 8
    assert "2 of 10 not tracked" in (tmp_path / "out" / "trajectory.txt").read_text().splitlines()[0]
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert (m["frames"], m["tracked"], m["lost"], m["tracked_fraction"]) == (10, 8, 2, 0.8)
    assert m["warnings"] and "2 of 10 frames" in m["warnings"][0] and "frames 0..1" in m["warnings"][0]
    assert m["matched_poses"] == 8  # scored on the tracked frames only
    rows = res.frame_stats
    assert [r["tracked"] for r in rows] == res.tracked.tolist()
    assert rows[0]["ate_error"] is None and rows[5]["ate_error"] is not None


def test_a_fully_tracked_run_has_no_warning(tmp_path, room):
    res = run_pipeline(Sequence(room), get_preset("orb-only"), tmp_path / "out")
    assert res.tracked.all() and res.metrics["warnings"] == [] and res.metrics["tracked_fraction"] == 1.0
    head = (tmp_path / "out" / "trajectory.txt").read_text().splitlines()[0]
    assert head == "# VTD-SLAM trajectory T_WC (every frame)"


def test_a_frame_lost_mid_run_has_no_pose(tmp_path):
    """The view jumps to the opposite wall: that frame is lost (it starts a new map), the next one tracks."""
    from tests.worker.slam.synthetic_room import pose

    behind = pose([0.1, 0.0, 0.2], 180)
    poses = np.concatenate([trajectory(6, yaw_span_deg=5), [behind, behind @ pose([0.01, 0.0, 0.005], 0.5)]])
    seq = Sequence(write_sequence(tmp_path / "seq", poses))
    res = run_pipeline(seq, get_preset("orb-only", {"dense.enabled": False}), tmp_path / "out")
    assert res.tracked.tolist() == [True] * 6 + [False, True]
    written = read_tum_trajectory(tmp_path / "out" / "trajectory.txt")
    assert np.allclose(written.timestamps, np.delete(seq.timestamps, 6), atol=1e-6)
    assert "frames 6..6" in res.metrics["warnings"][0]
