"""Restore the RGB and depth behind removed (dynamic) regions from reference frames.

Geometry first: each reference's static pixels are forward-projected into the target with depth and relative
pose; that gives every hole pixel it covers a starting match. PatchMatch then corrects what geometry gets wrong
(pose or depth noise, colour/depth misregistration) and fills what no reference sees from the target's own
static region. Depth comes through the same matches (reference depth expressed in the target camera), with a
confidence from the match cost so unreliable pixels stay invalid.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numba import njit

from worker.slam.config import valid
from worker.slam.inpainting.align import Ring, hole_ring, ring_shift
from worker.slam.inpainting.border_fill import fill_depth_from_border, harmonic_fill
from worker.slam.inpainting.gain import colour_gain
from worker.slam.inpainting.patchmatch import PatchMatchConfig, patchmatch_fill
from worker.slam.inpainting.refine import PoseRefinementConfig, PoseRefiner
from worker.slam.inpainting.warp import depth_in_target, forward_warp, relative_pose, sample_reference

UNSEEN_FILLS = ("telea", "harmonic", "patchmatch")


@dataclass(frozen=True)
class RestorationConfig:
    """Background restoration of one frame."""

    patchmatch: PatchMatchConfig = field(default_factory=PatchMatchConfig)
    refine: PoseRefinementConfig = field(default_factory=PoseRefinementConfig)
    """Each reference's relative pose is first corrected by photometric alignment with the target's static
    pixels (`refine.py`)."""
    use_target_as_source: bool = True
    """Let PatchMatch copy from the target's own static region where no reference sees the background."""
    unseen_fill: str = "harmonic"
    """How pixels no reference sees are filled: "harmonic" (the smoothest continuation of the colours around
    them, Laplace's equation with the border fixed, solved like the unseen depth, `border_fill`), "telea" (OpenCV's
    fast-marching diffusion from the border) or "patchmatch" (the paper: texture copied from the references' and
    the frame's own static regions). The smooth fills invent no texture, hence no false ORB corners; against the
    true background copied look-alike texture scores worse than a smooth guess and costs a full-image search,
    and harmonic beats Telea. Geometry-seen pixels are the same either way.
    Measured: docs/results/settings.md#restoration-unseen_fill"""

    def __post_init__(self) -> None:
        if self.unseen_fill not in UNSEEN_FILLS:
            raise ValueError(f"unseen_fill must be one of {UNSEEN_FILLS}, not {self.unseen_fill!r}")
        if self.unseen_depth not in ("border", "none"):
            raise ValueError(f"unseen_depth must be 'border' or 'none', not {self.unseen_depth!r}")
    max_depth_cost: float = valid(0.002, 1e-6, 3.0)
    """Matches whose patch cost (mean squared colour error, colours in [0, 1]) exceeds this give no depth."""
    subpixel: bool = True
    """Geometry-seen pixels take the reference colour at the exact sub-pixel point (bilinear) instead of the
    nearest reference pixel the splat found."""
    searched_depth: bool = False
    """Give depth to pixels PatchMatch found by appearance alone (no geometric support). Off: on synthetic truth
    their depth is typically wrong by centimetres to decimetres (look-alike textures elsewhere), so they stay
    invalid."""
    unseen_depth: str = "border"
    """Depth of hole pixels that get none from a reference: "border" continues the surrounding surfaces
    (inverse depth carried in from the hole's border, `border_fill`), "none" leaves them invalid."""
    border_depth_confidence: float = valid(0.25, 0.0, 1.0)
    """Confidence of border-continued depth: below the restored-feature threshold, since a crease or an
    object hidden entirely inside the hole is guessed, not seen."""
    colour_gain: bool = True
    """Scale each reference's copied colours by its per-channel gain to the target, measured on the static
    pixels around the hole that the reference sees too (`gain.py`): real cameras change exposure between frames."""
    align_px: int = valid(0, 0, 32)
    """> 0: each reference's colours are taken up to this many whole pixels away from where geometry puts them:
    the shift that best matches the static ring around the hole (`align.ring_shift`; needs `subpixel`). Off:
    it pays with poses from elsewhere, a few pixels off the images, not with the tracker's (consistent with
    them). Measured: docs/results/settings.md#restoration-align_px"""
    blend_refs: int = valid(2, 1, 16)
    """Hole pixels references see through geometry average the colours (each at its reference's gain) and the
    depths of up to this many of them, in reference order, each agreeing with the depth averaged so far within
    `blend_depth_tol`; 1 = the first (best) reference alone. Warps from two poses err differently (depth noise,
    a pose a few pixels off), so their average is closer to the truth; a third gained nothing more.
    Measured: docs/results/settings.md#restoration-blend_refs"""
    blend_depth_tol: float = valid(0.05, 0.0, 10.0)
    """Relative depth difference within which a further reference joins a pixel's average (beyond it, it saw
    another surface)."""
    align_ring_px: int = valid(15, 1, 200)
    """Width of that ring (pixels outside the hole)."""
    geometry_first: bool = True
    """Hole pixels a reference sees through geometry take that pixel directly and become context; PatchMatch
    searches only the rest: on synthetic truth free PatchMatch over geometry-initialised pixels drifted to
    look-alike patches, so geometry is trusted where it exists."""


