"""The RGB-D tracker: one call per frame, ORB-SLAM2 style.

Per frame: ORB features (the stages' culled ones, or extracted here minus an exclude mask; plus extra
features), depth per keypoint (restored depth when given), pose predicted by the constant-velocity model,
projection search against the local map (points of the keyframes covisible with the reference keyframe),
motion-only BA, a second finer search and BA; relocalisation against keyframes when that fails; keyframe
decision and creation of new map points from keyframe depth. Local BA, culling and loop closure run
afterwards on the keyframe it returns.

Maps start only on frames that give `init_min_points` new points. When a frame neither tracks nor
relocalises, `recovery.after_loss` decides: wait, or start a new map at the motion model's pose (a
constant-velocity bridge in the same world frame, so later frames keep consistent poses), discarding the lost
map's points first when it was young. Old maps' keyframes stay for relocalisation and loop closure. Each
keyframe of a new map tries to relocalise in the older maps; when one does, the new map is moved rigidly onto
the old one (merged) and tracking continues on both maps' points.
"""
from __future__ import annotations

import numpy as np

from worker.slam.config import FeatureConfig, TrackingConfig
from worker.slam.features.bow_database import KeyframeDatabase
from worker.slam.features.orb import OrbExtractor
from worker.slam.features.projection import search_by_projection
from worker.slam.features.search import KeypointIndex
from worker.slam.features.types import Features
from worker.slam.geometry.pose_optimizer import PoseEstimate, optimize_pose
from worker.slam.geometry.se3 import inv
from worker.slam.map.keyframe import KeyFrame
from worker.slam.map.map import Map
from worker.slam.sensor import SensorModel
from worker.slam.tracking.frame_view import FrameView, frame_view, undistorted
from worker.slam.tracking.inputs import TrackInputs
from worker.slam.tracking.keyframe_policy import KeyframeDecisionInput, need_keyframe
from worker.slam.tracking.motion import ConstantVelocityModel
from worker.slam.tracking.new_keyframe import add_keyframe
from worker.slam.tracking.recovery import LossAction, after_loss, can_start_map
from worker.slam.tracking.relocalization import older_map_candidates, pnp_against_keyframe, relocalisation_candidates
from worker.slam.tracking.result import TrackResult


