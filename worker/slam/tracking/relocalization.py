"""Relocalisation: candidate keyframes, then descriptor matches to their map points, PnP-RANSAC, motion-only BA.

Candidates come first from the vocabulary (ORB-SLAM2's KeyFrameDatabase::DetectRelocalizationCandidates):
keyframes sharing at least 80 % of the best one's common words, their scores accumulated over their covisible
neighbours, the groups within 75 % of the best, best first. The recent keyframes, the reference keyframe's
covisible ones and every 5th older keyframe follow, so a frame the vocabulary ranks badly is still tried.
"""
from __future__ import annotations

import numpy as np

from worker.slam.features.bow_database import KeyframeDatabase
from worker.slam.features.matching import match_ratio
from worker.slam.features.types import Features
from worker.slam.geometry.pnp import pnp_ransac
from worker.slam.map.map import Map


def vocabulary_candidates(slam_map: Map, db: KeyframeDatabase, desc: np.ndarray) -> list[int]:
    """Keyframes whose covisibility group looks most like a frame with (N,32) uint8 descriptors `desc`."""
    db.extend(kf.feats.desc for kf in slam_map.keyframes[len(db):])
    scores, common = db.query(db.transform(desc)[0])
    if not len(common) or common.max() == 0:
        return []
    sel = common > 0.8 * common.max()
    groups: dict[int, float] = {}
    for c in np.flatnonzero(sel):
        members = [int(c)] + [j for j in slam_map.best_covisible(int(c), 10) if sel[j]]
        acc = float(scores[members].sum())
        best = max(members, key=lambda j: scores[j])
        groups[best] = max(groups.get(best, 0.0), acc)
    if not groups:
        return []
    top = max(groups.values())
    return [j for j, a in sorted(groups.items(), key=lambda x: -x[1]) if a >= 0.75 * top]


def relocalisation_candidates(slam_map: Map, n_recent: int, around: int | None,
                              db: KeyframeDatabase | None = None, desc: np.ndarray | None = None) -> list[int]:
    """The vocabulary's candidates for `desc` (with `db`), then recent keyframes, the reference keyframe's
    covisible ones, then every 5th older keyframe."""
    n = len(slam_map)
    ids = vocabulary_candidates(slam_map, db, desc) if db is not None and desc is not None else []
    ids += list(range(n - 1, max(-1, n - 1 - n_recent), -1))
    if around is not None:
        ids += [around] + slam_map.best_covisible(around, n_recent)
    ids += list(range(n - 1 - n_recent, -1, -5))
    seen, out = set(), []
    for i in ids:
        if 0 <= i < n and i not in seen:
            seen.add(i)
            out.append(i)
    return out


def older_map_candidates(before: int, n_recent: int) -> list[int]:
    """Keyframes of the maps before keyframe `before`: the newest `n_recent`, then every 5th older one."""
    return list(range(before - 1, max(-1, before - 1 - n_recent), -1)) + list(range(before - 1 - n_recent, -1, -5))


def pnp_against_keyframe(slam_map: Map, kf_id: int, feats: Features, K: np.ndarray,
                         min_inliers: int) -> tuple[np.ndarray, int] | None:
    """(T_WC, inliers) of a frame from its descriptor matches to keyframe `kf_id`'s map points, or None."""
    kf = slam_map.keyframes[kf_id]
    pid = kf.point_ids
    has = pid >= 0
    has[has] = slam_map.points.alive[pid[has]]
    if has.sum() < min_inliers or len(feats) < min_inliers:
        return None
    q, t = match_ratio(feats.desc, kf.feats.desc[has], ratio=0.75, max_dist=70)
    if len(q) < min_inliers:
        return None
    X = slam_map.points.pos[pid[has][t]]
    res = pnp_ransac(X, feats.uv[q], K, reproj_px=4.0, iterations=300)
    if res is None or res[1].sum() < min_inliers:
        return None
    return res[0], int(res[1].sum())