@dataclass(frozen=True)
class ReferenceView:
    """A reference frame: `rgb` RGB uint8 (H, W, 3), `depth` float32 m (H, W), pose `T_WC`, and `dynamic`
    bool (H, W) marking its own moving pixels, which must not be copied. The algorithm's input, not a history:
    the stage builds it from the run's history records (`worker.slam.history.PastFrame`) or a frame read ahead."""

    rgb: np.ndarray
    depth: np.ndarray
    T_WC: np.ndarray
    dynamic: np.ndarray


@dataclass(frozen=True)
class Restoration:
    """`rgb` (H, W, 3) uint8 and `depth` (H, W) float32 m with the hole filled; `depth_confidence` (H, W) in
    [0, 1] (0 outside the hole and where depth was left invalid); `from_geometry` fraction of hole pixels whose
    final match is a reference pixel; `from_self` fraction copied from the target itself."""

    rgb: np.ndarray
    depth: np.ndarray
    depth_confidence: np.ndarray
    hole: np.ndarray
    seen_by_reference: np.ndarray
    """bool (H, W): hole pixels some reference sees through geometry."""
    from_geometry: float
    from_self: float
    poses_refined: int = 0
    """References whose relative pose the photometric refinement corrected (`refine.py`)."""


def restore_frame(rgb: np.ndarray, depth: np.ndarray, hole: np.ndarray, T_WC: np.ndarray,
                  refs: list[ReferenceView], K: np.ndarray,
                  config: RestorationConfig = RestorationConfig()) -> Restoration:
    """Fill `hole` (H, W) bool in `rgb` (H, W, 3) uint8 and `depth` (H, W) float32 of a frame at pose T_WC.

    In order: every reference is warped into the hole (`_warp_references`); pixels references see take their
    blended colour and depth (`_blend_geometry`); the rest are filled by `config.unseen_fill`; depth comes
    through the final matches, else from the hole's border (`_restored_depth`)."""
    h, w = hole.shape
    if not hole.any():
        return Restoration(rgb.copy(), depth.copy(), np.zeros((h, w), np.float32), hole, hole.copy(), 0.0, 0.0)
    pix = _HolePixels.of(hole)
    warps = _warp_references(rgb, depth, hole, T_WC, refs, K, config, pix)
    sources, valid, self_index = _sources(rgb, hole, refs, warps, config)
    matches = _Matches(warps.init_src.copy(), warps.init_yx.copy(), np.zeros(len(pix.py)))
    out_rgb = rgb.copy()
    geo = warps.init_src >= 0
    d = np.zeros(len(pix.py), np.float32)  # each hole pixel's depth in the target, through its match
    if config.geometry_first and geo.any():
        _blend_geometry(rgb, depth, hole, refs, K, config, pix, warps, out_rgb, d)
    search = ~geo if config.geometry_first else np.ones(len(pix.py), bool)
    if search.any() and config.unseen_fill in ("telea", "harmonic"):
        _smooth_fill(out_rgb, hole, pix.py[search], pix.px[search], config.unseen_fill)
        matches.src[search], matches.cost[search] = self_index, np.inf  # from the frame itself, with no depth
    elif search.any():
        out_rgb = _patchmatch_fill(out_rgb, hole, pix, search, sources, valid, warps, config.patchmatch, matches)
    todo = ~geo if config.geometry_first else np.ones(len(pix.py), bool)  # geometry's matches have their depth
    _match_depths(refs, K, warps, matches, todo, d)
    out_depth, confidence = _restored_depth(depth, hole, pix, d, matches, geo, config)
    n = max(len(pix.py), 1)
    from_self = float(np.sum(matches.src == self_index)) / n
    seen = np.zeros_like(hole)
    seen[pix.py[geo], pix.px[geo]] = True
    return Restoration(out_rgb, out_depth, confidence, hole, seen, 1.0 - from_self if refs else 0.0, from_self,
                       warps.refined)


