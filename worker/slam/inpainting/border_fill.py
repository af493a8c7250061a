"""Hole pixels no reference sees, depth and colour: what surrounds the hole continued into it.

A plane's inverse depth is an affine function of the pixel coordinates, and a harmonic interpolant (Laplace's
equation, the border's values fixed) reproduces affine functions exactly: solving it for inverse depth over the
unknown pixels continues a plane that surrounds the hole without error, and blends two planes that meet inside
it (the crease is rounded off). The border includes pixels the references restored by geometry, so the unknown
region is usually a thin band. Large regions are solved on a coarser grid (bilinear upsampling keeps planes
exact too), so the sparse solve stays small. Colour gets the same interpolant (the smoothest shading that meets
the border): no texture is invented, so no false corners for the tracker, and over real frames it is closer to the
hidden background than Telea's fast-marching fill.
"""
from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

_MAX_UNKNOWNS = 6000
"""The grid is coarsened (2x per step) until at most this many pixels are unknown: the solve's cost."""


Window = Callable[[slice, slice], tuple[np.ndarray, np.ndarray]]
"""(rows, cols) of the image -> its values there (h, w, C) and which of them are known (h, w) bool."""


def fill_depth_from_border(depth: np.ndarray, fill: np.ndarray,
                           pixels: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Depth (N,) float32 m for the N pixels of `fill` (H, W) bool, row-major, from `depth` (H, W) float32 m
    (0 = unknown; pixels of `fill` are ignored). 0 where no known depth is connected to continue from.
    `pixels`: `np.nonzero(fill)` when the caller has it (see `harmonic_fill`)."""
    def inverse_depth(rows: slice, cols: slice) -> tuple[np.ndarray, np.ndarray]:
        d = depth[rows, cols]
        known = d > 0
        return np.where(known, 1.0 / np.where(known, d, 1.0), 0.0)[..., None], known

    q = harmonic_fill(fill, inverse_depth, pixels)[:, 0]
    return np.where(q > 1e-6, 1.0 / np.maximum(q, 1e-6), 0.0).astype(np.float32)


def harmonic_fill(fill: np.ndarray, window: Window,
                  pixels: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(N, C) float64 for the N pixels of `fill` (H, W) bool, row-major: the harmonic interpolant of the image
    `window` reads (only around `fill`, so per-pixel work stays there) from its known pixels outside `fill`,
    all channels in one solve. 0 where no known pixel is connected (on the coarse grid: also next to a coarse
    pixel nothing reached). `pixels` (rows, cols): `np.nonzero(fill)` when the caller already has it (a
    full-image pass, 0.5 ms on VGA)."""
    h, w = fill.shape
    fy, fx = np.nonzero(fill) if pixels is None else pixels
    scale = 1
    while len(fy) / scale**2 > _MAX_UNKNOWNS:
        scale *= 2
    m = 2 * scale
    y0, y1 = (max(int(fy.min()) - m, 0), min(int(fy.max()) + m + 1, h)) if len(fy) else (0, 0)
    x0, x1 = (max(int(fx.min()) - m, 0), min(int(fx.max()) + m + 1, w)) if len(fx) else (0, 0)
    values, known = window(slice(y0, y1), slice(x0, x1))
    if len(fy) == 0:
        return np.zeros((0, values.shape[2]))
    known = known & ~fill[y0:y1, x0:x1]
    val = np.where(known[..., None], values, 0.0)
    if scale > 1:
        # a coarse pixel is known only if its whole block is (no unknown value averaged in)
        ch, cw = -(-(y1 - y0) // scale), -(-(x1 - x0) // scale)
        pad = ((0, ch * scale - (y1 - y0)), (0, cw * scale - (x1 - x0)))
        kb = np.pad(known, pad).reshape(ch, scale, cw, scale)
        vb = np.pad(val, pad + ((0, 0),)).reshape(ch, scale, cw, scale, -1)
        known_c = np.asarray(kb.all(axis=(1, 3)), bool)
        val_c = np.where(known_c[..., None], vb.mean(axis=(1, 3)), 0.0)
    else:
        known_c, val_c = known, val
    solved, reached = _harmonic(val_c, known_c)
    if scale > 1:
        # coarse pixel centres sit at (scale - 1) / 2 + scale * i in the window
        u = ((fx - x0) - (scale - 1) / 2) / scale
        v = ((fy - y0) - (scale - 1) / 2) / scale
        q = np.stack([_bilinear(solved[..., c], u, v) for c in range(solved.shape[2])], 1)
        # a sample next to a coarse pixel nothing reached would mix in its 0: those stay unknown
        ok = _bilinear(reached.astype(np.float64), u, v) > 0.999
        return np.where(ok[:, None], q, 0.0)
    return np.where(reached[fy - y0, fx - x0, None], solved[fy - y0, fx - x0], 0.0)


def _bilinear(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """`img` (h, w) sampled at (N,) points (u = column, v = row), clamped to its edge."""
    h, w = img.shape
    u, v = np.clip(u, 0, w - 1), np.clip(v, 0, h - 1)
    x0, y0 = np.minimum(np.floor(u).astype(int), w - 2).clip(0), np.minimum(np.floor(v).astype(int), h - 2).clip(0)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    a, b = u - x0, v - y0
    return ((1 - a) * (1 - b) * img[y0, x0] + a * (1 - b) * img[y0, x1] + (1 - a) * b * img[y1, x0]
            + a * b * img[y1, x1])


def _harmonic(val: np.ndarray, known: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`val` (h, w, C) with its unknown pixels replaced by the solution of Laplace's equation (5-point stencil,
    known pixels fixed, the window's edge free), and bool (h, w): known or solved. Unknown pixels with no known
    pixel in their component get 0."""
    h, w = known.shape
    n_lab, lab = cv2.connectedComponents((~known).astype(np.uint8), connectivity=4)
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))  # 4-neighbours: the stencil's own
    touching = np.unique(lab[cv2.dilate(known.astype(np.uint8), cross) > 0])
    solvable = ~known & np.isin(lab, touching[touching > 0])
    ys, xs = np.nonzero(solvable)
    out = np.where(known[..., None], val, 0.0)
    n = len(ys)
    if n == 0:
        return out, known.copy()
    idx = np.full((h, w), -1, np.int64)
    idx[ys, xs] = np.arange(n)
    diag = np.zeros(n)
    b = np.zeros((n, val.shape[2]))
    rows, cols = [], []
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        ny, nx = ys + dy, xs + dx
        inside = (ny >= 0) & (ny < h) & (nx >= 0) & (nx < w)
        nyc, nxc = np.clip(ny, 0, h - 1), np.clip(nx, 0, w - 1)
        unk = inside & (idx[nyc, nxc] >= 0)
        fixed = inside & known[nyc, nxc]
        diag += unk | fixed
        b += np.where(fixed[:, None], val[nyc, nxc], 0.0)
        rows.append(np.flatnonzero(unk))
        cols.append(idx[nyc, nxc][unk])
    r, c = np.concatenate(rows), np.concatenate(cols)
    A = sp.csc_matrix((np.r_[diag, -np.ones(len(r))], (np.r_[np.arange(n), r], np.r_[np.arange(n), c])),
                      shape=(n, n))
    out[ys, xs] = sla.spsolve(A, b).reshape(n, -1)
    return out, known | solvable
