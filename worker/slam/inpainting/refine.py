"""Refine a reference's pose against the target by direct photometric alignment before copying from it.

Geometry copies a reference pixel to where the two poses and the reference's depth put it. Poses from a
motion-capture or KinectFusion ground truth, or from feature tracking, are a centimetre or a degree off the
images, and 7-Scenes' depth comes from a second, unregistered camera: copied texture lands a few pixels away
from where the target would show it (the ring-shift alignment, `align.py`, finds a few pixels on augmented
frames, varying across the hole). A rigid correction of the relative pose fits all of it at once, parallax
included: the reference is rendered at its current relative pose into the target view (`warp.render_depth`),
and OpenCV's photometric RGB-D odometry (`cv2.Odometry`, RGB type: the reference's depth, both images'
intensities; Steinbruecker et al.) aligns that rendering with the target's static pixels, at half resolution.
An option, off by default: it pays where poses come from elsewhere, not from the tracker
(docs/results/settings.md#restoration-refine).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from worker.slam.config import valid
from worker.slam.geometry.se3 import pose_distance
from worker.slam.inpainting.align import Ring, ring_zncc
from worker.slam.inpainting.warp import render_depth

MAX_DEPTH_M = 20.0
"""OpenCV's default (4 m) would drop the far background of a room-sized scene from the alignment."""


@dataclass(frozen=True)
class PoseRefinementConfig:
    """Photometric refinement of each reference's relative pose before restoration."""

    enabled: bool = False
    """Off by default: with the tracker's poses (consistent with the images) it gains little and doubles the
    restoration's time; with external poses a few pixels off it gains.
    Measured: docs/results/settings.md#restoration-refine"""
    scale: float = valid(0.5, 0.125, 1.0)
    """Image scale the alignment runs at (0.5: half resolution)."""
    min_static_fraction: float = valid(0.1, 0.0, 1.0)
    """Fewer static target pixels with intensity than this share of the image: too little to align against,
    the pose is kept."""
    max_translation_m: float = valid(0.1, 0.0, 10.0)
    max_rotation_deg: float = valid(5.0, 0.0, 180.0)
    """Corrections larger than these are not believed (a failed alignment), the pose is kept."""
    hole_margin_px: int = valid(4, 0, 100)
    """The target's hole is widened by this much before its pixels are left out of the alignment."""
    check_ring_px: int = valid(30, 1, 200)
    """A refined pose is kept only if the static pixels within this distance of the hole correlate better
    with the reference through it than through the pose given (zero-normalised, grey): the alignment fits the
    whole view, the hole's surroundings are what the copy has to match.
    Measured: docs/results/settings.md#restoration-refine"""


class PoseRefiner:
    """Aligns references to one target frame: `rgb` (H, W, 3) uint8, `depth` (H, W) float32 m, `static` (H, W)
    bool (pixels that show the static scene), intrinsics K (3, 3); `ring` (`align.hole_ring`, `check_ring_px`
    wide) judges the result. The target's pyramid is built once and shared by every reference."""

    def __init__(self, rgb: np.ndarray, depth: np.ndarray, static: np.ndarray, K: np.ndarray, ring: Ring,
                 config: PoseRefinementConfig):
        self.config = config
        self.ring, self.K_full = ring, K
        h, w = static.shape
        self.size = (max(1, round(w * config.scale)), max(1, round(h * config.scale)))
        s = self.size[0] / w
        self.K = np.array([[K[0, 0] * s, 0.0, (K[0, 2] + 0.5) * s - 0.5],
                           [0.0, K[1, 1] * s, (K[1, 2] + 0.5) * s - 0.5], [0.0, 0.0, 1.0]], np.float32)
        if config.hole_margin_px:
            k = 2 * config.hole_margin_px + 1
            static = ~cv2.dilate((~static).astype(np.uint8), np.ones((k, k), np.uint8)).astype(bool)
        mask = self._small(static.astype(np.uint8) * 255, cv2.INTER_NEAREST)
        self.usable = float(np.mean(mask > 0)) >= config.min_static_fraction
        if not self.usable:
            return
        settings = cv2.OdometrySettings()
        settings.setCameraMatrix(self.K)
        settings.setMaxDepth(MAX_DEPTH_M)
        self.odometry = cv2.Odometry(cv2.OdometryType_RGB, settings, cv2.OdometryAlgoType_COMMON)
        grey = self._small(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), cv2.INTER_AREA)
        z = self._small(np.ascontiguousarray(depth, np.float32), cv2.INTER_NEAREST)
        self.target = cv2.OdometryFrame(z, grey, mask)
        self.odometry.prepareFrame(self.target)

    def _small(self, image: np.ndarray, interpolation: int) -> np.ndarray:
        return image if image.shape[1] == self.size[0] else cv2.resize(image, self.size,
                                                                       interpolation=interpolation)

    def refine(self, rgb: np.ndarray, depth: np.ndarray, static: np.ndarray,
               T_tr: np.ndarray) -> tuple[np.ndarray, bool]:
        """T_tr (4, 4), reference camera -> target camera, corrected so that the reference (`rgb` (H, W, 3)
        uint8, `depth` (H, W) float32 m, `static` (H, W) bool) matches the target photometrically, and True; T_tr
        itself and False when the alignment fails, moves it implausibly far or matches the hole's ring worse."""
        if not self.usable:
            return T_tr, False
        full_grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        grey = self._small(full_grey, cv2.INTER_AREA)
        z = self._small(np.ascontiguousarray(depth, np.float32), cv2.INTER_NEAREST)
        mask = self._small(static.astype(np.uint8) * 255, cv2.INTER_NEAREST)
        # rendered with the restoration's own splat: `cv2.warpFrame` floors projected coordinates, a half-pixel
        # shift the alignment would take for a pose error
        landed, wz = render_depth(z, mask > 0, T_tr, self.K)
        seen = landed[..., 0] >= 0
        if np.mean(seen) < self.config.min_static_fraction:
            return T_tr, False
        yx = landed[seen]
        wgrey = np.zeros_like(grey)
        wgrey[seen] = grey[yx[:, 0], yx[:, 1]]
        seen &= wz > 0
        source = cv2.OdometryFrame(wz, wgrey, seen.astype(np.uint8) * 255)  # wz is 0 wherever not `seen`
        self.odometry.prepareFrame(source)
        ok, delta = self.odometry.compute(source, self.target)
        if not ok or not self._plausible(delta):
            return T_tr, False
        refined = delta @ T_tr
        before = ring_zncc(self.ring, full_grey, static, np.linalg.inv(T_tr), self.K_full)
        after = ring_zncc(self.ring, full_grey, static, np.linalg.inv(refined), self.K_full)
        return (refined, True) if after > before else (T_tr, False)

    def _plausible(self, delta: np.ndarray) -> bool:
        if not np.isfinite(delta).all():
            return False
        metres, radians = pose_distance(np.eye(4), delta)
        return metres <= self.config.max_translation_m and np.degrees(radians) <= self.config.max_rotation_deg
