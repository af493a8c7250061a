"""Camera paths T_WC for the synthetic sequences (world: z up, floor at z = 0, as the TUM motion-capture frame).

`replay_path` keeps real recorded poses *unchanged* (rows of the file, sub-sampled to the frame rate), so the
written ground truth equals its source; the procedural paths mimic a hand-held RGB-D camera.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from worker.slam.errors import ConfigError
from worker.slam.io.trajectory import Trajectory, read_tum_trajectory

UP = np.array([0.0, 0.0, 1.0])


def replay_path(path: Path | str, frames: int, fps: float = 30.0) -> Trajectory:
    """The first `frames` recorded poses nearest to a `fps` grid from the file's first time stamp (poses are
    kept exactly; grid points in a gap of the recording are skipped)."""
    src = read_tum_trajectory(path)
    span = int(round((src.timestamps[-1] - src.timestamps[0]) * fps)) + 1
    grid = src.timestamps[0] + np.arange(span) / fps
    hi = np.clip(np.searchsorted(src.timestamps, grid), 1, len(src) - 1) if len(src) > 1 else np.zeros(span, int)
    lo = np.maximum(hi - 1, 0)
    nearest = np.where(np.abs(src.timestamps[lo] - grid) <= np.abs(src.timestamps[hi] - grid), lo, hi)
    close = np.abs(src.timestamps[nearest] - grid) < 0.5 / fps  # a gap in the recording leaves a frame out
    idx = np.unique(nearest[close])
    if len(idx) < frames:
        raise ConfigError(f"{path}: only {len(idx)} poses at {fps:g} Hz, asked for {frames} frames")
    return Trajectory(src.timestamps[idx[:frames]].copy(), src.poses[idx[:frames]].copy())


def look_at(position: np.ndarray, target: np.ndarray) -> np.ndarray:
    """3x3 R_WC of a camera at `position` looking at `target`, image x to the right, y down (z up world)."""
    z = target - position
    z = z / np.linalg.norm(z)
    x = np.cross(z, UP)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def _wobble(rng: np.random.Generator, t: np.ndarray, amp: float, f_lo: float, f_hi: float, n: int = 3) -> np.ndarray:
    """Sum of `n` random sinusoids (amplitude `amp` in total) with frequencies in [f_lo, f_hi] Hz, shape t."""
    out = np.zeros_like(t)
    for _ in range(n):
        out += np.sin(2 * np.pi * rng.uniform(f_lo, f_hi) * t + rng.uniform(0, 2 * np.pi))
    return out * amp / n


def _handheld(rng: np.random.Generator, t: np.ndarray, R: np.ndarray, deg: float) -> np.ndarray:
    """(N,3,3) rotations `R` with slow pan/tilt/roll of about `deg` degrees plus a small 2-5 Hz hand shake."""
    angles = np.stack([_wobble(rng, t, deg, 0.05, 0.25) + _wobble(rng, t, 0.25, 2.0, 5.0),
                       _wobble(rng, t, deg, 0.05, 0.25) + _wobble(rng, t, 0.25, 2.0, 5.0),
                       _wobble(rng, t, deg / 4, 0.05, 0.25)], axis=1)
    return R @ Rotation.from_euler("xyz", angles, degrees=True).as_matrix()


def _assemble(t: np.ndarray, R: np.ndarray, p: np.ndarray) -> Trajectory:
    poses = np.tile(np.eye(4), (len(t), 1, 1))
    poses[:, :3, :3], poses[:, :3, 3] = R, p
    return Trajectory(t, poses)


def circle_path(frames: int, rng: np.random.Generator, fps: float = 30.0, radius: float = 0.45,
                period_s: float = 14.0) -> Trajectory:
    """The camera circles at 1.4 m height, always facing a point 3 m ahead (translation and rotation)."""
    t = np.arange(frames) / fps
    a = 2 * np.pi * t / period_s
    p = np.stack([radius * np.cos(a), radius * np.sin(a), 1.4 + 0.08 * np.sin(2 * a)], axis=1)
    R = np.stack([look_at(pi, np.array([0.0, 3.0, 1.0])) for pi in p])
    return _assemble(t, _handheld(rng, t, R, 4.0), p)


def walk_path(frames: int, rng: np.random.Generator, fps: float = 30.0) -> Trajectory:
    """A hand-held camera: slow drift of +-0.5 m sideways, +-0.35 m back and forth, pans of ~12 degrees."""
    t = np.arange(frames) / fps
    p = np.stack([_wobble(rng, t, 0.5, 0.03, 0.12), _wobble(rng, t, 0.35, 0.03, 0.12),
                  1.35 + _wobble(rng, t, 0.1, 0.05, 0.2)], axis=1)
    p += _wobble(rng, t, 0.004, 2.0, 5.0)[:, None]
    R0 = look_at(np.zeros(3), np.array([0.0, 3.0, -0.45]))
    return _assemble(t, _handheld(rng, t, np.broadcast_to(R0, (frames, 3, 3)), 12.0), p)


def room_frame(traj: Trajectory) -> np.ndarray:
    """T_WR (4x4) of the room around a camera path: origin on the floor below the mean camera position, +y along
    the mean horizontal viewing direction, z up.

    A z-up world (the TUM motion-capture frame, the procedural paths) keeps its z axis and its floor at z = 0
    (lowered if a camera would be under it). Any other world (e.g. a KinectFusion frame with y down) gets its up
    from the cameras' mean image-up and a floor 1.4 m below the mean camera height."""
    up = -traj.poses[:, :3, 1].mean(axis=0)
    up /= np.linalg.norm(up)
    c = traj.positions.mean(axis=0)
    if up[2] > np.cos(np.radians(30)):
        up = UP
        floor_point = np.array([c[0], c[1], min(0.0, float(traj.positions[:, 2].min()) - 0.5)])
    else:
        heights = traj.positions @ up
        drop = min(1.4, float(heights.mean() - heights.min()) + 1.0) if len(heights) else 1.4
        floor_point = c - drop * up
    fwd = traj.poses[:, :3, 2].mean(axis=0)
    fwd = fwd - (fwd @ up) * up
    fwd /= max(np.linalg.norm(fwd), 1e-9)
    T = np.eye(4)
    T[:3, :3] = np.stack([np.cross(fwd, up), fwd, up], axis=1)
    T[:3, 3] = floor_point
    return T
