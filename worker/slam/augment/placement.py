"""Where the inserted people walk: straight, eased strolls on the floor that cross the camera's view.

Each walk lasts a few seconds. It starts just outside one side of the view at the start frame and ends just
outside the other side at the end frame, at a distance in front of the camera chosen from the real scene depth
(so the person is mostly in front of the furniture, sometimes behind a counter). People take turns: walker k's
walks are shifted by a fraction of a walk so that one or two are usually in view. Static instances (a parked
chair) are "walks" that start and end at the same floor point, in view of the camera somewhere in the sequence.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from worker.slam.augment.floor import Floor
from worker.slam.camera import Camera


@dataclass(frozen=True)
class PlacementConfig:
    """How people walk through the real scene."""

    walk_s: tuple[float, float] = (5.0, 8.0)
    """Duration range of one walk across the view (seconds)."""
    depth_fraction: tuple[float, float] = (0.6, 0.9)
    """Distance as a fraction of the median scene depth in the middle of the view."""
    distance_m: tuple[float, float] = (1.4, 3.2)
    """Clamp of that distance (metres)."""
    height_m: tuple[float, float] = (1.6, 1.85)
    """Height of the people (metres)."""
    overshoot: float = 1.25
    """Start/end lateral offset as a multiple of the half view width at that distance (> 1: off screen)."""


@dataclass(frozen=True)
class Walk:
    """One walk of sprite `sprite` from floor point `start` (3,) to `end` (3,) over frames `first`..`last`;
    `facing` (3,) a fixed horizontal world normal for a static instance (None: it turns to the camera)."""

    walker: int
    sprite: int
    first: int
    last: int
    start: np.ndarray
    end: np.ndarray
    height: float
    facing: np.ndarray | None = None

    def position(self, frame: int) -> np.ndarray:
        """Floor point under the person at `frame` (smooth start and stop)."""
        s = (frame - self.first) / max(self.last - self.first, 1)
        s = 0.5 - 0.5 * np.cos(np.pi * np.clip(s, 0.0, 1.0))
        return self.start + s * (self.end - self.start)

    def bob(self, frame: int, step_m: float = 0.7, amplitude_m: float = 0.02) -> float:
        """Vertical bounce (m) of a walking body: highest mid-step, one bounce per `step_m` walked."""
        walked = float(np.linalg.norm(self.position(frame) - self.start))
        return amplitude_m * abs(np.sin(np.pi * walked / step_m))


def _anchor(T_WC: np.ndarray, floor: Floor, distance: float, lateral: float) -> np.ndarray:
    """Floor point `distance` m ahead of the camera (horizontally) and `lateral` m to its right."""
    fwd = T_WC[:3, 2] - (T_WC[:3, 2] @ floor.up) * floor.up
    fwd /= max(np.linalg.norm(fwd), 1e-9)
    right = np.cross(fwd, floor.up)  # camera x (right) for an upright camera with y down
    return floor.project(T_WC[:3, 3] + distance * fwd + lateral * right)


def plan_walks(poses: np.ndarray, center_depth: np.ndarray, floor: Floor, camera: Camera, people: int,
               n_sprites: int, fps: float, rng: np.random.Generator,
               cfg: PlacementConfig = PlacementConfig(),
               heights: Callable[[int], tuple[float, float]] | None = None,
               pick: Callable[[np.random.Generator], int] | None = None) -> list[Walk]:
    """Walks covering the whole sequence: `poses` (N, 4, 4) T_WC, `center_depth` (N,) median depth (m) of the
    middle of each frame (0 = unknown), `people` walkers taking turns. `heights(sprite)`: the height range (m) of
    a sprite's class (default `cfg.height_m`, people); `pick(rng)`: a sprite index (default: uniform)."""
    n = len(poses)
    half_fov = camera.width / 2 / camera.fx  # tan of the half horizontal field of view
    known = center_depth[center_depth > 0]
    fallback = float(np.median(known)) if len(known) else 2.5
    walks: list[Walk] = []
    for k in range(people):
        frame = -int(rng.uniform(0, 1) * cfg.walk_s[1] * fps * k / max(people, 1))
        while frame < n:
            length = int(rng.uniform(*cfg.walk_s) * fps)
            first, last = frame, frame + length
            a, b = max(first, 0), min(last, n - 1)
            if b - a >= min(fps, n // 2):  # skip slivers at the ends of the sequence
                span = center_depth[a:b + 1]
                mid_depth = float(np.median(span[span > 0])) if (span > 0).any() else fallback
                dist = float(np.clip(rng.uniform(*cfg.depth_fraction) * mid_depth, *cfg.distance_m))
                side = 1.0 if rng.random() < 0.5 else -1.0
                off = cfg.overshoot * half_fov * dist
                # Start and end are placed against the camera pose at the clipped ends of the walk, so the
                # person crosses the view even while the camera pans.
                start = _anchor(poses[a], floor, dist, -side * off)
                end = _anchor(poses[b], floor, dist, side * off)
                sprite = pick(rng) if pick else int(rng.integers(n_sprites))
                height = float(rng.uniform(*(heights(sprite) if heights else cfg.height_m)))
                walks.append(Walk(k + 1, sprite, a, b, start, end, height))
            frame = last + int(rng.uniform(0.0, 1.0) * fps)
    return walks


def plan_static(poses: np.ndarray, center_depth: np.ndarray, floor: Floor, camera: Camera, count: int,
                first_id: int, pick: Callable[[np.random.Generator], int], rng: np.random.Generator,
                heights: Callable[[int], tuple[float, float]], cfg: PlacementConfig = PlacementConfig()) -> list[Walk]:
    """`count` instances that never move (ids `first_id`, `first_id + 1`, ...): instance j stands on the floor
    in view of the camera at frame (j + 0.5) / count of the sequence (`poses` (N, 4, 4) T_WC, `center_depth` (N,)
    as in `plan_walks`), at a distance chosen like a walk's and within the middle 60 % of the view's width, facing
    that camera within 40 degrees, and keeping that orientation; `pick(rng)` chooses its sprite, `heights(sprite)`
    its height range (m)."""
    n = len(poses)
    half_fov = camera.width / 2 / camera.fx
    known = center_depth[center_depth > 0]
    fallback = float(np.median(known)) if len(known) else 2.5
    out = []
    for j in range(count):
        f = min(int((j + 0.5) / count * n), n - 1)
        depth = float(center_depth[f]) if center_depth[f] > 0 else fallback
        dist = float(np.clip(rng.uniform(*cfg.depth_fraction) * depth, *cfg.distance_m))
        spot = _anchor(poses[f], floor, dist, float(rng.uniform(-0.6, 0.6)) * half_fov * dist)
        sprite = pick(rng)
        height = float(rng.uniform(*heights(sprite)))
        facing = _yawed(poses[f][:3, 3] - spot, floor.up, np.radians(rng.uniform(-40.0, 40.0)))
        out.append(Walk(first_id + j, sprite, 0, n - 1, spot, spot.copy(), height, facing))
    return out


def _yawed(v: np.ndarray, up: np.ndarray, angle: float) -> np.ndarray:
    """Horizontal unit vector (3,): `v` (3,) without its `up` component, turned by `angle` rad about `up`."""
    h = v - (v @ up) * up
    h /= max(np.linalg.norm(h), 1e-9)
    return h * np.cos(angle) + np.cross(up, h) * np.sin(angle)
