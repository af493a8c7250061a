"""Timestamped trajectories of camera poses T_WC and their TUM text format (`t tx ty tz qx qy qz qw`)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

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
    """Read a TUM trajectory; `#` comments and blank lines are skipped; errors name the file and line."""
    path = Path(path)
    if not path.is_file():
        raise TrajectoryFormatError("file not found", path=path)
    stamps, rows = [], []
    with path.open("r", encoding="utf-8", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            text = line.strip()
            if not text or text.startswith("#"):
                continue
            parts = text.replace(",", " ").split()
            if len(parts) != 8:
                raise TrajectoryFormatError(f"expected 8 values (t tx ty tz qx qy qz qw), got {len(parts)}",
                                            path=path, line=lineno)
            try:
                vals = [float(v) for v in parts]
            except ValueError:
                raise TrajectoryFormatError(f"not a number in {text!r}", path=path, line=lineno) from None
            if not np.all(np.isfinite(vals)):
                raise TrajectoryFormatError("non-finite value", path=path, line=lineno)
            if abs(np.linalg.norm(vals[4:8]) - 1.0) > 0.1:
                raise TrajectoryFormatError("quaternion is not unit length", path=path, line=lineno)
            stamps.append(vals[0])
            rows.append(vals[1:])
    if not rows:
        raise TrajectoryFormatError("no poses", path=path)
    t = np.asarray(stamps)
    order = np.argsort(t, kind="stable")
    return Trajectory(t[order], tum_rows_to_poses(np.asarray(rows)[order]))


def write_tum_trajectory(path: Path | str, traj: Trajectory, header: str | None = None) -> None:
    """Write atomically (temp file + rename) so a reader never sees half a trajectory."""
    path = Path(path)
    rows = poses_to_tum_rows(traj.poses)
    tmp = path.with_name(path.name + ".part")
    with tmp.open("w") as fh:
        fh.write(f"# {header or 'trajectory T_WC'}\n# timestamp tx ty tz qx qy qz qw\n")
        for t, r in zip(traj.timestamps, rows):
            fh.write(f"{t:.6f} " + " ".join(f"{v:.7f}" for v in r) + "\n")
    tmp.replace(path)
