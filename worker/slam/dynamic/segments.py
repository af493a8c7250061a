"""Object segments: connected regions of a mask, split where depth jumps (two people, or a person in front
of a chair, become separate segments even when their pixels touch)."""
from __future__ import annotations

import cv2
import numpy as np
from numba import njit


def depth_edges(depth: np.ndarray, rel_jump: float = 0.05) -> np.ndarray:
    """bool (H, W): pixels where depth jumps by more than `rel_jump` of itself to a 4-neighbour, or is invalid."""
    d = depth.astype(np.float32)
    # |b - a| > rel * min(a, b)  <=>  |ln b - ln a| > ln(1 + rel): one log, then OpenCV's absdiff per axis
    # (half the time of the ratio in numpy on a full frame; the same edges on the benchmark frames)
    log_d = cv2.log(np.maximum(d, np.float32(1e-3)))
    c = float(np.log1p(rel_jump))
    edges = (d <= 0).view(np.uint8)
    for first, second in ((np.s_[:-1], np.s_[1:]), (np.s_[:, :-1], np.s_[:, 1:])):
        jump = (cv2.absdiff(log_d[first], log_d[second]) > c).view(np.uint8)
        edges[first] |= jump
        edges[second] |= jump
    return edges.view(bool)


def split_segments(mask: np.ndarray, depth: np.ndarray, min_area: int = 200, rel_jump: float = 0.05,
                   step: int = 1) -> np.ndarray:
    """int32 labels (H, W): 0 = not in `mask`, 1..n = segments of at least `min_area` pixels.

    Components are computed with depth edges cut out, then edge pixels are given back to a neighbouring
    segment (dilation) so the segment still covers the whole object outline. With `step` > 1 on every
    step-th row and column only (`min_area` scaled to match), each mask pixel then taking the label of the
    sample at the top left of its step x step block (blocks from the image's corner): the split of
    `mask[::step, ::step]` spread back, step² times less work, segments accurate to `step` px.
    """
    m = mask.astype(bool, copy=False)
    out = np.zeros(mask.shape, np.int32)
    rows, cols = np.flatnonzero(m.any(1)), np.flatnonzero(m.any(0))
    if len(rows) == 0:
        return out
    # Work on the mask's bounding box, one sample wider so depth jumps at its border are seen (people cover
    # ~15 %), starting on a sample of the whole image's grid.
    h, w = m.shape
    y0, y1 = max(rows[0] - step, 0) // step * step, min(rows[-1] + step + 1, h)
    x0, x1 = max(cols[0] - step, 0) // step * step, min(cols[-1] + step + 1, w)
    if step == 1:
        out[y0:y1, x0:x1] = _split(m[y0:y1, x0:x1], depth[y0:y1, x0:x1], min_area, rel_jump)
        return out
    box = np.s_[y0:y1:step, x0:x1:step]
    coarse = _split(np.ascontiguousarray(m[box]), np.ascontiguousarray(depth[box]), -(-min_area // step**2),
                    rel_jump)
    _spread_labels(coarse, m[y0:y1, x0:x1], step, out[y0:y1, x0:x1])
    return out


@njit(cache=True, nogil=True)
def _spread_labels(coarse, m, step, out):
    """`out` (H, W) = the label of `coarse` (ceil(H / step), ceil(W / step)) at each pixel's block where `m`
    holds, else 0."""
    h, w = m.shape
    row = np.empty(w, out.dtype)
    for y in range(h):
        if y % step == 0:  # one coarse row spread over the width, reused by the block's rows
            for x in range(w):
                row[x] = coarse[y // step, x // step]
        for x in range(w):
            out[y, x] = row[x] * m[y, x]


def _split(m: np.ndarray, depth: np.ndarray, min_area: int, rel_jump: float) -> np.ndarray:
    # the mask without depth edges in one compiled pass over OpenCV's logarithm (`depth_edges`' arithmetic)
    d = depth.astype(np.float32, copy=False)
    inner = _inner(m, d, cv2.log(np.maximum(d, np.float32(1e-3))), np.float32(np.log1p(rel_jump)))
    # OpenCV's components without its statistics: two thirds of the time of `connectedComponentsWithStats`
    n, labels = cv2.connectedComponents(inner, connectivity=4)
    # uint16 labels (VGA: at most H*W/min_area = 1536 segments): OpenCV dilates them directly
    grown = _renumber(labels, n, min_area, np.uint16(0) if n <= np.iinfo(np.uint16).max else np.float32(0))
    # Give the cut-out edge pixels (and small fragments) of the mask to the nearest kept segment (OpenCV's
    # dilation of the whole box, then a compiled fill; its vector max beat a compiled one at the pixels to fill
    # alone, 0.9 against 4.8 ms on a Bonn frame)
    square = np.ones((5, 5), np.uint8)
    for _ in range(3):
        if not _fill_from(grown, cv2.dilate(grown, square), m):
            break
    return grown


@njit(cache=True, nogil=True)
def _fill_from(grown, dil, m):
    """`grown` (H, W) takes `dil` where `m` holds, `grown` is 0 and `dil` is not; True if any such pixel of `m`
    is still 0 after."""
    h, w = grown.shape
    left = False
    for y in range(h):
        for x in range(w):
            if m[y, x] and grown[y, x] == 0:
                if dil[y, x] > 0:
                    grown[y, x] = dil[y, x]
                else:
                    left = True
    return left


@njit(cache=True, nogil=True)
def _inner(m, depth, log_d, c):
    """uint8 (H, W): 1 where `m` holds, depth is valid and |Δ log depth| to every 4-neighbour is at most `c`."""
    h, w = m.shape
    out = np.zeros((h, w), np.uint8)
    for y in range(h):
        for x in range(w):
            if not m[y, x] or depth[y, x] <= 0:
                continue
            v = log_d[y, x]
            if (y > 0 and abs(v - log_d[y - 1, x]) > c) or (y + 1 < h and abs(v - log_d[y + 1, x]) > c) or \
                    (x > 0 and abs(v - log_d[y, x - 1]) > c) or (x + 1 < w and abs(v - log_d[y, x + 1]) > c):
                continue
            out[y, x] = 1
    return out


@njit(cache=True, nogil=True)
def _renumber(labels, n, min_area, zero):
    """`labels` (H, W) of `n` components renumbered 1.. in order over those of at least `min_area` pixels, the
    rest 0, as `zero`'s dtype (numpy's bincount would first copy the labels to int64)."""
    h, w = labels.shape
    area = np.zeros(n, np.int64)
    for y in range(h):  # counted by runs: neighbours mostly share a label, and `area[lab] += 1` per pixel stalls
        run_label, run = labels[y, 0], 0
        for x in range(w):
            if labels[y, x] != run_label:
                area[run_label] += run
                run_label, run = labels[y, x], 0
            run += 1
        area[run_label] += run
    keep = np.zeros(n, type(zero))
    k = 0
    for lab in range(1, n):
        if area[lab] >= min_area:
            k += 1
            keep[lab] = k
    out = np.empty((h, w), type(zero))
    for y in range(h):
        for x in range(w):
            out[y, x] = keep[labels[y, x]]
    return out


@njit(cache=True, nogil=True)
def pixels_of(labels: np.ndarray, chosen: np.ndarray) -> np.ndarray:
    """bool (H, W): the pixels of the segments `labels` (H, W) whose entry in `chosen` (L+1,) bool is True, in
    one compiled pass (numpy's `take` first copies int32 labels to int64: 0.3 ms per VGA frame)."""
    h, w = labels.shape
    out = np.empty((h, w), np.bool_)
    for y in range(h):
        for x in range(w):
            out[y, x] = chosen[labels[y, x]]
    return out


def grow_by_depth(region: np.ndarray, depth: np.ndarray, grow_px: int, rel_tol: float = 0.15,
                  rel_jump: float = 0.05) -> np.ndarray:
    """bool (H, W): `region` (one object) extended into the pixels that continue its surface: within `grow_px`
    of it, reachable without crossing a depth edge, and within `rel_tol` of its median depth (metres, `depth`).

    Segmentation under-covers people (limbs, hair, the last frames of a fast mover); their pixels are
    bounded by depth discontinuities, so the surface can be completed from depth alone. `grow_px` bounds
    the leak where a person touches something at the same depth (feet on the floor)."""
    if grow_px <= 0:
        return region
    ys, xs = np.nonzero(region)
    if len(ys) == 0:
        return region
    h, w = region.shape
    y0, y1 = max(ys.min() - grow_px, 0), min(ys.max() + grow_px + 1, h)
    x0, x1 = max(xs.min() - grow_px, 0), min(xs.max() + grow_px + 1, w)
    r, d = region[y0:y1, x0:x1], depth[y0:y1, x0:x1]
    z = d[r & (d > 0)]
    if len(z) == 0:
        return region
    zmed = float(np.median(z))
    # within grow_px of the region: a distance transform, whose cost does not grow with the radius as a
    # dilation with a (2 grow_px + 1) disc does
    near = cv2.distanceTransform((~r).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE) <= grow_px
    on_surface = near & (np.abs(d - zmed) < rel_tol * zmed)
    union = r | (on_surface & ~depth_edges(d, rel_jump))
    _, lab = cv2.connectedComponents(union.astype(np.uint8), connectivity=4)
    touched = np.unique(lab[r])
    grown = np.isin(lab, touched[touched > 0])
    # the object's own outline is a depth edge too: give back the edge pixels at its depth
    grown |= on_surface & (cv2.dilate(grown.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0)
    out = region.copy()
    out[y0:y1, x0:x1] |= grown
    return out
