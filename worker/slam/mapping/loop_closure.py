"""Loop closure as ORB-SLAM2's LoopClosing, with SE(3) instead of Sim(3) (RGB-D: depth fixes the scale).

Detection: `place_recognition.LoopDetector` (vocabulary scores, covisibility groups, consistency over
consecutive keyframes). Verification, per consistent candidate: descriptor matches under the same vocabulary
node (the direct index) to the candidate's map points, PnP-RANSAC, motion-only BA with depth, then the points
of the candidate and its connected keyframes projected into the query for more matches and a second BA;
the loop holds when enough of them are inliers. Correction: the query and its connected keyframes are moved
with the loop's correction, the essential graph (spanning tree, strong covisibility, every loop edge and the
new loop links) is optimised with the loop keyframe held, points follow the keyframe that created them, and
the loop side's points are fused into the query side (duplicates merged).
"""
from __future__ import annotations

import logging

import numpy as np

from worker.slam.config import LoopConfig
from worker.slam.features.bow_database import KeyframeDatabase
from worker.slam.features.projection import search_by_projection
from worker.slam.features.search import KeypointIndex
from worker.slam.features.vocabulary import Vocabulary
from worker.slam.geometry.pnp import pnp_ransac
from worker.slam.geometry.pose_optimizer import PoseEstimate, optimize_pose
from worker.slam.geometry.se3 import inv, orthonormalize, pose_distance
from worker.slam.map.keyframe import KeyFrame
from worker.slam.map.map import Map
from worker.slam.mapping.essential_graph import Edge, essential_edges
from worker.slam.mapping.fuse import FuseGeometry, apply_merges, fuse_into
from worker.slam.mapping.place_recognition import LoopDetector, connected, sync_database
from worker.slam.mapping.pose_graph import optimize_pose_graph
from worker.slam.sensor import SensorModel

log = logging.getLogger(__name__)

STRONG_COVIS = 100
"""ORB-SLAM2's essential graph keeps covisibility edges of at least 100 shared points."""
LOOP_WEIGHT = 10.0
"""Weight of a loop edge against an odometry edge: a verified loop is measured in one shot, not chained."""
SETTLE_KEYFRAMES = 10
"""No detection for this many keyframes after a loop (ORB-SLAM2's mLastLoopKFid + 10)."""
PROJECTION_RADIUS_PX = 10.0
MAX_HAMMING = 50


