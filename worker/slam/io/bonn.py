"""Bonn RGB-D Dynamic ground truth: the motion-capture marker's pose, corrected to the camera's.

The dataset documents T_WC(t) = T_ROS · T_gt(t) · T_ROS · T_m. T_m's 3x3 block carries a small scale, so it is
projected onto the nearest rotation (SVD) first. A sequence whose camera says ``groundtruth_frame: bonn-marker``
(the ``bonn`` preset) is scored with it (worker.slam.evaluation.groundtruth_frame): RPE against the corrected
(camera) ground truth only, ATE both against the raw GT (as published Bonn results are) and the corrected one.
"""
from __future__ import annotations

import numpy as np

from worker.slam.io.trajectory import Trajectory

T_ROS = np.array([[-1.0, 0, 0, 0], [0, 0, 1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])
T_M_RAW = np.array([[1.0157, 0.1828, -0.2389, 0.0113],
                    [0.0009, -0.8431, -0.6413, -0.0098],
                    [-0.3009, 0.6147, -0.8085, 0.0111],
                    [0, 0, 0, 1.0]])


def nearest_rotation(m: np.ndarray) -> np.ndarray:
    """3x3 -> the closest proper rotation in the Frobenius norm."""
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def marker_to_camera() -> np.ndarray:
    """T_m with its rotation block made orthonormal (4x4)."""
    t = T_M_RAW.copy()
    t[:3, :3] = nearest_rotation(t[:3, :3])
    return t


def correct_bonn_groundtruth(raw: Trajectory) -> Trajectory:
    """Raw Bonn GT (marker poses) -> camera poses T_WC."""
    poses = T_ROS @ raw.poses @ T_ROS @ marker_to_camera()
    return Trajectory(raw.timestamps.copy(), poses)