@dataclass(frozen=True)
class _HolePixels:
    """The hole's N pixels in row-major order: `py`, `px` (N,) int64 image rows and columns; `region`
    (y0, y1, x0, x1) their bounding box; `ry`, `rx` (N,) int64 the same pixels relative to the box."""

    py: np.ndarray
    px: np.ndarray
    region: tuple[int, int, int, int]
    ry: np.ndarray
    rx: np.ndarray

    @staticmethod
    def of(hole: np.ndarray) -> _HolePixels:
        """The pixels of `hole` (H, W) bool, which has at least one."""
        py, px = np.nonzero(hole)
        region = (int(py.min()), int(py.max()) + 1, int(px.min()), int(px.max()) + 1)
        return _HolePixels(py, px, region, py - region[0], px - region[2])


@dataclass(frozen=True)
class _Warps:
    """The references warped into the target, one entry per reference in order: `rel` (4, 4) reference camera
    -> target camera (photometrically refined if enabled), `valid` (H, W) bool its static pixels, `gains` (3,)
    float64 its colour gain to the target, `landed` (h, w, 2) int64 the reference pixel that lands on each pixel
    of the hole's region (-1: none, `forward_warp`). Per hole pixel: `init_src` (N,) int64 the first (best)
    reference that lands there (-1: none) and `init_yx` (N, 2) int64 its pixel. `refined`: references whose
    pose the refinement corrected."""

    rel: list[np.ndarray]
    valid: list[np.ndarray]
    gains: list[np.ndarray]
    landed: list[np.ndarray]
    init_src: np.ndarray
    init_yx: np.ndarray
    refined: int


@dataclass(frozen=True)
class _Matches:
    """Each hole pixel's final match, filled in place as the steps decide: `src` (N,) int64 the source image
    (a reference's index, the target's own `self_index`, -1 none), `yx` (N, 2) int64 the pixel there, `cost`
    (N,) float64 its patch cost (0 for geometry's matches, inf for smooth fills)."""

    src: np.ndarray
    yx: np.ndarray
    cost: np.ndarray


