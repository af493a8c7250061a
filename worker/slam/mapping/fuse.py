"""Map-point fusion between a new keyframe and its covisible neighbours (ORB-SLAM2's SearchInNeighbors).

Every keyframe creates points for the keypoints tracking did not match, so one surface point often gets
several map points, one per keyframe that saw it, each observed once: local BA then has nothing tying those
keyframes together, covisibility stays weak and the keyframe rule's count of well-observed points stays low.
Fusion projects the new keyframe's points into its neighbours and theirs into it: a keypoint with no point
gains the observation. ORB-SLAM2 also merges two points that land on one keypoint (the one more keyframes
observe stays); here that is `merge`, off: on static 7-Scenes merging cost accuracy while adding observations
alone helped. Fusion itself is off by default (`mapping.fuse_neighbours`;
docs/results/settings.md#mapping-fuse_neighbours).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.slam.features.projection import search_by_projection
from worker.slam.features.search import KeypointIndex
from worker.slam.geometry import reprojection as rp
from worker.slam.geometry.pose_optimizer import CHI2_MONO, CHI2_STEREO
from worker.slam.geometry.se3 import inv, transform
from worker.slam.map.keyframe import KeyFrame
from worker.slam.map.map import Map

MAX_HAMMING = 50
"""ORB-SLAM2's TH_LOW: fusion needs a closer descriptor than tracking, a wrong merge lasts."""


@dataclass(frozen=True)
class FuseGeometry:
    """What projecting into a keyframe needs: `K` (3,3), image `size` (width, height), pyramid `scales`
    (levels,), `inv_sigma2` (levels,) per octave, `bf` (fx x virtual baseline, pixels x metres)."""

    K: np.ndarray
    size: tuple[int, int]
    scales: np.ndarray
    inv_sigma2: np.ndarray
    bf: float


def _reprojection_ok(X_w: np.ndarray, kf: KeyFrame, kp: np.ndarray, g: FuseGeometry) -> np.ndarray:
    """(M,) bool: world points X_w (M,3) reproject onto keypoints `kp` of `kf` within the chi-square bound;
    keypoints with depth are also checked in the virtual right image (depth agreement), as in motion-only BA."""
    Pc = transform(inv(kf.T_WC), X_w)
    front = Pc[:, 2] > 0
    Pc[~front, 2] = 1.0  # behind the camera: rejected below, kept finite here
    obs, has = rp.observations(kf.feats.uv[kp], kf.feats.depth[kp], g.bf)
    e2 = ((rp.project(Pc, g.K, g.bf) - obs) ** 2 * rp.residual_weights(has)).sum(1)
    return front & (e2 * g.inv_sigma2[kf.feats.octave[kp]] < np.where(has, CHI2_STEREO, CHI2_MONO))


def fuse_into(slam_map: Map, kf: KeyFrame, ids: np.ndarray, g: FuseGeometry, radius_px: float,
              remap: np.ndarray, merge: bool) -> int:
    """Project alive points `ids` into `kf`; record observations and, with `merge`, merges. Merges go into
    `remap` (point id -> the id it is merged into, identity elsewhere) and are applied by `apply_merges`.
    Returns the observations added and merges recorded."""
    p = slam_map.points
    ids = np.unique(remap[ids])
    ids = ids[p.alive[ids]]
    ids = ids[~np.isin(ids, remap[kf.point_ids[kf.point_ids >= 0]])]
    if not len(ids) or not len(kf.feats):
        return 0
    m = search_by_projection(KeypointIndex(kf.feats), p.pos[ids], p.desc[ids], p.normal[ids], p.max_dist[ids],
                             kf.T_WC, g.K, g.size, g.scales, radius_px, MAX_HAMMING, 1.0)
    ok = _reprojection_ok(p.pos[ids[m.point_idx]], kf, m.kp_idx, g)
    used = 0
    for pid, k in zip(ids[m.point_idx[ok]], m.kp_idx[ok]):
        pid = _root(remap, int(pid))
        q = int(kf.point_ids[k])
        q = _root(remap, q) if q >= 0 else q
        if q < 0 or not p.alive[q]:
            kf.point_ids[k] = pid
            p.n_obs[pid] += 1
        elif q != pid and merge:
            keep, drop = (pid, q) if p.n_obs[pid] >= p.n_obs[q] else (q, pid)
            remap[drop] = keep
        else:
            continue
        used += 1
    return used


def _root(remap: np.ndarray, i: int) -> int:
    while remap[i] != i:
        i = int(remap[i])
    return i


def apply_merges(slam_map: Map, remap: np.ndarray) -> int:
    """Replace every merged point by the one it merged into, in every keyframe (a keyframe that then sees one
    point twice keeps the first keypoint); recount the kept points' observations. Returns points merged."""
    dropped = np.flatnonzero(remap != np.arange(len(remap)))
    if not len(dropped):
        return 0
    for i in dropped:  # resolve chains a -> b -> c
        remap[i] = _root(remap, int(i))
    p = slam_map.points
    counts = np.zeros(len(remap), np.int32)
    for kf in slam_map.keyframes:
        pid = kf.point_ids
        sel = np.flatnonzero(pid >= 0)
        pid[sel] = remap[pid[sel]]
        ids, first = np.unique(pid[sel], return_index=True)
        repeat = np.ones(len(sel), bool)
        repeat[first] = False
        pid[sel[repeat]] = -1
        counts[ids] += 1
    np.add.at(p.visible, remap[dropped], p.visible[dropped])
    np.add.at(p.found, remap[dropped], p.found[dropped])
    p.kill(dropped)
    kept = np.unique(remap[dropped])
    p.n_obs[kept] = counts[kept]
    return len(dropped)


def fuse_neighbours(slam_map: Map, kf: KeyFrame, neighbours: int, g: FuseGeometry, radius_px: float,
                    merge: bool = False) -> int:
    """Fuse `kf`'s points into its `neighbours` best covisible keyframes (and their best 5 each, as ORB-SLAM2)
    and theirs into `kf`; update covisibility. Returns the observations added and points merged."""
    first = slam_map.best_covisible(kf.id, neighbours)
    targets = list(first)
    for j in first:
        targets += [i for i in slam_map.best_covisible(j, 5) if i != kf.id and i not in targets]
    if not targets:
        return 0
    remap = np.arange(len(slam_map.points))
    mine = kf.point_ids[kf.point_ids >= 0]
    n = sum(fuse_into(slam_map, slam_map.keyframes[j], mine, g, radius_px, remap, merge) for j in targets)
    theirs = np.concatenate([slam_map.keyframes[j].point_ids for j in targets])
    n += fuse_into(slam_map, kf, theirs[theirs >= 0], g, radius_px, remap, merge)
    apply_merges(slam_map, remap)
    for i in [kf.id] + first:  # ORB-SLAM2 updates the new keyframe's; its neighbours' gained most besides
        slam_map.update_covisibility(i)
    return n
