"""The adaptive epipolar threshold Δd = f(H) from the differential motion entropy of the pose estimate.

H = ½ ln((2πe)^k |Σ|) is the entropy of a Gaussian pose estimate with covariance Σ (k = 6 for SE(3)). A
confident pose (small |Σ|, low H) means the fundamental matrix and the epipolar lines are sharp, so a small
distance already signals motion; an uncertain pose (high H) widens the lines, so the threshold must grow or
static points get culled. f grows slowly (a logistic in H) and is bounded on both sides so that one bad pose
estimate can neither disable culling nor cull the whole frame:

    Δd(H) = d_min + (d_max - d_min) · σ((H - H0) / s)

With the defaults, Δd ≈ 1.5 px for a well-constrained pose (H ≪ H0), 2.75 px at H = H0 and at most 4 px
(static points' scores reach 2.5-3 px at the 95th percentile on synthetic truth with Kinect-like noise).

`mode` chooses whose estimate H is taken from: `frame` = the camera's previous pose (one Δd per frame),
`object` = each segment's own motion between the compared frames (`object_motion`, one Δd per object, as in
the paper), with its own midpoint `object_h0`: an object's motion from a few dozen points is far less
certain than the camera's from the whole view. Entropy adds up over dimensions, so for a k-DoF estimate the
midpoint is `object_h0 * k / 6`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from worker.slam.config import valid


@dataclass(frozen=True)
class ThresholdConfig:
    """Parameters of f(H)."""

    d_min: float = valid(1.5, 0.0, 100.0, at_most="d_max")
    """Lower bound of Δd in pixels (sub-pixel noise of ORB keypoints stays below it)."""
    d_max: float = valid(4.0, 0.0, 100.0)
    """Upper bound of Δd in pixels."""
    h0: float = valid(-33.0, -1000.0, 1000.0)
    """Entropy (nats) at the midpoint; about the entropy of a pose with ~1 mm / 0.05° standard deviations."""
    scale: float = valid(4.0, 0.001, 1000.0)
    """Width of the transition in nats: f changes slowly with H."""
    fixed: float | None = None
    """A fixed threshold instead (for the ablation); None = adaptive."""
    mode: str = "frame"
    """`frame` (H of the camera's pose) or `object` (H of each segment's motion; see the module doc). `frame` by
    default: `object` was less accurate. Measured: docs/results/settings.md#culling-threshold-mode"""
    object_h0: float = valid(-26.0, -1000.0, 1000.0)
    """Midpoint (nats) of f for a 6-DoF object motion in `object` mode: the entropy of a board's motion from
    ~40 matched points with 0.5 px residuals on the test scene (150 points: -29, 10 points: -24)."""

    def __post_init__(self) -> None:
        if self.mode not in ("frame", "object"):
            raise ValueError(f"threshold.mode must be 'frame' or 'object', got {self.mode!r}")


def motion_entropy(cov: np.ndarray | None) -> float | None:
    """H = ½ ln((2πe)^k |Σ|) for a k×k covariance; None when Σ is missing or not positive definite."""
    if cov is None:
        return None
    k = cov.shape[0]
    sign, logdet = np.linalg.slogdet(cov)
    if sign <= 0 or not np.isfinite(logdet):
        return None
    return 0.5 * (k * math.log(2 * math.pi * math.e) + float(logdet))


def adaptive_threshold(entropy: float | None, config: ThresholdConfig = ThresholdConfig(),
                       h0: float | None = None) -> float:
    """Δd in pixels. Without an entropy (first frames, lost tracking) the midpoint is used; `h0` overrides
    the configured midpoint (the object-level one)."""
    if config.fixed is not None:
        return config.fixed
    mid = config.h0 if h0 is None else h0
    x = 0.0 if entropy is None else (entropy - mid) / config.scale
    return config.d_min + (config.d_max - config.d_min) / (1.0 + math.exp(-max(min(x, 50.0), -50.0)))


def object_threshold(cov: np.ndarray, config: ThresholdConfig) -> tuple[float, float | None]:
    """(Δd px, H nats) of an object from its k×k motion covariance (k = 6 or 3); the midpoint scales with k.
    A Σ that is not positive definite gives the midpoint's Δd and no entropy."""
    entropy = motion_entropy(cov)
    return adaptive_threshold(entropy, config, config.object_h0 * cov.shape[0] / 6), entropy
