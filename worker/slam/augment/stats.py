"""How much of the image the inserted people (or other movers) cover: the figure a dynamic benchmark sequence is
judged by."""
from __future__ import annotations

import numpy as np


def coverage_summary(fractions: list[float], lo: float = 0.05, hi: float = 0.30, what: str = "people") -> str:
    """One line (`what` names the movers): share of frames whose dynamic fraction is in [lo, hi], empty, above hi;
    median coverage."""
    f = np.asarray(fractions, dtype=np.float64)
    if f.size == 0:
        return "no frames"
    return (f"{what} cover {100 * lo:.0f}-{100 * hi:.0f} % of the image in {100 * np.mean((f >= lo) & (f <= hi)):.1f} %"
            f" of the frames (none: {100 * np.mean(f == 0):.1f} %, more: {100 * np.mean(f > hi):.1f} %; "
            f"median {100 * np.median(f):.1f} %)")
