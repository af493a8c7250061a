"""Everything the viewer shows of one run, read from the run's artifact folder (no pipeline import).

Artifacts used (all optional except the trajectory): `trajectory.txt` (TUM, T_WC of the tracked frames: pose k
is frame k only when no frame was lost, so frames are matched by timestamp), `groundtruth_aligned.txt`
(TUM, ground truth expressed in the estimate's frame), `keyframes.txt` (TUM), `map.ply` (binary little-endian
PLY with float x y z and uchar red green blue), `frame_stats.csv` (formats.frame_stats: `frame_index`,
`timestamp`, `ate_error`...), `frame_NNNNNN_{rgb,classes,mask,restored}.jpg` (flat names: the artifact store keeps
one folder per run), `metrics.json` (its segmentation section's `legend`: the classes the previews are coloured by).
"""
from __future__ import annotations

import os
import stat
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from formats import artifacts
from formats.errors import FormatError
from formats.frame_stats import load_frame_stats
from formats.ply import read_ply
from formats.trajectory import read_tum_trajectory
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
    frame_index: np.ndarray | None = None
    """(N,) int: the frame of each trajectory pose (trajectory.txt holds only tracked frames, so pose k is not
    frame k when frames were lost), from the frame stats by timestamp; -1 where unknown."""
    previews: dict[int, dict[str, Path]] = field(default_factory=dict)
    legend: list[dict] = field(default_factory=list)
    """The segmentation classes seen in the run and their colours (`formats.class_palette.legend`), if any."""


def read_tum(path: Path) -> Poses:
    """A TUM trajectory file (formats.trajectory) as viser wants it; a malformed file is NotFound."""
    try:
        tum = read_tum_trajectory(path)
    except FormatError as exc:
        raise NotFound(f"{path.name}: not a TUM trajectory ({exc.message})") from None
    q = tum.quaternions  # qx qy qz qw -> viser wxyz
    return Poses(tum.timestamps, tum.positions, np.hstack([q[:, 3:4], q[:, :3]]))


def _read_map(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    try:
        return read_ply(path)
    except FormatError as exc:
        raise NotFound(f"{path.name}: {exc.message}") from None


def _per_pose(run_dir: Path, stamps: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Each pose's ATE error (m) and frame index from the run's frame stats (formats.frame_stats), matched by
    timestamp; (None, None) without a readable file (both are optional)."""
    path = run_dir / artifacts.FRAME_STATS
    try:
        rows = load_frame_stats(path) if path.is_file() else None
    except FormatError:
        return None, None
    if rows is None:
        return None, None
    errors = {round(r.timestamp, 4): r.ate_error for r in rows if r.ate_error is not None}
    frames = {round(r.timestamp, 4): r.frame_index for r in rows}
    return (np.array([errors.get(round(t, 4), np.nan) for t in stamps]),
            np.array([frames.get(round(t, 4), -1) for t in stamps], dtype=np.int64))


def read_legend(run_dir: Path) -> list[dict]:
    """metrics.json's `segmentation.legend` (entries with a name and a #rrggbb colour); [] when absent or unreadable."""
    import json

    try:
        seg = json.loads((run_dir / artifacts.METRICS).read_text(encoding="utf-8")).get("segmentation")
    except (OSError, ValueError, AttributeError):
        return []
    entries = seg.get("legend") if isinstance(seg, dict) else None
    return valid_legend(entries)


def valid_legend(entries: object) -> list[dict]:
    """The well-formed entries of a legend list (`name` str, `colour` #rrggbb, `dynamic` bool)."""
    if not isinstance(entries, list):
        return []
    return [{"name": e["name"], "colour": e["colour"], "dynamic": bool(e.get("dynamic"))} for e in entries
            if isinstance(e, dict) and isinstance(e.get("name"), str) and isinstance(e.get("colour"), str)
            and len(e["colour"]) == 7 and e["colour"].startswith("#")]


def _is_file(path: Path) -> bool:
    """``Path.is_file`` that lets a PermissionError through (it would say "no such file")."""
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except (FileNotFoundError, NotADirectoryError):
        return False


def load_run(run_dir: Path, max_points: int = 400_000) -> RunData:
    """Read a run's artifacts; the map is subsampled to `max_points` so the browser stays responsive."""
    traj = run_dir / artifacts.TRAJECTORY
    if not _is_file(traj):
        raise NotFound(f"run has no trajectory yet ({run_dir.name})")
    data = RunData(read_tum(traj))
    if _is_file(run_dir / artifacts.GROUNDTRUTH_ALIGNED):
        data.groundtruth = read_tum(run_dir / artifacts.GROUNDTRUTH_ALIGNED)
    if _is_file(run_dir / artifacts.KEYFRAMES):
        try:
            data.keyframes = read_tum(run_dir / artifacts.KEYFRAMES)
        except NotFound:  # an empty keyframes file (no keyframe): the rest of the run still shows
            data.keyframes = None
    if _is_file(run_dir / artifacts.MAP):
        pts, cols = _read_map(run_dir / artifacts.MAP)
        if len(pts) > max_points:
            keep = np.random.default_rng(0).choice(len(pts), max_points, replace=False)
            pts, cols = pts[keep], (cols[keep] if cols is not None else None)
        data.points, data.colors = pts, cols
    data.ate_error, data.frame_index = _per_pose(run_dir, data.trajectory.timestamps)
    data.legend = read_legend(run_dir)
    for f in sorted(run_dir.glob("frame_*_*.*")):
        named = artifacts.parse_frame_image(f.name)
        if named is not None:
            data.previews.setdefault(named[0], {})[named[1]] = f
    return data
