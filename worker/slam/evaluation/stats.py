"""Summary statistics of a set of per-pose (or per-pair) errors, as TUM's scripts print them."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ErrorStats:
    rmse: float
    mean: float
    median: float
    std: float  # population standard deviation (numpy's default, as TUM's scripts)
    max: float


def error_stats(err: np.ndarray) -> ErrorStats:
    """Statistics of (N,) non-negative errors, N >= 1."""
    return ErrorStats(float(np.sqrt(np.mean(err**2))), float(np.mean(err)), float(np.median(err)),
                      float(np.std(err)), float(np.max(err)))
