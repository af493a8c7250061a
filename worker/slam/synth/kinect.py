"""A Kinect-v1-like depth sensor applied to clean rendered depth.

Structured light measures disparity d = f*b / z in 1/8 pixel steps, so noise and quantisation live in disparity
and grow as z^2 in depth (about 3 mm at 1 m, 5 cm at 4 m). Depth is lost at occlusion edges (the projector
and the camera see different sides), on dark, absorbing surfaces, and beyond the working range.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class KinectConfig:
    """Sensor model parameters."""

    focal_baseline: float = 580.0 * 0.075
    """f * b in pixel metres (Kinect v1: f ~ 580 px, baseline 7.5 cm)."""
    subpixel: float = 8.0
    """Disparity steps per pixel (quantisation)."""
    sigma_disparity: float = 0.07
    """Std of the disparity noise in pixels (a smooth 4x4-pixel part plus a 2x2-block part)."""
    min_depth: float = 0.45
    """Nearer than this returns nothing (metres)."""
    max_depth: float = 5.0
    """Farther than this returns nothing (metres)."""
    edge_jump: float = 0.05
    """Relative depth jump between neighbours that makes an occlusion edge."""
    dark_level: int = 28
    """Grey level below which a surface absorbs the projector's pattern."""
    dark_dropout: float = 0.8
    """Fraction of dark pixels without depth."""


class KinectSensor:
    """Noise fields are drawn once per frame so the background and the frame share them (exact truth)."""

    def __init__(self, cfg: KinectConfig, shape: tuple[int, int]) -> None:
        self.cfg, self.shape = cfg, shape

    def draw(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """(disparity noise float32 (H,W) px, uniform speckle float32 (H,W) in [0,1)) for one frame."""
        h, w = self.shape
        low = rng.standard_normal((h // 4, w // 4), dtype=np.float32)
        noise = cv2.resize(low, (w, h), interpolation=cv2.INTER_LINEAR) * np.float32(0.8 * self.cfg.sigma_disparity)
        fine = rng.standard_normal((h // 2, w // 2), dtype=np.float32) * np.float32(0.5 * self.cfg.sigma_disparity)
        noise += cv2.resize(fine, (w, h), interpolation=cv2.INTER_NEAREST)
        speckle = cv2.resize(rng.random((h // 2, w // 2), dtype=np.float32), (w, h), interpolation=cv2.INTER_NEAREST)
        return noise, speckle

    def measure(self, depth: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """Quantised noisy depth float32 (H,W) m from clean depth; no holes yet (0 stays 0)."""
        c = self.cfg
        fb = np.float32(c.focal_baseline)
        with np.errstate(divide="ignore"):
            disp = fb / depth + noise
        q = np.rint(disp * np.float32(c.subpixel)) / np.float32(c.subpixel)
        with np.errstate(divide="ignore"):
            z = np.where(q > 0, fb / q, 0).astype(np.float32)
        z[(depth < c.min_depth) | (depth > c.max_depth) | ~np.isfinite(depth)] = 0
        return z

    def holes(self, depth: np.ndarray, grey: np.ndarray, speckle: np.ndarray) -> np.ndarray:
        """bool (H,W): pixels the sensor returns no depth for, from clean depth and grey (H,W) uint8 image."""
        c = self.cfg
        k3 = np.ones((3, 3), np.uint8)
        spread = cv2.dilate(depth, k3) - cv2.erode(depth, k3)
        edge = (spread > np.float32(c.edge_jump) * depth).astype(np.uint8)
        # Edges lose 1-2 px reliably and a ragged extra band of 1-3 px more, as Kinect shadows do.
        core = cv2.dilate(edge, k3).astype(bool)
        ragged = cv2.dilate(edge, np.ones((5, 7), np.uint8)).astype(bool) & (speckle < 0.45)
        # Thin dark lines do not kill the pattern, dark areas do: test the grey level over a 9x9 neighbourhood.
        dark = (cv2.blur(grey, (9, 9)) < c.dark_level) & (speckle < c.dark_dropout)
        return core | ragged | dark
