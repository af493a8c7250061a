"""Constant-velocity motion model: the next pose continues the last inter-frame motion."""
from __future__ import annotations

import numpy as np

from worker.slam.geometry.se3 import inv


class ConstantVelocityModel:
    """Predicts T_WC(k+1) = T_WC(k) @ V with V = T_WC(k-1)^-1 @ T_WC(k), the last relative motion.

    Poses are T_WC 4x4 float64; `velocity` V is T_{C(k-1) C(k)} (previous camera <- current camera).
    """

    def __init__(self) -> None:
        self.last: np.ndarray | None = None
        self.velocity: np.ndarray | None = None

    def predict(self) -> np.ndarray | None:
        """Predicted T_WC of the next frame; the last pose if no velocity yet; None before the first frame."""
        if self.last is None:
            return None
        if self.velocity is None:
            return self.last.copy()
        return self.last @ self.velocity

    def update(self, T_WC: np.ndarray) -> None:
        if self.last is not None:
            self.velocity = inv(self.last) @ T_WC
        self.last = T_WC.copy()

    def reset(self, T_WC: np.ndarray | None = None) -> None:
        """Forget the velocity (after a loss or a relocalisation)."""
        self.velocity = None
        self.last = None if T_WC is None else T_WC.copy()