class LoopCloser:
    def __init__(self, slam_map: Map, cfg: LoopConfig, sensor: SensorModel,
                 db: KeyframeDatabase | None = None) -> None:
        """`db`: the keyframe database shared with relocalisation (default: a new one on the shipped
        vocabulary)."""
        self.map, self.cfg, self.K, self.bf = slam_map, cfg, sensor.K, sensor.bf
        self.inv_sigma2 = sensor.inv_sigma2
        self.geometry = FuseGeometry(sensor.K, sensor.size, sensor.sigmas, sensor.inv_sigma2, sensor.bf)
        self.db = db if db is not None else KeyframeDatabase(Vocabulary.load())
        self.detector = LoopDetector(slam_map, self.db, cfg.min_keyframe_gap, cfg.consistency)
        self.loop_edges: list[Edge] = []
        self.n_candidates = 0  # consistent candidates that went to geometric verification
        self.n_loops = 0  # verified loops
        self.n_applied = 0  # loops whose correction moved the map
        self.last_kf_with_loop = -10**9

    def process(self, kf: KeyFrame) -> bool:
        """Register `kf`; if it closes a loop, correct the map. True when a loop was found."""
        sync_database(self.db, self.map)
        if kf.id - self.last_kf_with_loop < SETTLE_KEYFRAMES:  # let the map settle after a correction
            return False
        for cand in self.detector.detect(kf.id):
            self.n_candidates += 1
            found = self.verify(kf, cand)
            if found is None:
                continue
            T_loop, q, old_pids = found
            self.n_loops += 1
            self.last_kf_with_loop = kf.id
            applied = self.correct(kf, cand, T_loop, q, old_pids)
            log.info("loop: keyframe %d closes on %d with %d inliers%s", kf.id, cand, len(q),
                     "" if applied else " (correction below min_correction_m: not applied)")
            self.detector.reset()
            return True
        return False

    def _points_of(self, kf_ids: list[int]) -> np.ndarray:
        ids = np.concatenate([self.map.keyframes[j].point_ids for j in kf_ids])
        ids = np.unique(ids[ids >= 0])
        return ids[self.map.points.alive[ids]]

    def _refine(self, kf: KeyFrame, T: np.ndarray, q: np.ndarray, pids: np.ndarray) -> PoseEstimate:
        """Motion-only BA of `kf` (with depth) on keypoints `q` matched to points `pids`, from pose `T`."""
        f, X = kf.feats, self.map.points.pos[pids]
        return optimize_pose(T, X, f.uv[q], f.depth[q], self.inv_sigma2[f.octave[q]], self.K, self.bf)

    def verify(self, kf: KeyFrame, cand_id: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(T_WC of `kf` in the candidate's map, query keypoint indices, matched old point ids) or None."""
        cand, pts = self.map.keyframes[cand_id], self.map.points
        has = cand.point_ids >= 0
        has[has] = pts.alive[cand.point_ids[has]]
        q, t = self.db.match(kf.id, kf.feats.desc, cand_id, cand.feats.desc, ratio=0.75, max_dist=MAX_HAMMING,
                             candidates_b=has)
        if len(q) < self.cfg.min_matches:
            return None
        pids = cand.point_ids[t]
        res = pnp_ransac(pts.pos[pids], kf.feats.uv[q], self.K, reproj_px=4.0, iterations=300)
        if res is None or res[1].sum() < self.cfg.min_matches:
            return None
        est = self._refine(kf, res[0], q[res[1]], pids[res[1]])
        if est.n_inliers < self.cfg.min_matches:
            return None
        # more matches: the loop side's points projected into the query (ORB-SLAM2's SearchByProjection)
        loop_pts = self._points_of([cand_id] + connected(self.map, cand_id))
        taken = np.zeros(len(kf.feats), bool)
        taken[q[res[1]][est.inliers]] = True
        m = search_by_projection(KeypointIndex(kf.feats), pts.pos[loop_pts], pts.desc[loop_pts],
                                 pts.normal[loop_pts], pts.max_dist[loop_pts], est.T_WC, self.K,
                                 self.geometry.size, self.geometry.scales, PROJECTION_RADIUS_PX, MAX_HAMMING,
                                 0.8, taken=taken)
        q_all = np.r_[q[res[1]][est.inliers], m.kp_idx]
        p_all = np.r_[pids[res[1]][est.inliers], loop_pts[m.point_idx]]
        est = self._refine(kf, est.T_WC, q_all, p_all)
        if est.n_inliers < self.cfg.min_inliers:
            return None
        return est.T_WC, q_all[est.inliers], p_all[est.inliers]

    def correct(self, kf: KeyFrame, cand_id: int, T_loop: np.ndarray, q: np.ndarray, old_pids: np.ndarray) -> bool:
        """Correct the map for the loop `kf` -> `cand_id`; True when the poses moved."""
        kfs = self.map.keyframes
        old = self.map.poses()
        side = [kf.id] + [j for j in connected(self.map, kf.id) if j != cand_id]
        init = old.copy()
        init[side] = T_loop @ inv(old[kf.id]) @ old[side]  # the query side moves with the loop's correction
        self.loop_edges.append((cand_id, kf.id, inv(old[cand_id]) @ T_loop, LOOP_WEIGHT))
        dt, dr = pose_distance(kf.T_WC, T_loop)
        applied = dt >= self.cfg.min_correction_m or np.degrees(dr) >= 1.0
        if applied:
            links = [(cand_id, j, inv(old[cand_id]) @ init[j], 1.0) for j in side[1:]]  # new loop links
            edges = essential_edges(self.map, old, STRONG_COVIS) + self.loop_edges + links
            new = orthonormalize(optimize_pose_graph(init, edges, fixed=cand_id))
            corr = new @ inv(old)  # per keyframe world correction
            for k, T in zip(kfs, new):
                k.T_WC = T
            p = self.map.points
            n = p.n
            C = corr[p.first_kf[:n]]
            p.pos[:n] = np.einsum("nij,nj->ni", C[:, :3, :3], p.pos[:n]) + C[:, :3, 3]
            p.normal[:n] = np.einsum("nij,nj->ni", C[:, :3, :3], p.normal[:n])
            self.n_applied += 1
        self._fuse(kf, side, cand_id, q, old_pids)
        return applied

    def _fuse(self, kf: KeyFrame, side: list[int], cand_id: int, q: np.ndarray, old_pids: np.ndarray) -> None:
        """The query side observes the loop side's points from now on; duplicates merge into them."""
        p = self.map.points
        remap = np.arange(len(p))
        for k, pid in zip(q, old_pids):  # the verified matches first: the loop's point is kept
            dup = int(kf.point_ids[k])
            if dup >= 0 and dup != pid and p.alive[dup]:
                remap[dup] = pid
            elif dup < 0:
                kf.point_ids[k] = pid
                p.n_obs[pid] += 1
        loop_pts = self._points_of([cand_id] + connected(self.map, cand_id))
        for j in side:
            fuse_into(self.map, self.map.keyframes[j], loop_pts, self.geometry, 4.0, remap, merge=True)
        apply_merges(self.map, remap)
        for j in side + [cand_id]:
            self.map.update_covisibility(j)
