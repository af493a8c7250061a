"""A frame's keypoints as arrays (struct of arrays), so matching and optimisation stay vectorised."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Features:
    """N keypoints of one image.

    `uv` (N,2) float64 pixel coordinates at full resolution, undistorted (ideal pinhole) once the tracker has
    seen them; `uv_raw` the same in the raw image (where masks and depth live; None = equal to `uv`);
    `octave` (N,) int pyramid level; `response` (N,) float32; `desc` (N,32) uint8 ORB descriptors;
    `depth` (N,) float32 metres (0 = no valid depth); `depth_w` (N,) float32 weight of each depth residual
    relative to the virtual baseline's (`features.depth.depth_weights`; None = all 1).
    """

    uv: np.ndarray
    octave: np.ndarray
    response: np.ndarray
    desc: np.ndarray
    depth: np.ndarray
    uv_raw: np.ndarray | None = None
    depth_w: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.uv)

    @classmethod
    def empty(cls) -> Features:
        return cls(np.zeros((0, 2)), np.zeros(0, int), np.zeros(0, np.float32), np.zeros((0, 32), np.uint8),
                   np.zeros(0, np.float32))

    def select(self, idx: np.ndarray) -> Features:
        """A subset by boolean mask or index array."""
        return Features(self.uv[idx], self.octave[idx], self.response[idx], self.desc[idx], self.depth[idx],
                        None if self.uv_raw is None else self.uv_raw[idx],
                        None if self.depth_w is None else self.depth_w[idx])

    @property
    def image_uv(self) -> np.ndarray:
        """(N,2) coordinates in the raw image."""
        return self.uv if self.uv_raw is None else self.uv_raw

    @staticmethod
    def concat(parts: list[Features]) -> Features:
        parts = [p for p in parts if p is not None and len(p)]
        if not parts:
            return Features.empty()
        raw = None
        if any(p.uv_raw is not None for p in parts):
            raw = np.concatenate([p.image_uv for p in parts])
        cat = {f: np.concatenate([getattr(p, f) for p in parts]) for f in ("uv", "octave", "response", "desc", "depth")}
        dw = None
        if any(p.depth_w is not None for p in parts):
            dw = np.concatenate([np.ones(len(p), np.float32) if p.depth_w is None else p.depth_w for p in parts])
        return Features(**cat, uv_raw=raw, depth_w=dw)
