"""Ground truth that is a marker's pose (Bonn): RPE against the camera's truth, ATE both ways, labelled."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from worker.slam.camera import PRESETS
from worker.slam.evaluation.groundtruth_frame import camera_groundtruth, evaluate_framed
from worker.slam.evaluation.rpe import RpeMode, relative_pose_error
from worker.slam.io.bonn import T_ROS, marker_to_camera
from worker.slam.io.trajectory import Trajectory


def _camera_path(n: int = 90, rate: float = 30.0) -> Trajectory:
    """A camera that translates and turns (yaw and pitch up to ~40 degrees), T_WC."""
    t = np.arange(n) / rate
    poses = np.repeat(np.eye(4)[None], n, axis=0)
    poses[:, :3, :3] = Rotation.from_euler("yxz", np.c_[0.7 * np.sin(t), 0.3 * np.sin(2 * t), 0.1 * t]).as_matrix()
    poses[:, :3, 3] = np.c_[0.5 * t, 0.1 * np.sin(3 * t), 0.2 * np.cos(t)]
    return Trajectory(t, poses)


def _as_bonn_marker(camera: Trajectory) -> Trajectory:
    """The raw Bonn ground truth whose correction is `camera`: T_gt = T_ROS · T_WC · (T_ROS · T_m)^-1."""
    poses = T_ROS @ camera.poses @ np.linalg.inv(T_ROS @ marker_to_camera())
    return Trajectory(camera.timestamps.copy(), poses)


def test_marker_truth_is_corrected_to_the_camera():
    cam = _camera_path()
    back = camera_groundtruth(_as_bonn_marker(cam), "bonn-marker")
    assert np.allclose(back.poses, cam.poses, atol=1e-9)
    assert camera_groundtruth(cam, "camera") is cam
    with pytest.raises(ValueError):
        camera_groundtruth(cam, "tripod")


def test_a_perfect_estimate_has_no_rpe_against_the_corrected_truth_and_a_large_one_against_the_marker():
    cam = _camera_path()
    raw = _as_bonn_marker(cam)
    lever = np.linalg.norm(marker_to_camera()[:3, 3])
    assert lever > 0.01  # the known lever arm the marker swings on
    against_marker = relative_pose_error(raw, cam)
    assert against_marker is not None and against_marker.trans.rmse > 0.005  # it measures the lever arm
    ev = evaluate_framed(raw, cam, "bonn-marker", rpe_delta_s=1.0)
    d = ev.to_dict()
    assert d["rpe"]["trans"]["rmse"] < 1e-9 and d["rpe"]["rot_deg"]["rmse"] < 1e-5
    assert d["rpe_frame"]["trans"]["rmse"] < 1e-9 and d["rpe_frame"]["delta_frames"] == 1
    assert d["rpe_frame"]["mode"] == "fixed-frames" and d["rpe_frame"]["delta_s"] is None
    assert d["ate_corrected"]["rmse"] < 1e-9
    assert d["ate"]["rmse"] > 1e-3  # the published convention scores the marker's path
    assert d["groundtruth_frame"] == "bonn-marker"
    assert d["rpe_against"] == d["ate_corrected_against"] == "camera (corrected from bonn-marker)"
    assert "published convention" in d["ate_against"]
    assert list(d)[:3] == ["ate", "matched_poses", "rpe"]  # the keys readers know stay where they were


def test_a_camera_truth_reports_the_same_ate_twice_and_labels_it():
    cam = _camera_path()
    noisy = Trajectory(cam.timestamps, cam.poses.copy())
    noisy.poses[:, :3, 3] += np.random.default_rng(1).normal(0, 0.01, (len(cam), 3))
    d = evaluate_framed(cam, noisy).to_dict()
    assert d["ate_corrected"] == d["ate"] and d["ate"]["rmse"] > 0.005
    assert d["groundtruth_frame"] == d["ate_against"] == d["rpe_against"] == "camera"
    assert d["rpe"]["delta_s"] == 1.0 and "delta_frames" not in d["rpe"]


def test_rpe_per_frame_pairs_consecutive_poses_as_the_script_does():
    """TUM's --fixed_delta --delta_unit f --delta 1: pairs (i, i+1), the one ending on the last pose dropped."""
    cam = _camera_path(40)
    est = Trajectory(cam.timestamps, cam.poses.copy())
    est.poses[:, :3, 3] += np.random.default_rng(2).normal(0, 0.002, (len(cam), 3))
    got = relative_pose_error(cam, est, RpeMode.FIXED_FRAMES, delta_frames=1)
    assert got is not None and got.pairs == len(cam) - 2
    expected = []
    for i in range(len(cam) - 2):
        e = np.linalg.inv(np.linalg.inv(est.poses[i]) @ est.poses[i + 1]) @ (
            np.linalg.inv(cam.poses[i]) @ cam.poses[i + 1])
        expected.append(np.linalg.norm(np.linalg.inv(e)[:3, 3]))
    assert got.trans.rmse == pytest.approx(float(np.sqrt(np.mean(np.square(expected)))), rel=1e-9)
    with pytest.raises(ValueError):
        relative_pose_error(cam, est, RpeMode.FIXED_FRAMES, delta_frames=0)


def test_the_bonn_preset_says_its_truth_is_the_marker():
    assert PRESETS["bonn"].groundtruth_frame == "bonn-marker"
    assert all(c.groundtruth_frame == "camera" for name, c in PRESETS.items() if name != "bonn")
