"""The sparse map: keyframes, map points and the covisibility graph between keyframes."""
from __future__ import annotations

import numpy as np

from worker.slam.map.keyframe import KeyFrame
from worker.slam.map.map_points import MapPoints


class Map:
    """Keyframes by id (ids are 0..n-1 in insertion order), points, and covisibility weights.

    `covis[i][j]` = number of map points keyframes i and j both observe (at insertion time of the newer).
    """

    def __init__(self) -> None:
        self.keyframes: list[KeyFrame] = []
        self.points = MapPoints()
        self.covis: dict[int, dict[int, int]] = {}

    def __len__(self) -> int:
        return len(self.keyframes)

    def add_keyframe(self, kf: KeyFrame) -> None:
        if kf.id != len(self.keyframes):
            raise ValueError(f"keyframe id {kf.id} out of order")
        self.keyframes.append(kf)
        self.covis[kf.id] = {}
        self.update_covisibility(kf.id)

    def alive_ids(self, kf: KeyFrame) -> np.ndarray:
        """Sorted unique alive point ids observed by `kf`."""
        ids = kf.point_ids[kf.point_ids >= 0]
        return np.unique(ids[self.points.alive[ids]])

    def update_covisibility(self, kf_id: int, min_shared: int = 1) -> None:
        mine = self.alive_ids(self.keyframes[kf_id])
        for other in self.keyframes:
            if other.id == kf_id:
                continue
            shared = len(np.intersect1d(mine, self.alive_ids(other), assume_unique=True))
            if shared >= min_shared:
                self.covis[kf_id][other.id] = shared
                self.covis[other.id][kf_id] = shared
            else:
                self.covis[kf_id].pop(other.id, None)
                self.covis[other.id].pop(kf_id, None)

    def best_covisible(self, kf_id: int, n: int, min_weight: int = 1) -> list[int]:
        """Up to `n` keyframe ids sharing the most points with `kf_id`, strongest first."""
        items = [(w, j) for j, w in self.covis.get(kf_id, {}).items() if w >= min_weight]
        items.sort(reverse=True)
        return [j for _, j in items[:n]]

    def move_keyframes_since(self, first_kf: int, C: np.ndarray) -> None:
        """Apply world correction `C` (4,4; new world <- old world) to keyframes >= `first_kf` and the points
        they created: a map started after a loss, moved rigidly onto the map it is merged into."""
        for kf in self.keyframes[first_kf:]:
            kf.T_WC = C @ kf.T_WC
        p = self.points
        mine = np.flatnonzero(p.first_kf[: p.n] >= first_kf)
        p.pos[mine] = p.pos[mine] @ C[:3, :3].T + C[:3, 3]
        p.normal[mine] = p.normal[mine] @ C[:3, :3].T

    def poses(self) -> np.ndarray:
        """(K,4,4) T_WC of all keyframes."""
        return np.stack([kf.T_WC for kf in self.keyframes]) if self.keyframes else np.zeros((0, 4, 4))
