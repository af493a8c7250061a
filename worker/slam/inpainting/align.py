"""Align a reference's colours to the target on the static ring around the hole.

Geometry puts a reference pixel where the poses and depths say; on real footage that is a few pixels off
(pose error, colour/depth misregistration: 7-Scenes' colour and depth come from two unregistered cameras).
The static pixels just outside the hole are seen by both frames, so the whole-pixel shift of the reference
that best matches them there (zero-normalised cross-correlation of grey values, so exposure does not matter)
is applied to the hole's pixels too.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from worker.slam.inpainting.warp import project_into_reference

MAX_RING_PIXELS = 1500
"""Ring pixels scored per shift (evenly picked): the shift is one 2-vector, and its cost grows with them."""
MIN_RING_PIXELS = 200
"""Fewer usable ring pixels than this (a hole at the border, a reference that sees little of the ring): no shift."""


@dataclass(frozen=True)
class Ring:
    """Static target pixels around a hole with measured depth: rows `ys`, columns `xs` (N,) int64, their grey
    values `grey` (N,) float64 and depths `depth` (N,) float64 m; at most `MAX_RING_PIXELS`, evenly picked."""

    ys: np.ndarray
    xs: np.ndarray
    grey: np.ndarray
    depth: np.ndarray


def hole_ring(rgb: np.ndarray, depth: np.ndarray, hole: np.ndarray, box: tuple[int, int, int, int],
              ring_px: int) -> Ring:
    """The pixels within `ring_px` of `hole` (H, W) bool, outside it, with depth > 0, of a frame `rgb` (H, W, 3)
    uint8 with `depth` (H, W) float32 m; `box` (y0, y1, x0, x1) bounds the hole."""
    h, w = hole.shape
    y0, y1 = max(box[0] - ring_px, 0), min(box[1] + ring_px, h)
    x0, x1 = max(box[2] - ring_px, 0), min(box[3] + ring_px, w)
    inside = hole[y0:y1, x0:x1].astype(np.uint8)
    size = 2 * ring_px + 1
    ring = (cv2.dilate(inside, np.ones((size, size), np.uint8)) > 0) & (inside == 0) & (depth[y0:y1, x0:x1] > 0)
    ys, xs = np.nonzero(ring)
    if len(ys) > MAX_RING_PIXELS:
        pick = np.linspace(0, len(ys) - 1, MAX_RING_PIXELS).astype(np.int64)
        ys, xs = ys[pick], xs[pick]
    ys, xs = ys + y0, xs + x0
    grey = cv2.cvtColor(rgb[ys, xs][None], cv2.COLOR_RGB2GRAY)[0].astype(np.float64)
    return Ring(ys, xs, grey, depth[ys, xs].astype(np.float64))


def ring_shift(ring: Ring, ref_grey: np.ndarray, ref_valid: np.ndarray, T_rt: np.ndarray, K: np.ndarray,
               radius: int) -> tuple[int, int]:
    """The whole-pixel shift (dy, dx), |dy|, |dx| <= `radius`, to add to the reference point each target pixel
    projects to (with its depth, T_rt: target camera -> reference camera) so that the reference best matches
    the target on `ring`. `ref_grey` (H, W) uint8 or float; `ref_valid` (H, W) bool marks the reference pixels that
    may be used (static). (0, 0) when the ring gives too little to go on."""
    args = _ring_samples(ring, ref_grey, ref_valid, T_rt, K, radius)
    if args is None:
        return 0, 0
    # every second shift first, then the best one's neighbours: a third of the full search's cost, and the
    # same choice on the augmented frames (docs/results/restoration.md)
    coarse = np.arange(-radius, radius + 1, 2)
    shifts = np.stack(np.meshgrid(coarse, coarse, indexing="ij"), -1).reshape(-1, 2)
    dy, dx = shifts[int(np.argmax(_zncc_per_shift(*args, shifts)))]
    near = np.stack(np.meshgrid(np.arange(dy - 1, dy + 2), np.arange(dx - 1, dx + 2), indexing="ij"), -1)
    near = near.reshape(-1, 2)
    near = near[(np.abs(near) <= radius).all(1)]
    dy, dx = near[int(np.argmax(_zncc_per_shift(*args, near)))]
    return int(dy), int(dx)


def ring_zncc(ring: Ring, ref_grey: np.ndarray, ref_valid: np.ndarray, T_rt: np.ndarray, K: np.ndarray) -> float:
    """Zero-normalised cross-correlation of the target's `ring` with the reference (`ref_grey` (H, W),
    `ref_valid` (H, W) bool) sampled where the ring's pixels project at pose T_rt (target camera -> reference
    camera); -2 when too little of the ring is seen to say."""
    args = _ring_samples(ring, ref_grey, ref_valid, T_rt, K, 0)
    return -2.0 if args is None else float(_zncc_per_shift(*args, np.zeros((1, 2), np.int64))[0])


_Samples = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""grey, valid, y0, x0, fy, fx, t: `_zncc_per_shift`'s arguments before the shifts."""


def _ring_samples(ring: Ring, ref_grey: np.ndarray, ref_valid: np.ndarray, T_rt: np.ndarray, K: np.ndarray,
                  radius: int) -> _Samples | None:
    """The arguments of `_zncc_per_shift` for the ring pixels whose projections stay `radius` pixels inside
    the reference on a valid pixel; None when fewer than `MIN_RING_PIXELS` do."""
    h, w = ref_grey.shape
    u, v, z_ref = project_into_reference(np.stack([ring.ys, ring.xs], 1), ring.depth, T_rt, K)
    x0, y0 = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
    ok = (z_ref > 1e-3) & (x0 - radius >= 0) & (y0 - radius >= 0) & (x0 + 1 + radius < w) & \
        (y0 + 1 + radius < h)
    ok[ok] &= ref_valid[y0[ok], x0[ok]]
    if ok.sum() < MIN_RING_PIXELS:
        return None
    return ref_grey, ref_valid, y0[ok], x0[ok], v[ok] - y0[ok], u[ok] - x0[ok], ring.grey[ok]


@njit(cache=True, nogil=True)
def _zncc_per_shift(grey, valid, y0, x0, fy, fx, t, shifts):
    """ZNCC of the target's ring values `t` with the reference's bilinear samples at (y0 + fy + dy, x0 + fx +
    dx), for each whole-pixel shift (dy, dx) of `shifts` (S, 2); samples touching a pixel that is not `valid`
    are left out of that shift's score, and a shift that loses half of them scores -2."""
    out = np.full(len(shifts), -2.0)
    for k in range(len(shifts)):
        dy, dx = shifts[k, 0], shifts[k, 1]
        n, st, ss, sst, sr, srr = 0, 0.0, 0.0, 0.0, 0.0, 0.0
        for i in range(len(t)):
            y, x = y0[i] + dy, x0[i] + dx
            if not (valid[y, x] and valid[y, x + 1] and valid[y + 1, x] and valid[y + 1, x + 1]):
                continue
            a, b = fy[i], fx[i]
            r = (grey[y, x] * (1 - a) * (1 - b) + grey[y, x + 1] * (1 - a) * b + grey[y + 1, x] * a * (1 - b)
                 + grey[y + 1, x + 1] * a * b)
            n += 1
            st += t[i]
            ss += t[i] * t[i]
            sr += r
            srr += r * r
            sst += r * t[i]
        if n < max(2, len(t) // 2):  # a shift that loses half the ring to invalid pixels is not comparable
            continue
        cov = sst - sr * st / n
        var = (ss - st * st / n) * (srr - sr * sr / n)
        if var > 1e-9:
            out[k] = cov / np.sqrt(var)
    return out
