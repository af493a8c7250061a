"""The sensor model every measurement of a run is weighed with: intrinsics, depth weight and keypoint noise.

Built once per run (`SensorModel.build`) and handed to the tracker, local mapping, loop closure and the final
frame refit alike, so they all solve with the same K, bf and per-octave sigmas.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.slam.camera import Camera
from worker.slam.config import FeatureConfig, TrackingConfig


@dataclass(frozen=True, eq=False)
class SensorModel:
    """Arrays are read-only. Pixels are ideal pinhole pixels of the full image (keypoints are undistorted)."""

    K: np.ndarray
    """(3,3) float64 intrinsics."""
    bf: float
    """fx x virtual baseline (px m): how much a keypoint's depth weighs in pose and BA residuals, as a stereo
    disparity (`tracking.virtual_baseline_m`, or `unregistered_baseline_m` when depth is not registered)."""
    size: tuple[int, int]
    """(width, height) px."""
    scales: np.ndarray
    """(levels,) float64: the ORB pyramid's scale per octave, scale_factor ** octave."""
    inv_sigma2: np.ndarray
    """(levels,) float64: 1/sigma^2 of a keypoint's position per octave, 1/scale^2 (ORB-SLAM2's invSigma2)."""
    dist: np.ndarray | None
    """(5,) float64 OpenCV coefficients (k1, k2, p1, p2, k3) of the colour image; None: no distortion."""
    depth_sigma_k: float = 0.0
    """> 0: each keypoint's depth weighs by its own sigma (`features.depth_sigma_per_m2`, registered depth only);
    0: by the virtual baseline alone."""

    @classmethod
    def build(cls, camera: Camera, features: FeatureConfig, tracking: TrackingConfig) -> SensorModel:
        baseline = tracking.virtual_baseline_m if camera.depth_registered else tracking.unregistered_baseline_m
        scales = features.scale_factor ** np.arange(features.n_levels)
        return cls(K=_frozen(camera.K), bf=camera.fx * baseline, size=(camera.width, camera.height),
                   scales=_frozen(scales), inv_sigma2=_frozen(1.0 / scales**2),
                   dist=_frozen(np.asarray(camera.dist)) if camera.has_distortion else None,
                   depth_sigma_k=features.depth_sigma_per_m2 if camera.depth_registered else 0.0)

    @property
    def sigmas(self) -> np.ndarray:
        """(levels,) float64: sigma of a keypoint's position per octave (px)."""
        return 1.0 / np.sqrt(self.inv_sigma2)

    @property
    def scale_factor(self) -> float:
        """The pyramid's scale factor, from its per-octave 1/sigma^2 (one level: no pyramid, 1)."""
        return float(np.sqrt(self.inv_sigma2[0] / self.inv_sigma2[1])) if len(self.inv_sigma2) > 1 else 1.0


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a
