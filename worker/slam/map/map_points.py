"""Map points as growable arrays (struct of arrays), so projection search over thousands stays vectorised."""
from __future__ import annotations

import numpy as np


class MapPoints:
    """World points with what tracking needs to find them again.

    Per point: `pos` (3,) world metres; `desc` (32,) uint8 ORB descriptor; `normal` (3,) unit mean viewing
    direction; `max_dist` distance at which it would be seen at octave 0 (scale invariance range);
    `n_obs` keyframes observing it; `visible`/`found` frames it projected into / was matched in;
    `first_kf` creating keyframe id (its reference for loop correction); `alive`.
    """

    def __init__(self, capacity: int = 4096) -> None:
        self.n = 0
        self.pos = np.zeros((capacity, 3))
        self.desc = np.zeros((capacity, 32), np.uint8)
        self.normal = np.zeros((capacity, 3))
        self.max_dist = np.zeros(capacity)
        self.n_obs = np.zeros(capacity, np.int32)
        self.visible = np.zeros(capacity, np.int32)
        self.found = np.zeros(capacity, np.int32)
        self.first_kf = np.zeros(capacity, np.int64)
        self.alive = np.zeros(capacity, bool)

    def __len__(self) -> int:
        return self.n

    @property
    def n_alive(self) -> int:
        return int(self.alive[: self.n].sum())

    def _grow(self, need: int) -> None:
        cap = len(self.pos)
        if self.n + need <= cap:
            return
        new = max(cap * 2, self.n + need)
        for name in ("pos", "desc", "normal", "max_dist", "n_obs", "visible", "found", "first_kf", "alive"):
            old = getattr(self, name)
            arr = np.zeros((new,) + old.shape[1:], old.dtype)
            arr[: self.n] = old[: self.n]
            setattr(self, name, arr)

    def add(self, pos: np.ndarray, desc: np.ndarray, cam_center: np.ndarray, octave: np.ndarray,
            scale_factor: float, kf_id: int) -> np.ndarray:
        """Add (M,3) world points seen from `cam_center` (3,) at keypoint `octave` (M,). Returns (M,) ids."""
        m = len(pos)
        self._grow(m)
        ids = np.arange(self.n, self.n + m)
        ray = pos - cam_center
        dist = np.linalg.norm(ray, axis=1)
        self.pos[ids] = pos
        self.desc[ids] = desc
        self.normal[ids] = ray / np.maximum(dist, 1e-9)[:, None]
        self.max_dist[ids] = dist * scale_factor ** octave
        self.n_obs[ids] = 1
        self.visible[ids] = 1
        self.found[ids] = 1
        self.first_kf[ids] = kf_id
        self.alive[ids] = True
        self.n += m
        return ids

    def kill(self, ids: np.ndarray) -> None:
        self.alive[ids] = False
