"""Loop closure: find a revisit among old keyframes, verify it geometrically, correct with a pose graph.

Detection: bag-of-words similarity (`PlaceRecognizer`) above the lowest similarity of the query to its own
covisible keyframes (ORB-SLAM2's adaptive threshold), candidates at least `min_keyframe_gap` keyframes old.
Verification: descriptor matches to the candidate's map points, PnP-RANSAC, then motion-only BA (with depth).
Correction: keyframe pose graph (consecutive + strong covisibility + all loop edges), points moved with their
creating keyframe, and the loop's matched points fused (the query keeps the old point, the duplicate dies).
"""
from __future__ import annotations

import numpy as np

from worker.slam.config import LoopConfig
from worker.slam.features.matching import match_ratio
from worker.slam.geometry.pnp import pnp_ransac
from worker.slam.geometry.pose_optimizer import optimize_pose
from worker.slam.geometry.se3 import inv, orthonormalize, pose_distance
from worker.slam.map.keyframe import KeyFrame
from worker.slam.map.map import Map
from worker.slam.mapping.place_recognition import PlaceRecognizer
from worker.slam.mapping.pose_graph import optimize_pose_graph
from worker.slam.sensor import SensorModel

STRONG_COVIS = 100
MAX_CANDIDATES = 3


class LoopCloser:
    def __init__(self, slam_map: Map, cfg: LoopConfig, sensor: SensorModel) -> None:
        self.map, self.cfg, self.K, self.bf = slam_map, cfg, sensor.K, sensor.bf
        self.inv_sigma2 = sensor.inv_sigma2
        self.places = PlaceRecognizer(cfg.descriptors_per_keyframe)
        self.loop_edges: list[tuple[int, int, np.ndarray, float]] = []
        self.n_loops = 0
        self.n_applied = 0
        self.last_kf_with_loop = -10**9

    def process(self, kf: KeyFrame) -> bool:
        """Register `kf`; if it closes a loop, correct the map. True when a loop was found."""
        self.places.add(kf.feats.desc, kf.feats.response)
        if kf.id - self.last_kf_with_loop < 5:  # let the map settle after a correction
            return False
        for cand in self.candidates(kf):
            found = self.verify(kf, cand)
            if found is None:
                continue
            T_loop, q, old_pids = found
            self.n_loops += 1
            self.last_kf_with_loop = kf.id
            self.correct(kf, cand, T_loop, q, old_pids)
            return True
        return False

    def candidates(self, kf: KeyFrame) -> list[int]:
        scores = self.places.scores(kf.id)
        if not scores.any() or kf.id < self.cfg.min_keyframe_gap:
            return []
        neigh = self.map.best_covisible(kf.id, 10)
        min_score = min((scores[j] for j in neigh if j < len(scores)), default=0.0)
        old = np.arange(0, kf.id - self.cfg.min_keyframe_gap + 1)
        near = set(neigh)
        old = np.array([j for j in old if j not in near], int)
        if len(old) == 0:
            return []
        good = old[scores[old] >= max(min_score, 0.05)]
        return [int(j) for j in good[np.argsort(-scores[good])][:MAX_CANDIDATES]]

    def verify(self, kf: KeyFrame, cand_id: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(T_WC of `kf` in the candidate's map, query keypoint indices, matched old point ids) or None."""
        cand = self.map.keyframes[cand_id]
        pts = self.map.points
        has = cand.point_ids >= 0
        has[has] = pts.alive[cand.point_ids[has]]
        idx = np.flatnonzero(has)
        q, t = match_ratio(kf.feats.desc, cand.feats.desc[idx], ratio=0.8, max_dist=70)
        if len(q) < self.cfg.min_matches:
            return None
        old_pids = cand.point_ids[idx[t]]
        X = pts.pos[old_pids]
        res = pnp_ransac(X, kf.feats.uv[q], self.K, reproj_px=4.0, iterations=300)
        if res is None or res[1].sum() < self.cfg.min_inliers:
            return None
        q, old_pids, X = q[res[1]], old_pids[res[1]], X[res[1]]
        est = optimize_pose(res[0], X, kf.feats.uv[q], kf.feats.depth[q], self.inv_sigma2[kf.feats.octave[q]],
                            self.K, self.bf)
        if est.n_inliers < self.cfg.min_inliers:
            return None
        return est.T_WC, q[est.inliers], old_pids[est.inliers]

    def correct(self, kf: KeyFrame, cand_id: int, T_loop: np.ndarray, q: np.ndarray, old_pids: np.ndarray) -> None:
        kfs = self.map.keyframes
        dt, dr = pose_distance(kf.T_WC, T_loop)
        old_poses = self.map.poses()
        Z = inv(kfs[cand_id].T_WC) @ T_loop
        self.loop_edges.append((cand_id, kf.id, Z, 10.0))
        if dt >= self.cfg.min_correction_m or np.degrees(dr) >= 1.0:
            edges = [(i, i + 1, inv(old_poses[i]) @ old_poses[i + 1], 1.0) for i in range(len(kfs) - 1)]
            for i, nb in self.map.covis.items():
                for j, w in nb.items():
                    if i < j - 1 and w >= STRONG_COVIS:
                        edges.append((i, j, inv(old_poses[i]) @ old_poses[j], 1.0))
            edges += self.loop_edges
            new_poses = orthonormalize(optimize_pose_graph(old_poses, edges, fixed=0))
            corr = new_poses @ inv(old_poses)  # per keyframe world correction
            for k, T in zip(kfs, new_poses):
                k.T_WC = T
            p = self.map.points
            n = p.n
            C = corr[p.first_kf[:n]]
            p.pos[:n] = np.einsum("nij,nj->ni", C[:, :3, :3], p.pos[:n]) + C[:, :3, 3]
            p.normal[:n] = np.einsum("nij,nj->ni", C[:, :3, :3], p.normal[:n])
            self.n_applied += 1
        self._fuse(kf, q, old_pids)
        self.map.update_covisibility(kf.id)

    def _fuse(self, kf: KeyFrame, q: np.ndarray, old_pids: np.ndarray) -> None:
        """The query keyframe observes the old points from now on; its duplicates are removed."""
        p = self.map.points
        dup = kf.point_ids[q]
        replace = (dup >= 0) & (dup != old_pids)
        p.kill(dup[replace])
        kf.point_ids[q] = old_pids
        p.n_obs[old_pids] += 1
