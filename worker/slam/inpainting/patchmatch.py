"""PatchMatch (Barnes et al. 2009) for filling holes from a library of source images.

Every hole pixel p holds a match (source s, pixel q). Each iteration scans the hole (alternating direction):
propagation from the already-visited neighbours' matches, then random search around the current match with a
radius halving from the image size, and finally a vote re-fills the hole from the matched patches. Patch
distances use known target pixels at full weight and the current estimate of hole pixels at reduced weight
(Wexler-style completion); invalid source pixels are skipped.

The scan is inherently sequential (a match found early spreads along the scan), so it is compiled with numba:
a vectorised numpy version (jump-flood propagation) was an order of magnitude slower.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from worker.slam.config import valid


@dataclass(frozen=True)
class PatchMatchConfig:
    """Parameters of the PatchMatch search."""

    patch_radius: int = valid(2, 1, 10)
    """Patches are (2r+1)^2 pixels."""
    iterations: int = valid(3, 1, 20)
    """Scan + vote rounds (the paper uses about 3)."""
    hole_weight: float = valid(0.5, 0.0, 1.0)
    """Weight of still-estimated hole pixels in the patch distance, relative to known pixels."""
    min_valid: float = valid(0.5, 0.0, 1.0)
    """A source patch needs a valid centre and at least this fraction (by weight) of valid pixels."""
    init_search_radius: int = valid(16, 1, 10_000)
    """Random search of pixels that start from a given match (e.g. geometry) begins at this radius instead of
    the image size: the match is already close, and the wide radii would only cost time."""
    seed: int = valid(0, 0, 2**31 - 1)


@dataclass(frozen=True)
class PatchMatchResult:
    """`rgb` (H, W, 3) uint8 with the hole filled; `source` (N,), `yx` (N, 2) the match of each hole pixel and
    `cost` (N,) its weighted mean squared patch distance (colours in [0, 1]); N = hole pixels, row-major."""

    rgb: np.ndarray
    source: np.ndarray
    yx: np.ndarray
    cost: np.ndarray


@njit(cache=True)
def _dist(est, tw, wsum, lib, valid, py, px, s, qy, qx, r, min_valid, bound):
    """Weighted mean squared distance over the source pixels that are valid; the centre must be valid and the
    valid weight at least `min_valid` of the patch (a reference's own moving object sits right next to the
    background we want from it, so invalid neighbours are skipped, not charged)."""
    h, w = est.shape[0], est.shape[1]
    if not valid[s, qy, qx]:
        return np.inf
    total = 0.0
    used = 0.0
    skipped = 0.0
    limit = bound * wsum
    for dy in range(-r, r + 1):
        ty = py + dy
        if ty < 0 or ty >= h:
            continue
        sy = qy + dy
        for dx in range(-r, r + 1):
            tx = px + dx
            if tx < 0 or tx >= w:
                continue
            wt = tw[ty, tx]
            sx = qx + dx
            if sy < 0 or sy >= h or sx < 0 or sx >= w or not valid[s, sy, sx]:
                skipped += wt
                if skipped > (1.0 - min_valid) * wsum:
                    return np.inf
                continue
            d0 = lib[s, sy, sx, 0] - est[ty, tx, 0]
            d1 = lib[s, sy, sx, 1] - est[ty, tx, 1]
            d2 = lib[s, sy, sx, 2] - est[ty, tx, 2]
            total += wt * (d0 * d0 + d1 * d1 + d2 * d2)
            used += wt
            if total > limit:
                return np.inf
    return total / max(used, 1e-9)


@njit(cache=True)
def _scan(est, tw, lib, valid, py, px, slot, src, qy, qx, cost, start_radius, r, min_valid, backward, seed):
    np.random.seed(seed)
    n = py.shape[0]
    h, w = est.shape[0], est.shape[1]
    n_src = lib.shape[0]
    step = -1 if backward else 1
    for k in range(n):
        i = n - 1 - k if backward else k
        y, x = py[i], px[i]
        wsum = 0.0
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                if 0 <= y + dy < h and 0 <= x + dx < w:
                    wsum += tw[y + dy, x + dx]
        wsum = max(wsum, 1e-6)
        best = _dist(est, tw, wsum, lib, valid, y, x, src[i], qy[i], qx[i], r, min_valid, np.inf)
        # propagation from the neighbours already visited in this scan direction
        for ny, nx in ((y, x - step), (y - step, x)):
            if 0 <= ny < h and 0 <= nx < w and slot[ny, nx] >= 0:
                j = slot[ny, nx]
                cy = min(max(qy[j] + (y - ny), 0), h - 1)
                cx = min(max(qx[j] + (x - nx), 0), w - 1)
                c = _dist(est, tw, wsum, lib, valid, y, x, src[j], cy, cx, r, min_valid, best)
                if c < best:
                    best, src[i], qy[i], qx[i] = c, src[j], cy, cx
        # random search, radius halving from the image size
        radius = start_radius[i]
        while radius >= 1:
            cs = src[i]
            if n_src > 1 and radius * 4 > max(h, w) and np.random.random() < 0.3:
                cs = np.random.randint(0, n_src)
            cy = min(max(qy[i] + np.random.randint(-radius, radius + 1), 0), h - 1)
            cx = min(max(qx[i] + np.random.randint(-radius, radius + 1), 0), w - 1)
            c = _dist(est, tw, wsum, lib, valid, y, x, cs, cy, cx, r, min_valid, best)
            if c < best:
                best, src[i], qy[i], qx[i] = c, cs, cy, cx
            radius //= 2
        cost[i] = best


@njit(cache=True)
def _vote(est, lib, valid, py, px, slot, src, qy, qx, cost, r, sigma2):
    h, w = est.shape[0], est.shape[1]
    weight = np.exp(-cost / sigma2)
    for i in range(py.shape[0]):
        y, x = py[i], px[i]
        acc0 = acc1 = acc2 = 0.0
        wsum = 0.0
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                ny, nx = y - dy, x - dx  # the patch centred at p - d covers p at offset d
                if ny < 0 or ny >= h or nx < 0 or nx >= w or slot[ny, nx] < 0:
                    continue
                j = slot[ny, nx]
                sy, sx = qy[j] + dy, qx[j] + dx
                if sy < 0 or sy >= h or sx < 0 or sx >= w or not valid[src[j], sy, sx]:
                    continue
                wt = weight[j]
                acc0 += wt * lib[src[j], sy, sx, 0]
                acc1 += wt * lib[src[j], sy, sx, 1]
                acc2 += wt * lib[src[j], sy, sx, 2]
                wsum += wt
        if wsum > 1e-9:
            est[y, x, 0], est[y, x, 1], est[y, x, 2] = acc0 / wsum, acc1 / wsum, acc2 / wsum
        else:
            est[y, x, 0] = lib[src[i], qy[i], qx[i], 0]
            est[y, x, 1] = lib[src[i], qy[i], qx[i], 1]
            est[y, x, 2] = lib[src[i], qy[i], qx[i], 2]


def patchmatch_fill(target: np.ndarray, hole: np.ndarray, sources: np.ndarray, source_valid: np.ndarray,
                    init_source: np.ndarray | None = None, init_yx: np.ndarray | None = None,
                    config: PatchMatchConfig = PatchMatchConfig()) -> PatchMatchResult:
    """Fill `hole` (H, W) bool of `target` (H, W, 3) uint8 from `sources` (S, H, W, 3) uint8.

    `source_valid` (S, H, W) bool marks usable source pixels. `init_source` (N,) / `init_yx` (N, 2) give a
    starting match per hole pixel in row-major order (e.g. from geometry; source -1 = none → random).
    """
    h, w = hole.shape
    py, px = (a.astype(np.int64) for a in np.nonzero(hole))
    n = len(py)
    if n == 0:
        return PatchMatchResult(target.copy(), np.zeros(0, np.int64), np.zeros((0, 2), np.int64),
                                np.zeros(0, np.float64))
    rng = np.random.default_rng(config.seed)
    lib = np.ascontiguousarray(sources, dtype=np.float32) / np.float32(255.0)
    valid = np.ascontiguousarray(source_valid, dtype=np.bool_)
    est = target.astype(np.float32) / np.float32(255.0)
    src = rng.integers(0, len(sources), n)
    qy, qx = rng.integers(0, h, n), rng.integers(0, w, n)
    start_radius = np.full(n, max(h, w), np.int64)
    if init_source is not None and init_yx is not None:
        have = init_source >= 0
        start_radius[have] = config.init_search_radius
        src[have], qy[have], qx[have] = init_source[have], init_yx[have, 0], init_yx[have, 1]
        est[py[have], px[have]] = lib[src[have], qy[have], qx[have]]  # start the estimate from geometry
    slot = np.full((h, w), -1, np.int64)
    slot[py, px] = np.arange(n)
    tw = np.where(hole, np.float32(config.hole_weight), np.float32(1.0)).astype(np.float32)
    cost = np.zeros(n, np.float64)
    for it in range(config.iterations):
        _scan(est, tw, lib, valid, py, px, slot, src, qy, qx, cost, start_radius, config.patch_radius,
              config.min_valid, it % 2 == 1, config.seed + it)
        sigma2 = max(float(np.percentile(cost[np.isfinite(cost)], 75)) if np.isfinite(cost).any() else 1.0, 1e-4)
        _vote(est, lib, valid, py, px, slot, src, qy, qx, cost, config.patch_radius, sigma2)
    out = target.copy()
    out[py, px] = np.clip(est[py, px] * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return PatchMatchResult(out, src, np.stack([qy, qx], 1), cost)
