"""Timestamped trajectories of camera poses T_WC; their TUM text format is formats.trajectory's."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

import formats.trajectory
from formats.errors import FormatError
from worker.slam.errors import TrajectoryFormatError


@dataclass(frozen=True)
class Trajectory:
    """`timestamps` (N,) float64 seconds, `poses` (N, 4, 4) float64 camera-to-world T_WC."""

    timestamps: np.ndarray
    poses: np.ndarray

    def __post_init__(self) -> None:
        if self.poses.ndim != 3 or self.poses.shape[1:] != (4, 4) or len(self.timestamps) != len(self.poses):
            raise ValueError(f"poses must be (N,4,4) with N timestamps, got {self.poses.shape}, {len(self.timestamps)}")

    def __len__(self) -> int:
        return len(self.timestamps)

    @property
    def positions(self) -> np.ndarray:
        """(N, 3) camera centres in the world frame."""
        return self.poses[:, :3, 3]


def poses_to_tum_rows(poses: np.ndarray) -> np.ndarray:
    """(N,4,4) T_WC -> (N,7) `tx ty tz qx qy qz qw` (scipy's scalar-last quaternion order)."""
    quat = Rotation.from_matrix(poses[:, :3, :3]).as_quat()
    return np.hstack([poses[:, :3, 3], quat])


def tum_rows_to_poses(rows: np.ndarray) -> np.ndarray:
    """(N,7) `tx ty tz qx qy qz qw` -> (N,4,4) T_WC."""
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(rows[:, 3:7]).as_matrix()
    poses[:, :3, 3] = rows[:, :3]
    return poses


def read_tum_trajectory(path: Path | str) -> Trajectory:
    """Read a TUM trajectory (formats.trajectory); errors name the file and line."""
    try:
        tum = formats.trajectory.read_tum_trajectory(path)
    except FormatError as exc:
        raise TrajectoryFormatError(exc.message, path=exc.path, line=exc.line) from None
    return Trajectory(tum.timestamps, tum_rows_to_poses(np.hstack([tum.positions, tum.quaternions])))


def write_tum_trajectory(path: Path | str, traj: Trajectory, header: str | None = None) -> None:
    """Write atomically (temp file + rename) so a reader never sees half a trajectory."""
    rows = poses_to_tum_rows(traj.poses)
    formats.trajectory.write_tum_trajectory(
        path, formats.trajectory.TumTrajectory(traj.timestamps, rows[:, :3], rows[:, 3:]), header)
