"""A reference's exposure relative to the target: per-channel colour gain over the static pixels they share.

Real cameras change exposure between frames; restoration scales the colours it copies from a reference by it.
"""
from __future__ import annotations

import numpy as np
from numba import njit


def colour_gain(rgb: np.ndarray, hole: np.ndarray, ref_rgb: np.ndarray, landed: np.ndarray,
                 region: tuple[int, int, int, int], min_pixels: int = 500, max_pixels: int = 20_000) -> np.ndarray:
    """(3,) target / reference colour ratio over the static target pixels of `region` that the reference's
    `landed` (h, w, 2) map covers; 1 where too few are shared to say. The median of per-pixel ratios: moving
    things outside the hole (a mask that missed them) or misregistered edges must not set it. Clipped to a
    plausible exposure change. Of more than `max_pixels` shared pixels an even subsample is used: a median of
    20 000 ratios is as good an estimate, and a large hole's region shares 100 000+ (17 ms per reference)."""
    y0, _, x0, _ = region
    shared, ratios = _shared_ratios(rgb, hole, ref_rgb, landed, y0, x0, max_pixels)
    if shared < min_pixels or ratios.shape[1] < min_pixels:
        return np.ones(3)
    return np.clip(np.median(ratios, axis=1), 0.7, 1.4)


@njit(cache=True)
def _shared_ratios(rgb, hole, ref_rgb, landed, y0, x0, max_pixels):
    """(number of shared pixels, (3, m) float64 target / reference ratios of the bright ones among every step-th
    shared pixel in row-major order): one pass to count, one to sample, no index arrays. Channels as rows, so
    numpy's median reads them contiguously."""
    h, w = landed.shape[0], landed.shape[1]
    n = 0
    for y in range(h):
        for x in range(w):
            if landed[y, x, 0] >= 0 and not hole[y0 + y, x0 + x]:
                n += 1
    step = (n + max_pixels - 1) // max_pixels if n > max_pixels else 1
    out = np.empty((3, (n + step - 1) // step if n else 0))
    i = m = 0
    for y in range(h):
        for x in range(w):
            if landed[y, x, 0] < 0 or hole[y0 + y, x0 + x]:
                continue
            if i % step == 0:
                ry, rx = landed[y, x, 0], landed[y, x, 1]
                t0, t1, t2 = rgb[y0 + y, x0 + x, 0], rgb[y0 + y, x0 + x, 1], rgb[y0 + y, x0 + x, 2]
                r0, r1, r2 = ref_rgb[ry, rx, 0], ref_rgb[ry, rx, 1], ref_rgb[ry, rx, 2]
                # ratios of dark pixels are mostly noise
                if min(t0, t1, t2) > 16 and min(r0, r1, r2) > 16:
                    out[0, m] = np.float64(t0) / np.float64(r0)
                    out[1, m] = np.float64(t1) / np.float64(r1)
                    out[2, m] = np.float64(t2) / np.float64(r2)
                    m += 1
            i += 1
    return n, out[:, :m]
