"""Which previous keypoint each current keypoint of a frame pair is: guided by the predicted pose where the
tracker confirms it, brute force on the objects and where it does not."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.slam.dynamic.culling_config import CullingConfig
from worker.slam.dynamic.epipolar import Matches, match_guided, match_orb, predict_positions
from worker.slam.dynamic.pair import FramePair, nearest_pixel
from worker.slam.features.matching import hamming
from worker.slam.features.search import KeypointIndex


@dataclass(frozen=True)
class FrameMatches(Matches):
    guided: bool = False
    pred: np.ndarray | None = None
    """(N_prev, 2) px: every previous keypoint where the predicted pose puts it (guided matching only)."""


@dataclass(frozen=True)
class MatchedPoints:
    """The matches of a frame pair as points, one row per match: `prev` / `cur` (N, 2) float64 px (x, y) in the
    previous / current frame; `xi`, `yi` (N,) int the current point's nearest pixel (column, row)."""

    prev: np.ndarray
    cur: np.ndarray
    xi: np.ndarray
    yi: np.ndarray

    @classmethod
    def of(cls, pair: FramePair, m: Matches) -> MatchedPoints:
        h, w = pair.shape
        p_prev, p_cur = pair.prev_uv[m.prev_idx].astype(np.float64), pair.cur_uv[m.cur_idx].astype(np.float64)
        return cls(p_prev, p_cur, nearest_pixel(p_cur[:, 0], w), nearest_pixel(p_cur[:, 1], h))

    def __len__(self) -> int:
        return len(self.prev)

    def labels_at(self, labels: np.ndarray) -> np.ndarray:
        """`labels` (H, W) at each match's current point, (N,)."""
        return labels[self.yi, self.xi]


def _near_box(pred: np.ndarray, pts: np.ndarray, margin: float) -> np.ndarray:
    """Indices of predicted positions (N,2) within `margin` px of the bounding box of `pts` (M,2)."""
    if len(pts) == 0:
        return np.zeros(0, int)
    lo, hi = pts.min(0) - margin, pts.max(0) + margin
    with np.errstate(invalid="ignore"):
        return np.flatnonzero(((pred >= lo) & (pred <= hi)).all(1))


def match_frames(pair: FramePair, on_object: np.ndarray | None, config: CullingConfig) -> FrameMatches:
    """Guided matching when a relative pose is predicted and enough guided matches are found, else brute force.

    With segments (`on_object` (M,) bool), the current keypoints on objects are brute-forced against the
    previous keypoints predicted near them (giving way to a nearly as good guided match, `prefer_static_within`)
    and the rest are guided. Without (`on_object` None, geometry-only) everything is guided first, then what is
    left on both sides is brute-forced: the moving points a search radius misses are exactly what the geometric
    path looks for."""
    kp_prev, desc_prev, kp_cur, desc_cur = pair.prev_uv, pair.prev_desc, pair.cur_uv, pair.cur_desc
    guided = np.flatnonzero(~on_object) if on_object is not None else np.arange(len(kp_cur))
    T_cur_prev, K = pair.T_cur_prev, pair.K
    if T_cur_prev is not None and K is not None and pair.prev_depth is not None and len(kp_prev) and len(kp_cur):
        z = pair.prev_depth_at(kp_prev)
        uv_prev = kp_prev.astype(np.float64)
        pred = predict_positions(uv_prev, z, T_cur_prev, K)  # (N, 2) px, once for every search below

        def search(cur: np.ndarray, prev: np.ndarray | None = None) -> Matches:
            """Guided matches of the current keypoints `cur` among the previous ones `prev` (None = all)."""
            sel = np.s_[:] if prev is None else prev  # all: views, no copies
            index = KeypointIndex.of_points(kp_cur[cur], desc_cur[cur], grid=True)
            m = match_guided(uv_prev[sel], z[sel], desc_prev[sel], index,
                             T_cur_prev, K, config.guided_radius_px, config.match_max_distance, pred=pred[sel])
            return m if prev is None else Matches(prev[m.prev_idx], m.cur_idx)

        g = search(guided)
        confirmed = len(g.prev_idx) >= config.guided_min_matches
        if not confirmed and on_object is not None and config.confirm_on_objects:
            # Segments covering most of the view leave too few keypoints outside them to confirm the
            # prediction; the static scene under a wrong mask confirms it as well as the scene outside.
            confirmed = len(search(np.arange(len(kp_cur))).prev_idx) >= config.guided_min_matches
        if confirmed:
            g_cur = guided[g.cur_idx]
            if on_object is not None:
                rest_cur = np.flatnonzero(on_object)
                rest_prev = _near_box(pred, kp_cur[rest_cur], config.object_margin_px)
            else:
                rest_cur = np.setdiff1d(np.arange(len(kp_cur)), g_cur)
                rest_prev = np.setdiff1d(np.arange(len(kp_prev)), g.prev_idx)
            b = match_orb(desc_prev[rest_prev], desc_cur[rest_cur], config.match_max_distance)
            b_prev, b_cur = rest_prev[b.prev_idx], rest_cur[b.cur_idx]
            if on_object is not None and config.prefer_static_within >= 0 and len(b_cur):
                # only previous keypoints that can land within the search radius (doubled without depth)
                reach = _near_box(pred, kp_cur[b_cur], 2 * config.guided_radius_px)
                b_prev, b_cur = prefer_static(b_prev, b_cur, search(b_cur, reach), desc_prev, desc_cur,
                                              config.prefer_static_within)
            free = ~np.isin(b_prev, g.prev_idx)  # a previous keypoint matched twice keeps its guided match
            return FrameMatches(np.concatenate([g.prev_idx, b_prev[free]]),
                                np.concatenate([g_cur, b_cur[free]]), True, pred)
    m = match_orb(desc_prev, desc_cur, config.match_max_distance)
    return FrameMatches(m.prev_idx, m.cur_idx, False)


def prefer_static(b_prev: np.ndarray, b_cur: np.ndarray, near: Matches, desc_prev: np.ndarray,
                  desc_cur: np.ndarray, within: int) -> tuple[np.ndarray, np.ndarray]:
    """Brute-force matches (b_prev, b_cur) (K,) with a current keypoint's previous one replaced by its guided
    match (`near`: indices into `b_cur` and into the previous keypoints) where that one's Hamming distance
    exceeds the brute-force one's by at most `within` (see `prefer_static_within`). A previous keypoint
    claimed twice stays with the first of its current keypoints."""
    pos = near.cur_idx
    d_brute = hamming(desc_prev[b_prev[pos]], desc_cur[b_cur[pos]])
    d_near = hamming(desc_prev[near.prev_idx], desc_cur[b_cur[pos]])
    swap = d_near <= d_brute + within
    b_prev = b_prev.copy()
    b_prev[pos[swap]] = near.prev_idx[swap]
    first = np.sort(np.unique(b_prev, return_index=True)[1])
    return b_prev[first], b_cur[first]
