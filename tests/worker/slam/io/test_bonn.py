import numpy as np

from worker.slam.io.bonn import T_ROS, correct_bonn_groundtruth, marker_to_camera
from worker.slam.io.trajectory import Trajectory


def test_marker_to_camera_is_rigid():
    r = marker_to_camera()[:3, :3]
    assert np.allclose(r @ r.T, np.eye(3), atol=1e-9) and np.isclose(np.linalg.det(r), 1.0)


def test_correction_formula_and_rigidity():
    raw = np.tile(np.eye(4), (2, 1, 1))
    raw[1, :3, 3] = [1, 2, 3]
    out = correct_bonn_groundtruth(Trajectory(np.array([0.0, 1.0]), raw)).poses
    assert np.allclose(out[1], T_ROS @ raw[1] @ T_ROS @ marker_to_camera())
    # relative camera motion keeps the marker's travelled distance
    assert np.isclose(np.linalg.norm(out[1, :3, 3] - out[0, :3, 3]), np.linalg.norm([1, 2, 3]))
