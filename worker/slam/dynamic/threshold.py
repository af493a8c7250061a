"""The adaptive epipolar threshold Δd = f(H) from the differential motion entropy of the pose estimate.

H = ½ ln((2πe)^k |Σ|) is the entropy of a Gaussian pose estimate with covariance Σ (k = 6 for SE(3)). A
confident pose (small |Σ|, low H) means the fundamental matrix and the epipolar lines are sharp, so a small
distance already signals motion; an uncertain pose (high H) widens the lines, so the threshold must grow or
static points get culled. f grows slowly (a logistic in H) and is bounded on both sides so that one bad pose
estimate can neither disable culling nor cull the whole frame:

    Δd(H) = d_min + (d_max - d_min) · σ((H - H0) / s)

With the defaults, Δd ≈ 1.5 px for a well-constrained pose (H ≪ H0), 2.75 px at H = H0 and at most 4 px
(static points' scores reach 2.5-3 px at the 95th percentile on synthetic truth with Kinect-like noise).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from worker.slam.config import valid


@dataclass(frozen=True)
class ThresholdConfig:
    """Parameters of f(H)."""

    d_min: float = valid(1.5, 0.0, 100.0)
    """Lower bound of Δd in pixels (sub-pixel noise of ORB keypoints stays below it)."""
    d_max: float = valid(4.0, 0.0, 100.0)
    """Upper bound of Δd in pixels."""
    h0: float = valid(-33.0, -1000.0, 1000.0)
    """Entropy (nats) at the midpoint; about the entropy of a pose with ~1 mm / 0.05° standard deviations."""
    scale: float = valid(4.0, 0.001, 1000.0)
    """Width of the transition in nats: f changes slowly with H."""
    fixed: float | None = None
    """A fixed threshold instead (for the ablation); None = adaptive."""


def motion_entropy(cov: np.ndarray | None) -> float | None:
    """H = ½ ln((2πe)^k |Σ|) for a k×k covariance; None when Σ is missing or not positive definite."""
    if cov is None:
        return None
    k = cov.shape[0]
    sign, logdet = np.linalg.slogdet(cov)
    if sign <= 0 or not np.isfinite(logdet):
        return None
    return 0.5 * (k * math.log(2 * math.pi * math.e) + float(logdet))


def adaptive_threshold(entropy: float | None, config: ThresholdConfig = ThresholdConfig()) -> float:
    """Δd in pixels. Without an entropy (first frames, lost tracking) the midpoint is used."""
    if config.fixed is not None:
        return config.fixed
    x = 0.0 if entropy is None else (entropy - config.h0) / config.scale
    return config.d_min + (config.d_max - config.d_min) / (1.0 + math.exp(-max(min(x, 50.0), -50.0)))
