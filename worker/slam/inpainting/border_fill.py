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

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from numba import njit

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
    if scale > 1:
        known_c, val_c = _block_means(values, known, scale)
    else:
        known_c, val_c = known, np.where(known[..., None], values, 0.0)
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


@njit(cache=True, nogil=True)
def _block_means(values, known, scale):
    """The (h, w, C) `values` on a grid `scale` times coarser: bool (ceil(h / s), ceil(w / s)), whether a block
    is known (all its pixels known and inside the window: no unknown value averaged in), and the blocks' means
    in float64 (0 where not known), summed row by row. One pass instead of numpy's padding, reshapes and
    reductions over the window, which after the solve were the fill's largest cost."""
    h, w, n_ch = values.shape
    ch, cw = -(-h // scale), -(-w // scale)
    known_c = np.zeros((ch, cw), np.bool_)
    val_c = np.zeros((ch, cw, n_ch))
    acc = np.zeros(n_ch)
    for by in range(ch):
        for bx in range(cw):
            y0, x0 = by * scale, bx * scale
            if y0 + scale > h or x0 + scale > w:
                continue  # the block runs past the window: padded with unknowns
            ok = True
            acc[:] = 0.0
            for y in range(y0, y0 + scale):
                for x in range(x0, x0 + scale):
                    if not known[y, x]:
                        ok = False
                        break
                    for c in range(n_ch):
                        acc[c] += values[y, x, c]
                if not ok:
                    break
            if ok:
                known_c[by, bx] = True
                for c in range(n_ch):
                    val_c[by, bx, c] = acc[c] / (scale * scale)
    return known_c, val_c


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
    solvable = _reachable(known)
    out = np.where(known[..., None], val, 0.0)
    indptr, indices, data, b, ys, xs = _laplace_system(np.asarray(val, np.float64), known, solvable)
    n = len(ys)
    if n == 0:
        return out, known.copy()
    # SuperLU's own (COLAMD) order: the natural row-major order was faster on a person-sized hole (1.4 against
    # 2.2 ms) but its fill grows with the window's width, and on Bonn's half-the-view masks restoration took
    # 2.3x as long end to end
    A = sp.csc_matrix((data, indices, indptr), shape=(n, n))
    out[ys, xs] = sla.spsolve(A, b).reshape(n, -1)
    return out, known | solvable


@njit(cache=True, nogil=True)
def _reachable(known):
    """bool (h, w): the unknown pixels connected (4-neighbours, through unknown pixels) to a known one."""
    h, w = known.shape
    out = np.zeros((h, w), np.bool_)
    stack = np.empty(h * w, np.int64)
    top = 0
    for y in range(h):
        for x in range(w):
            if known[y, x] or out[y, x]:
                continue
            if (y > 0 and known[y - 1, x]) or (y + 1 < h and known[y + 1, x]) or \
                    (x > 0 and known[y, x - 1]) or (x + 1 < w and known[y, x + 1]):
                out[y, x] = True
                stack[top] = y * w + x
                top += 1
    while top:
        top -= 1
        y, x = stack[top] // w, stack[top] % w
        for ny, nx in ((y - 1, x), (y + 1, x), (y, x - 1), (y, x + 1)):
            if 0 <= ny < h and 0 <= nx < w and not known[ny, nx] and not out[ny, nx]:
                out[ny, nx] = True
                stack[top] = ny * w + nx
                top += 1
    return out


@njit(cache=True, nogil=True)
def _laplace_system(val, known, solvable):
    """The 5-point Laplace system of the `solvable` (h, w) pixels, numbered row-major: the matrix in CSC form
    (indptr, indices, data; rows sorted within each column: the canonical form scipy would build), the
    right-hand side (n, C) of the known neighbours' `val` (h, w, C) (summed right, left, down, up), and the
    unknowns' (rows, cols). One compiled pass instead of numpy's per-direction arrays and scipy's COO->CSC."""
    h, w = known.shape
    idx = np.full((h, w), -1, np.int64)
    n = 0
    for y in range(h):
        for x in range(w):
            if solvable[y, x]:
                idx[y, x] = n
                n += 1
    ys, xs = np.empty(n, np.int64), np.empty(n, np.int64)
    indptr = np.zeros(n + 1, np.int64)
    indices = np.empty(5 * n, np.int64)
    data = np.empty(5 * n)
    b = np.zeros((n, val.shape[2]))
    k = 0
    for y in range(h):
        for x in range(w):
            j = idx[y, x]
            if j < 0:
                continue
            ys[j], xs[j] = y, x
            deg = 0.0
            for ny, nx in ((y, x + 1), (y, x - 1), (y + 1, x), (y - 1, x)):
                if 0 <= ny < h and 0 <= nx < w:
                    if idx[ny, nx] >= 0:
                        deg += 1.0
                    elif known[ny, nx]:
                        deg += 1.0
                        for c in range(val.shape[2]):
                            b[j, c] += val[ny, nx, c]
            # column j: its unknown neighbours and itself, by row number (up, left, self, right, down)
            for ny, nx in ((y - 1, x), (y, x - 1), (y, x), (y, x + 1), (y + 1, x)):
                if 0 <= ny < h and 0 <= nx < w and idx[ny, nx] >= 0:
                    indices[k] = idx[ny, nx]
                    data[k] = deg if idx[ny, nx] == j else -1.0
                    k += 1
            indptr[j + 1] = k
    return indptr, indices[:k], data[:k], b, ys, xs
