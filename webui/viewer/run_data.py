"""Everything the viewer shows of one run, read from the run's artifact folder (no pipeline import).

Artifacts used (all optional except the trajectory): `trajectory.txt` (TUM, T_WC), `groundtruth_aligned.txt`
(TUM, ground truth expressed in the estimate's frame), `keyframes.txt` (TUM), `map.ply` (binary little-endian
PLY with float x y z and uchar red green blue), `frame_stats.csv` (`frame_index`, `timestamp`, `ate_error`...),
`frame_NNNNNN_{rgb,mask,restored}.jpg` (flat names: the artifact store keeps one folder per run).
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from storage.errors import NotFound


@dataclass(frozen=True)
class Poses:
    """`timestamps` (N,), `positions` (N, 3) and `wxyz` (N, 4) unit quaternions (viser's order) of T_WC."""

    timestamps: np.ndarray
    positions: np.ndarray
    wxyz: np.ndarray


@dataclass
class RunData:
    trajectory: Poses
    groundtruth: Poses | None = None
    keyframes: Poses | None = None
    points: np.ndarray | None = None  # (M, 3) float32
    colors: np.ndarray | None = None  # (M, 3) uint8
    ate_error: np.ndarray | None = None  # (N,) metres per trajectory pose, NaN where unknown
    previews: dict[int, dict[str, Path]] = field(default_factory=dict)


def read_tum(path: Path) -> Poses:
    rows = np.loadtxt(path, comments="#", ndmin=2)
    if rows.shape[1] != 8:
        raise NotFound(f"{path.name}: not a TUM trajectory")
    q = rows[:, 4:8]  # qx qy qz qw -> viser wxyz
    return Poses(rows[:, 0], rows[:, 1:4], np.hstack([q[:, 3:4], q[:, :3]]))


_PLY_TYPES = {"float": "<f4", "float32": "<f4", "double": "<f8", "uchar": "u1", "uint8": "u1"}


def read_ply(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Vertices (M, 3) float32 and colours (M, 3) uint8 of a binary little-endian PLY point cloud."""
    with path.open("rb") as fh:
        header, props, count = [], [], 0
        while True:
            line = fh.readline().decode("ascii", "replace").strip()
            header.append(line)
            if line.startswith("element vertex"):
                count = int(line.split()[2])
            elif line.startswith("property") and len(line.split()) == 3:
                _, typ, name = line.split()
                props.append((name, _PLY_TYPES[typ]))
            elif line == "end_header" or not line and len(header) > 50:
                break
        if "format binary_little_endian 1.0" not in header:
            raise NotFound(f"{path.name}: only binary little-endian PLY is supported")
        data = np.frombuffer(fh.read(), dtype=np.dtype(props), count=count)
    xyz = np.stack([data["x"], data["y"], data["z"]], 1).astype(np.float32)
    rgb = np.stack([data["red"], data["green"], data["blue"]], 1) if "red" in (data.dtype.names or ()) else None
    return xyz, rgb


def _ate_errors(run_dir: Path, stamps: np.ndarray) -> np.ndarray | None:
    path = run_dir / "frame_stats.csv"
    if not path.is_file():
        return None
    by_time = {}
    with path.open() as fh:
        for row in csv.DictReader(fh):
            if row.get("ate_error") not in (None, "", "nan"):
                by_time[round(float(row["timestamp"]), 4)] = float(row["ate_error"])
    return np.array([by_time.get(round(t, 4), np.nan) for t in stamps])


def load_run(run_dir: Path, max_points: int = 400_000) -> RunData:
    """Read a run's artifacts; the map is subsampled to `max_points` so the browser stays responsive."""
    traj = run_dir / "trajectory.txt"
    if not traj.is_file():
        raise NotFound(f"run has no trajectory yet ({run_dir.name})")
    data = RunData(read_tum(traj))
    if (run_dir / "groundtruth_aligned.txt").is_file():
        data.groundtruth = read_tum(run_dir / "groundtruth_aligned.txt")
    if (run_dir / "keyframes.txt").is_file():
        data.keyframes = read_tum(run_dir / "keyframes.txt")
    if (run_dir / "map.ply").is_file():
        pts, cols = read_ply(run_dir / "map.ply")
        if len(pts) > max_points:
            keep = np.random.default_rng(0).choice(len(pts), max_points, replace=False)
            pts, cols = pts[keep], (cols[keep] if cols is not None else None)
        data.points, data.colors = pts, cols
    data.ate_error = _ate_errors(run_dir, data.trajectory.timestamps)
    for f in sorted(run_dir.glob("frame_*_*.*")):
        parts = f.stem.split("_")  # frame_000123_rgb
        if len(parts) == 3 and parts[1].isdigit() and f.suffix in (".jpg", ".png"):
            data.previews.setdefault(int(parts[1]), {})[parts[2]] = f
    return data
