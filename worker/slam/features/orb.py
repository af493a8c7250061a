"""ORB extraction with OpenCV's scale pyramid and a grid that spreads keypoints over the image.

OpenCV's ORB keeps the strongest corners, which cluster on a few high-contrast objects; ORB-SLAM2 instead
spreads them over a grid so that every part of the view constrains the pose. Here corners are detected at
a low threshold, then cells are served round-robin (each keeps its strongest few, the same quota for all),
and descriptors are computed only for the kept keypoints.
"""
from __future__ import annotations

import cv2
import numpy as np

from worker.slam.config import FeatureConfig
from worker.slam.features.depth import lookup_depth
from worker.slam.features.types import Features


class OrbExtractor:
    def __init__(self, cfg: FeatureConfig) -> None:
        self.cfg = cfg
        # Over-detect so the grid has candidates in weak cells; only kept ones get descriptors.
        self._orb = cv2.ORB_create(  # type: ignore[attr-defined]  # (absent from OpenCV 5's stubs)
            nfeatures=cfg.n_features * cfg.overdetect, scaleFactor=cfg.scale_factor, nlevels=cfg.n_levels,
            edgeThreshold=19, fastThreshold=cfg.fast_threshold, scoreType=cv2.ORB_HARRIS_SCORE, patchSize=31)
        self.scales = cfg.scale_factor ** np.arange(cfg.n_levels)
        #: (levels,) inverse variance of a keypoint's position, 1/scale^2 (ORB-SLAM2's invSigma2).
        self.inv_sigma2 = 1.0 / self.scales**2

    def extract(self, gray: np.ndarray, depth: np.ndarray | None = None,
                exclude: np.ndarray | None = None) -> Features:
        """Keypoints of `gray` (H,W) uint8. `depth` float32 metres (H,W) fills `Features.depth`.

        `exclude` bool (H,W): True pixels get no keypoints (e.g. dynamic objects).
        """
        mask = None
        if exclude is not None:
            mask = np.where(exclude, 0, 255).astype(np.uint8)
        kps = self._orb.detect(gray, mask)
        if not kps:
            return Features.empty()
        kps = self._balance(kps, gray.shape)
        kps, desc = self._orb.compute(gray, kps)
        if desc is None or not kps:
            return Features.empty()
        uv = cv2.KeyPoint_convert(kps).astype(np.float64)  # type: ignore[attr-defined]  # (absent from the stubs)
        octave = np.array([k.octave for k in kps], dtype=int)
        resp = np.array([k.response for k in kps], dtype=np.float32)
        z = (lookup_depth(uv, depth, self.cfg.min_depth_m, self.cfg.max_depth_m,
                          edge_radius=self.cfg.depth_edge_radius_px) if depth is not None
             else np.zeros(len(uv), np.float32))
        return Features(uv, octave, resp, desc, z)

    def _balance(self, kps: list, shape: tuple[int, int]) -> list:
        n = self.cfg.n_features
        if len(kps) <= n:
            return list(kps)
        h, w = shape
        cell = self.cfg.grid_cell_px
        pts = cv2.KeyPoint_convert(kps).astype(np.float64)  # type: ignore[attr-defined]  # (absent from the stubs)
        resp = np.array([k.response for k in kps])
        gx, gy = int(np.ceil(w / cell)), int(np.ceil(h / cell))
        cid = np.minimum(pts[:, 1] // cell, gy - 1).astype(int) * gx + np.minimum(pts[:, 0] // cell, gx - 1).astype(int)
        order = np.lexsort((-resp, cid))  # by cell, strongest first inside a cell
        sorted_cid = cid[order]
        starts = np.searchsorted(sorted_cid, sorted_cid, side="left")
        rank = np.empty(len(kps), int)
        rank[order] = np.arange(len(kps)) - starts
        # Round-robin over cells: the largest per-cell quota that fits the budget, then the strongest of the
        # next rank fill what is left, so no cell takes more than one more than any other non-exhausted cell.
        per_rank = np.bincount(rank)
        quota = int(np.searchsorted(np.cumsum(per_rank), n, side="right"))
        keep = rank < quota
        nxt = np.flatnonzero(rank == quota)
        keep[nxt[np.argsort(-resp[nxt])][: n - keep.sum()]] = True
        return [kps[i] for i in np.flatnonzero(keep)]