def _warp_references(rgb: np.ndarray, depth: np.ndarray, hole: np.ndarray, T_WC: np.ndarray,
                     refs: list[ReferenceView], K: np.ndarray, config: RestorationConfig,
                     pix: _HolePixels) -> _Warps:
    """Each reference's relative pose (refined against the target's static pixels if enabled), its static
    pixels forward-warped into the hole's region and its colour gain; the first reference landing on each hole
    pixel is its starting match (references in order of preference)."""
    init_src = np.full(len(pix.py), -1, np.int64)
    init_yx = np.full((len(pix.py), 2), -1, np.int64)
    refiner = None
    if config.refine.enabled and refs:
        ring = hole_ring(rgb, depth, hole, pix.region, config.refine.check_ring_px)
        refiner = PoseRefiner(rgb, depth, ~hole, K, ring, config.refine)
    rel: list[np.ndarray] = []
    valid: list[np.ndarray] = []
    gains: list[np.ndarray] = []
    landed: list[np.ndarray] = []
    refined = 0
    for s, ref in enumerate(refs):
        rel.append(relative_pose(ref.T_WC, T_WC))
        valid.append(~ref.dynamic)
        if refiner is not None:
            rel[-1], better = refiner.refine(ref.rgb, ref.depth, valid[-1], rel[-1])
            refined += better
        landed_region = forward_warp(ref.depth, valid[-1], rel[-1], K, pix.region)
        gains.append(colour_gain(rgb, hole, ref.rgb, landed_region, pix.region) if config.colour_gain
                     else np.ones(3))
        # pixels no earlier (better) reference reached take this one's
        first, yx = _landings(landed_region, pix.ry, pix.rx, (init_src >= 0).astype(np.int64), 1)
        init_src[first], init_yx[first] = s, yx
        landed.append(landed_region)
    return _Warps(rel, valid, gains, landed, init_src, init_yx, refined)


def _sources(rgb: np.ndarray, hole: np.ndarray, refs: list[ReferenceView], warps: _Warps,
             config: RestorationConfig) -> tuple[list[np.ndarray], list[np.ndarray], int]:
    """PatchMatch's source images (H, W, 3) uint8 and their copyable pixels (H, W) bool: the references, then
    the target itself (away from the hole) if it may be copied from; and the target's index (-1: not a source)."""
    sources = [ref.rgb for ref in refs]
    valid = list(warps.valid)
    self_index = -1
    if config.use_target_as_source or not refs:
        self_index = len(sources)
        sources.append(rgb)
        valid.append(~cv2.dilate(hole.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool))
    return sources, valid, self_index


def _blend_geometry(rgb: np.ndarray, depth: np.ndarray, hole: np.ndarray, refs: list[ReferenceView],
                    K: np.ndarray, config: RestorationConfig, pix: _HolePixels, warps: _Warps,
                    out_rgb: np.ndarray, d: np.ndarray) -> None:
    """Hole pixels references see through geometry: written into `out_rgb` (H, W, 3) uint8 and their depth in
    the target into `d` (N,) float32, each averaging up to `blend_refs` references (at their gains) that agree
    with the depth averaged so far."""
    aligned = config.align_px and config.subpixel  # the shift moves the sub-pixel samples
    ring = hole_ring(rgb, depth, hole, pix.region, config.align_ring_px) if aligned else None
    acc, z_acc = np.zeros((len(pix.py), 3)), np.zeros(len(pix.py))
    n_acc = np.zeros(len(pix.py), np.int64)
    for s, ref in enumerate(refs):
        sel, yx_sel = _landings(warps.landed[s], pix.ry, pix.rx, n_acc, config.blend_refs)
        if not len(sel):
            continue
        z = depth_in_target(ref.depth, yx_sel, warps.rel[s], K)
        agree = _agreeing(sel, z, z_acc, n_acc, config.blend_depth_tol)
        if not agree.all():
            sel, yx_sel, z = sel[agree], yx_sel[agree], z[agree]
        col = ref.rgb[yx_sel[:, 0], yx_sel[:, 1]]
        if config.subpixel:
            col = _subpixel_colours(ref, warps.valid[s], warps.rel[s], K, ring, config.align_px,
                                    np.stack([pix.py[sel], pix.px[sel]], 1), z, col)
        _accumulate(acc, z_acc, n_acc, sel, col, np.asarray(warps.gains[s], np.float64), z)
    done = np.flatnonzero(n_acc > 0)
    n_done = n_acc[done].astype(np.float64)
    d[done] = z_acc[done] / n_done
    out_rgb[pix.py[done], pix.px[done]] = np.clip(acc[done] / n_done[:, None] + 0.5, 0, 255).astype(np.uint8)