class Tracker:
    """Tracks frames into `slam_map` (shared with local mapping and loop closure, which change it between
    frames) with the run's `sensor`; reads only the `tracking` and `features` settings, plus the two numbers
    of other sections it applies when it creates a keyframe (`mapping.new_point_max_depth_m`, `dense.stride`).
    """

    def __init__(self, sensor: SensorModel, slam_map: Map, tracking: TrackingConfig, features: FeatureConfig,
                 new_point_max_depth_m: float, image_stride: int) -> None:
        """`new_point_max_depth_m`: keypoints farther than this make no map points; `image_stride`: keyframes
        keep their images subsampled by it (for the dense map)."""
        self.sensor = sensor
        self.tc = tracking
        self.fc = features
        self.K = sensor.K
        self.new_point_max_depth_m = new_point_max_depth_m
        self.image_stride = image_stride
        self.extractor = OrbExtractor(features)
        self.map = slam_map
        self.motion = ConstantVelocityModel()
        self.ref_kf: int | None = None
        self.local_kfs: list[int] = []
        self.last_kf_frame = -1
        self.last_point_ids = np.zeros(0, np.int64)
        self.lost_streak = 0
        #: Frames whose final pose solve took the established points' pose (`established_frames`).
        self.established_switches = 0
        #: Frames tracked only with the keypoints culling held back (`rescue_with_held_back`).
        self.rescued_frames = 0
        #: Frames tracked from the last pose after the motion model failed (`retry_from_last_pose`).
        self.last_pose_retries = 0
        #: First keyframe id of every map not merged into an older one (maps after a loss continue the ids).
        self.map_starts = [0]
        #: The last successfully tracked frame's result (the pipeline hands its pose to the stages).
        self.last_result: TrackResult | None = None
        #: Keyframe database of the run's vocabulary, shared with loop closure (set by `run.parts`); relocalisation
        #: tries its candidates first.
        self.places: KeyframeDatabase | None = None

    # ---- public ------------------------------------------------------------------------------------------

    def predicted_pose(self) -> np.ndarray | None:
        """T_WC (4,4) the motion model expects for the next frame; None before the first tracked frame."""
        return self.motion.predict()

    def track(self, index: int, timestamp: float, rgb: np.ndarray, depth: np.ndarray,
              given: TrackInputs | None = None) -> TrackResult:
        """Track one frame. `rgb` RGB uint8 (H,W,3); `depth` float32 metres (H,W), 0 = invalid.

        `given`: what the per-frame stages found (features, exclude mask, restored images; see `TrackInputs`).
        """
        given = given if given is not None else TrackInputs()
        view = frame_view(rgb, depth, given, self.extractor, self.fc, self.sensor)
        if len(self.map) == 0:
            return self._initialise(index, timestamp, view, given.held_back)
        pred = self.motion.predict()
        assert pred is not None and self.ref_kf is not None, "the map's first keyframe set both"
        est, pids, feats, relocalised = self._estimate(pred, view.feats, given.held_back)
        if est is None:
            return self._lost(index, timestamp, pred, feats, view)
        self.lost_streak = 0
        if relocalised:
            self.motion.reset(est.T_WC)
            # back in an older map: the newer ones are left as they are (no transform to merge them by)
            self.map_starts = [s for s in self.map_starts if s <= self.ref_kf]
        else:
            self.motion.update(est.T_WC)
        res = TrackResult(index, timestamp, est.T_WC, True, relocalised, feats, pids, est.covariance,
                          self.ref_kf)
        if relocalised or self._need_keyframe(res):
            res.keyframe = self._insert_keyframe(res, view)
            res.ref_kf = res.keyframe.id
        if len(self.map_starts) > 1:
            res.merged = self._merge_into_older_map(res)
        self.last_point_ids = pids[pids >= 0]
        self.last_result = res
        return res

    def on_map_updated(self, res: TrackResult) -> None:
        """After local BA / loop closure moved keyframes: re-anchor the motion model's last pose."""
        if res.keyframe is not None and self.motion.last is not None:
            self.motion.last = res.keyframe.T_WC.copy()

    # ---- steps -------------------------------------------------------------------------------------------

    def _estimate(self, pred: np.ndarray, feats: Features, held_back: Features | None
                  ) -> tuple[PoseEstimate | None, np.ndarray, Features, bool]:
        """The frame's pose from the prediction `pred`, else from the last pose, else by relocalisation;
        returns (estimate or None, point ids, the frame's keypoints, whether it relocalised)."""
        est, pids, feats = self._track_from(pred, feats, held_back)
        if est is None and self.tc.retry_from_last_pose and self.motion.velocity is not None:
            # ORB-SLAM's fallback from the motion model to the last frame's pose: a velocity from a few badly
            # tracked frames overshoots (Bonn, motion blur behind people: the frame after them was lost)
            assert self.motion.last is not None
            est, pids, feats = self._track_from(self.motion.last, feats, held_back)
            self.last_pose_retries += int(est is not None)
        if est is not None:
            return est, pids, feats, False
        est, pids = self._relocalise(feats)
        return est, pids, feats, est is not None

    def _lost(self, index: int, timestamp: float, pred: np.ndarray, feats: Features,
              view: FrameView) -> TrackResult:
        """A frame neither tracked nor relocalised: posed at the prediction; maybe the start of a new map."""
        assert self.ref_kf is not None
        self.lost_streak += 1
        self.motion.reset(pred)  # keep the prediction as the last pose; forget the velocity
        res = TrackResult(index, timestamp, pred, False, False, feats, np.full(len(feats), -1, np.int64),
                          None, self.ref_kf)
        action = after_loss(self.lost_streak, len(self.map) - self.map_starts[-1], self.tc)
        if action is not LossAction.WAIT:
            self._start_new_map(res, view, discard_old=action is LossAction.RESET)
        return res

    # ---- steps -------------------------------------------------------------------------------------------

    def _initialise(self, index: int, timestamp: float, view: FrameView, held_back: Features | None) -> TrackResult:
        T = np.eye(4)
        feats = view.feats
        if not can_start_map(self._n_new_points(feats), self.tc) and self.tc.rescue_with_held_back \
                and held_back is not None and len(held_back):
            # segmentation marks most of the first view: start on every keypoint (nothing to judge them by yet;
            # culling against this frame and the established points' weighting sort them out afterwards)
            both = self._with_held_back(feats, held_back)
            if can_start_map(self._n_new_points(both), self.tc):
                feats = both
                self.rescued_frames += 1
        res = TrackResult(index, timestamp, T, False, False, feats, np.full(len(feats), -1, np.int64), None, 0)
        if not can_start_map(self._n_new_points(feats), self.tc):
            return res  # wait for a frame with enough depth
        res.ok = True
        res.keyframe = self._insert_keyframe(res, view)
        self.motion.reset(T)
        self.last_result = res
        return res

    def _n_new_points(self, feats: Features) -> int:
        """Map points a keyframe on `feats` with nothing tracked would create (see `_insert_keyframe`)."""
        z = feats.depth
        return int(((z > 0) & (z < self.new_point_max_depth_m)).sum())

    def _start_new_map(self, res: TrackResult, view: FrameView, discard_old: bool) -> None:
        """Make lost frame `res` (pose = the prediction) the first keyframe of a new map, if it can start one.

        The frame itself stays `ok=False`: its pose was predicted, not measured.
        """
        if not can_start_map(self._n_new_points(res.feats), self.tc):
            return
        if discard_old:
            p = self.map.points
            p.kill(np.flatnonzero(p.alive[: p.n] & (p.first_kf[: p.n] >= self.map_starts[-1])))
        res.keyframe = self._insert_keyframe(res, view)
        res.ref_kf = res.keyframe.id
        res.new_map = True
        self.map_starts.append(res.keyframe.id)
        self.last_point_ids = np.zeros(0, np.int64)
        self.lost_streak = 0
        self.motion.reset(res.T_WC)
        self.last_result = res

    def _merge_into_older_map(self, res: TrackResult) -> bool:
        """Relocalise frame `res`, tracked in the newest map, in an older map; on success move the newest map
        onto it. The same PnP + local-map tracking as relocalisation, so a merge needs what a relocalisation
        needs; tried on every frame while a newer map exists (a returning view may last only a few frames).
        """
        start = self.map_starts[-1]
        saved = (self.ref_kf, self.local_kfs, self.last_point_ids)
        for kf_id in older_map_candidates(start, self.tc.reloc_keyframes):
            got = pnp_against_keyframe(self.map, kf_id, res.feats, self.K, self.tc.reloc_min_inliers)
            if got is None:
                continue
            self.local_kfs = [kf_id] + self.map.best_covisible(kf_id, self.tc.local_map_keyframes - 1)
            self.last_point_ids = np.zeros(0, np.int64)
            est, _ = self._track_local_map(res.feats, got[0], frame_to_frame=False)
            if est is None:
                continue
            old_local = self.local_kfs
            self.map.move_keyframes_since(start, est.T_WC @ inv(res.T_WC))
            res.T_WC = est.T_WC
            self.motion.last = res.T_WC.copy()  # the velocity is relative: it holds in either world
            # the merged map counts from the start of the map it joined (maps in between join it too)
            self.map_starts = [s for s in self.map_starts if s <= kf_id]
            # track on both maps' points from now on: shared observations will link them in covisibility
            self.ref_kf, self.last_point_ids = saved[0], saved[2]
            self.local_kfs = saved[1] + [i for i in old_local if i not in saved[1]]
            return True
        self.ref_kf, self.local_kfs, self.last_point_ids = saved
        return False

    def _track_from(self, pred: np.ndarray, feats: Features, held_back: Features | None
                    ) -> tuple[PoseEstimate | None, np.ndarray, Features]:
        """Local-map tracking of `feats` from the pose `pred`, then with the held-back keypoints added (see
        `rescue_with_held_back`); returns (estimate or None, point ids, the frame's keypoints)."""
        est, pids = self._track_local_map(feats, pred)
        if est is None and self.tc.rescue_with_held_back and held_back is not None and len(held_back):
            est, pids, feats = self._rescue(feats, held_back, pred)
            self.rescued_frames += int(est is not None)
        return est, pids, feats

    def _rescue(self, feats: Features, held_back: Features, pred: np.ndarray
                ) -> tuple[PoseEstimate | None, np.ndarray, Features]:
        """Track on `feats` plus the keypoints culling held back (see `rescue_with_held_back`); returns
        (estimate or None, point ids, the frame's keypoints: `feats` and the held-back inliers)."""
        both = self._with_held_back(feats, held_back)
        est, pids = self._track_local_map(both, pred)
        if est is None:  # lost or relocalised on the kept keypoints alone, as without the rescue
            return None, pids[: len(feats)], feats
        keep = np.ones(len(both), bool)
        keep[len(feats):] = pids[len(feats):] >= 0
        return est, pids[keep], both.select(keep)

    def _with_held_back(self, feats: Features, held_back: Features) -> Features:
        """The frame's (undistorted) keypoints followed by the held-back ones, undistorted the same way."""
        return Features.concat([feats, undistorted(held_back, self.sensor)])

    def _local_points(self) -> np.ndarray:
        kfs = self.map.keyframes
        parts = [kfs[i].point_ids for i in self.local_kfs] + [self.last_point_ids]
        ids = np.concatenate(parts)
        ids = ids[ids >= 0]
        ids = np.unique(ids)
        return ids[self.map.points.alive[ids]]

    def _search(self, index: KeypointIndex, ids: np.ndarray, T_WC: np.ndarray, radius: float):
        p = self.map.points
        return search_by_projection(index, p.pos[ids], p.desc[ids], p.normal[ids], p.max_dist[ids], T_WC,
                                    self.K, self.sensor.size, self.sensor.scales,
                                    radius, self.tc.max_hamming, self.tc.ratio)

    def _optimize(self, feats: Features, ids: np.ndarray, kp: np.ndarray, T_WC: np.ndarray,
                  established: bool) -> tuple[PoseEstimate, bool]:
        """Motion-only BA of the matches of keypoints `kp` to map points `ids`; with `established`, see
        `established_frames` (frame to frame tracking only: a relocalisation's PnP has already chosen among
        the hypotheses, and an older map's points are in that map's frame). Returns (estimate, whether the
        established points' pose was taken)."""
        def solve(weights: np.ndarray | None = None) -> PoseEstimate:
            return optimize_pose(T_WC, self.map.points.pos[ids], feats.uv[kp], feats.depth[kp],
                                 self.sensor.inv_sigma2[feats.octave[kp]], self.K, self.sensor.bf, self.tc.huber_px,
                                 self.tc.ba_rounds, self.tc.ba_iterations, weights,
                                 None if feats.depth_w is None else feats.depth_w[kp])

        est = solve()
        n = self.tc.established_frames
        if n <= 0 or not established:
            return est, False
        # People walking together can outnumber the static matches: the plain solve then follows them. Points
        # matched in many frames have kept still so far; if the pose they favour differs, trust them. Points of
        # an older map not merged yet are in that map's frame, not this one's: they count as new.
        p = self.map.points
        found = np.where(p.first_kf[ids] >= self.map_starts[-1], p.found[ids], 1)
        weighted = solve(np.clip(found / n, 1.0 / n, 1.0))
        if np.linalg.norm(weighted.T_WC[:3, 3] - est.T_WC[:3, 3]) > self.tc.established_disagree_m:
            return weighted, True
        return est, False

    def _track_local_map(self, feats: Features, T_pred: np.ndarray,
                         frame_to_frame: bool = True) -> tuple[PoseEstimate | None, np.ndarray]:
        """Coarse search + BA from the prediction, then a fine search over the local map + BA. Frame to frame
        tracking also searches a wider window and weighs established points; relocalisation and merging start
        from a PnP pose and do neither."""
        none = (None, np.full(len(feats), -1, np.int64))
        if len(feats) < self.tc.min_matches:
            return none
        index = KeypointIndex(feats)
        ids = self._local_points()
        est = None
        radii = [self.tc.search_radius_px] + ([self.tc.search_radius_px * 3] if frame_to_frame else [])
        for r in radii:
            m = self._search(index, ids, T_pred, r)
            if len(m.kp_idx) < self.tc.min_matches:
                continue
            est, _ = self._optimize(feats, ids[m.point_idx], m.kp_idx, T_pred, frame_to_frame)
            if est.n_inliers >= self.tc.min_matches:
                break
            est = None
        if est is None:
            return none
        m = self._search(index, ids, est.T_WC, self.tc.refine_radius_px)
        if len(m.kp_idx) < self.tc.min_matches:
            return none
        est, switched = self._optimize(feats, ids[m.point_idx], m.kp_idx, est.T_WC, frame_to_frame)
        if est.n_inliers < self.tc.min_matches:
            return none
        self.established_switches += int(switched)
        p = self.map.points
        p.visible[ids[m.visible]] += 1
        good_ids = ids[m.point_idx[est.inliers]]
        p.found[good_ids] += 1
        pids = np.full(len(feats), -1, np.int64)
        pids[m.kp_idx[est.inliers]] = good_ids
        self._update_local_keyframes(good_ids)
        return est, pids

    def _update_local_keyframes(self, tracked_ids: np.ndarray) -> None:
        """Reference keyframe = the one that created most tracked points; local map = its neighbourhood."""
        counts = np.bincount(self.map.points.first_kf[tracked_ids], minlength=len(self.map))
        top = [int(i) for i in np.argsort(-counts)[: self.tc.local_map_keyframes // 2] if counts[i] > 0]
        if not top:
            return
        self.ref_kf = top[0]
        local = list(top)
        for j in self.map.best_covisible(self.ref_kf, self.tc.local_map_keyframes):
            if len(local) >= self.tc.local_map_keyframes:
                break
            if j not in local:
                local.append(j)
        self.local_kfs = local

    def _relocalise(self, feats: Features) -> tuple[PoseEstimate | None, np.ndarray]:
        none = (None, np.full(len(feats), -1, np.int64))
        for kf_id in relocalisation_candidates(self.map, self.tc.reloc_keyframes, self.ref_kf, self.places,
                                               feats.desc):
            got = pnp_against_keyframe(self.map, kf_id, feats, self.K, self.tc.reloc_min_inliers)
            if got is None:
                continue
            saved = (self.ref_kf, self.local_kfs, self.last_point_ids)
            self.ref_kf = kf_id
            self.local_kfs = [kf_id] + self.map.best_covisible(kf_id, self.tc.local_map_keyframes - 1)
            self.last_point_ids = np.zeros(0, np.int64)
            est, pids = self._track_local_map(feats, got[0], frame_to_frame=False)
            if est is not None:
                return est, pids
            self.ref_kf, self.local_kfs, self.last_point_ids = saved
        return none

    def _need_keyframe(self, res: TrackResult) -> bool:
        if not len(self.map):
            return True
        s = KeyframeDecisionInput.of_frame(self.map, res.index, res.feats.depth, res.point_ids, self.last_kf_frame,
                                           self.tc.close_depth_m)
        return need_keyframe(s, self.tc)

    def _insert_keyframe(self, res: TrackResult, view: FrameView) -> KeyFrame:
        """Make frame `res` a keyframe (`new_keyframe.add_keyframe`); it becomes the reference keyframe."""
        kf = add_keyframe(self.map, res, view, self.K, self.fc.scale_factor, self.new_point_max_depth_m,
                          self.image_stride)
        self.ref_kf = kf.id
        self.local_kfs = [kf.id] + self.map.best_covisible(kf.id, self.tc.local_map_keyframes - 1)
        self.last_kf_frame = res.index
        return kf