def _subpixel_colours(ref: ReferenceView, valid: np.ndarray, rel: np.ndarray, K: np.ndarray, ring: Ring | None,
                      align_px: int, target_yx: np.ndarray, z: np.ndarray, nearest: np.ndarray) -> np.ndarray:
    """(K, 3) colours of target pixels `target_yx` (K, 2) at depths `z` (K,) m, taken at the exact sub-pixel
    point of the reference (T_tr `rel`) they come from, shifted to match `ring` if given; `nearest` (K, 3)
    (the splat's pixels) where a bilinear neighbour is not in `valid` (H, W) bool."""
    shift = (0, 0)
    if ring is not None:
        ref_grey = cv2.cvtColor(ref.rgb, cv2.COLOR_RGB2GRAY)
        shift = ring_shift(ring, ref_grey, valid, np.linalg.inv(rel), K, align_px)
    sub, ok = sample_reference(ref.rgb, valid, target_yx, z, rel, K, shift)
    return np.where(ok[:, None], sub, nearest)


def _smooth_fill(out_rgb: np.ndarray, hole: np.ndarray, fy: np.ndarray, fx: np.ndarray, method: str) -> None:
    """Fill pixels (`fy`, `fx`) (M,) of `out_rgb` (H, W, 3) uint8 in place from the colours around them:
    "telea" (OpenCV's fast marching) or "harmonic" (Laplace's equation with the border fixed)."""
    if method == "telea":
        # on the fill's bounding box (+ the inpainting radius): the same result without whole-image passes
        h, w = hole.shape
        y0, y1 = max(int(fy.min()) - 4, 0), min(int(fy.max()) + 5, h)
        x0, x1 = max(int(fx.min()) - 4, 0), min(int(fx.max()) + 5, w)
        box = np.zeros((y1 - y0, x1 - x0), np.uint8)
        box[fy - y0, fx - x0] = 1
        out_rgb[y0:y1, x0:x1] = cv2.inpaint(np.ascontiguousarray(out_rgb[y0:y1, x0:x1]), box, 3, cv2.INPAINT_TELEA)
        return
    fill = np.zeros_like(hole)
    fill[fy, fx] = True

    def colours(rows: slice, cols: slice) -> tuple[np.ndarray, np.ndarray]:
        patch = out_rgb[rows, cols].astype(np.float32)
        return patch, np.ones(patch.shape[:2], bool)  # every colour outside `fill` is known

    col = harmonic_fill(fill, colours, (fy, fx))
    out_rgb[fy, fx] = np.clip(col + 0.5, 0, 255).astype(np.uint8)


def _patchmatch_fill(out_rgb: np.ndarray, hole: np.ndarray, pix: _HolePixels, search: np.ndarray,
                     sources: list[np.ndarray], valid: list[np.ndarray], warps: _Warps, config: PatchMatchConfig,
                     matches: _Matches) -> np.ndarray:
    """`out_rgb` (H, W, 3) uint8 with the hole pixels `search` (N,) bool filled by PatchMatch from `sources`
    (starting from geometry's matches); their matches are recorded in `matches`."""
    # PatchMatch visits only the pixels it must fill, so its cost scales with them, not the image.
    pm_hole = np.zeros_like(hole)
    pm_hole[pix.py[search], pix.px[search]] = True
    res = patchmatch_fill(out_rgb, pm_hole, np.stack(sources), np.stack(valid), warps.init_src[search],
                          warps.init_yx[search], config)
    matches.src[search], matches.yx[search], matches.cost[search] = res.source, res.yx, res.cost
    return res.rgb


def _match_depths(refs: list[ReferenceView], K: np.ndarray, warps: _Warps, matches: _Matches, todo: np.ndarray,
                  d: np.ndarray) -> None:
    """Depth in the target (into `d` (N,) float32) of the hole pixels `todo` (N,) bool matched to a reference
    pixel; those matched to the target itself keep 0."""
    for s, ref in enumerate(refs):
        m = todo & (matches.src == s)
        if m.any():
            d[m] = depth_in_target(ref.depth, matches.yx[m], warps.rel[s], K)


def _restored_depth(depth: np.ndarray, hole: np.ndarray, pix: _HolePixels, d: np.ndarray, matches: _Matches,
                    geo: np.ndarray, config: RestorationConfig) -> tuple[np.ndarray, np.ndarray]:
    """The depth (H, W) float32 m with the hole's depths `d` (N,) where their match is good enough (and from
    geometry unless `searched_depth`), the rest continued from the border (`unseen_depth`) or left 0; and its
    confidence (H, W) float32 in [0, 1]. `geo` (N,) bool: pixels geometry matched."""
    py, px = pix.py, pix.px
    conf = np.exp(-matches.cost / config.max_depth_cost).astype(np.float32)
    ok = (matches.cost <= config.max_depth_cost) & (d > 0) & (geo | config.searched_depth)
    out_depth = depth.copy()
    out_depth[py, px] = np.where(ok, d, 0.0)
    confidence = np.zeros(hole.shape, np.float32)
    confidence[py, px] = np.where(ok, conf, 0.0)
    if config.unseen_depth == "border" and not ok.all():
        gy, gx = py[~ok], px[~ok]  # row-major, as np.nonzero(guess) gives them
        guess = np.zeros_like(hole)
        guess[gy, gx] = True
        z = fill_depth_from_border(out_depth, guess, (gy, gx))
        out_depth[gy, gx] = z
        confidence[gy, gx] = np.where(z > 0, np.float32(config.border_depth_confidence), 0.0)
    return out_depth, confidence


@njit(cache=True, nogil=True)
def _landings(landed, ry, rx, n_acc, limit):
    """Indices (K,) of the hole pixels (ry, rx) (N,) that a reference lands on in `landed` (h, w, 2) and that
    have fewer than `limit` colours so far (`n_acc` (N,)), with the reference pixel (K, 2) of each."""
    idx = np.empty(len(ry), np.int64)
    yx = np.empty((len(ry), 2), np.int64)
    k = 0
    for i in range(len(ry)):
        y = landed[ry[i], rx[i], 0]
        if y >= 0 and n_acc[i] < limit:
            idx[k] = i
            yx[k, 0], yx[k, 1] = y, landed[ry[i], rx[i], 1]
            k += 1
    return idx[:k], yx[:k]


@njit(cache=True, nogil=True)
def _agreeing(sel, z, z_acc, n_acc, tol):
    """bool (K,): hole pixels `sel` (K,) with no colour yet, or whose depth `z` (K,) through this reference is
    within `tol` (relative) of the depth averaged so far (`z_acc` / `n_acc`, (N,))."""
    out = np.empty(len(sel), np.bool_)
    for k in range(len(sel)):
        n = n_acc[sel[k]]
        out[k] = n == 0 or abs(z[k] - z_acc[sel[k]] / n) <= tol * z[k]
    return out


@njit(cache=True, nogil=True)
def _accumulate(acc, z_acc, n_acc, sel, col, gain, z):
    """Add colours `col` (K, 3) x `gain` (3,) and depths `z` (K,) to the sums of hole pixels `sel` (K,)."""
    for k in range(len(sel)):
        i = sel[k]
        for c in range(3):
            acc[i, c] += col[k, c] * gain[c]
        z_acc[i] += z[k]
        n_acc[i] += 1
