"""Local mapping run on each new keyframe: map-point culling, triangulation, fusion with the covisible
keyframes, then local bundle adjustment."""
from __future__ import annotations

import numpy as np

from worker.slam.config import MappingConfig
from worker.slam.map.keyframe import KeyFrame
from worker.slam.map.map import Map
from worker.slam.mapping.fuse import FuseGeometry, fuse_neighbours
from worker.slam.mapping.local_ba import BAStats, local_bundle_adjust
from worker.slam.mapping.triangulation import triangulate_new_points
from worker.slam.sensor import SensorModel

MIN_OBSERVATIONS = 2


def cull_points(slam_map: Map, kf_id: int, cfg: MappingConfig) -> int:
    """Kill recent points that tracking rarely finds or that no later keyframe observed. Returns the count.

    ORB-SLAM2's rule: found/visible < 0.25, or still seen by fewer than 2 keyframes two keyframes after
    creation. Points older than the grace window have proven themselves and are kept.
    """
    p = slam_map.points
    n = p.n
    age = kf_id - p.first_kf[:n]
    recent = p.alive[:n] & (age >= 1) & (age <= cfg.cull_grace_keyframes)
    ratio = p.found[:n] / np.maximum(p.visible[:n], 1)
    bad = recent & ((ratio < cfg.cull_min_found_ratio) | ((age >= 2) & (p.n_obs[:n] < MIN_OBSERVATIONS)))
    bad |= p.alive[:n] & (p.n_obs[:n] <= 0)
    ids = np.flatnonzero(bad)
    p.kill(ids)
    return len(ids)


class LocalMapper:
    def __init__(self, slam_map: Map, cfg: MappingConfig, sensor: SensorModel, huber_px: float) -> None:
        """`huber_px`: the robust kernel's width in BA (the tracker's, `tracking.huber_px`)."""
        self.map, self.cfg, self.K, self.bf = slam_map, cfg, sensor.K, sensor.bf
        self.inv_sigma2, self.huber_px = sensor.inv_sigma2, huber_px
        self.n_processed = 0
        self.culled = 0
        self.triangulated = 0
        self.fused = 0
        self.scale_factor = sensor.scale_factor
        self.geometry = FuseGeometry(sensor.K, sensor.size, sensor.sigmas, sensor.inv_sigma2, sensor.bf)
        self.last_ba: BAStats | None = None

    def process(self, kf: KeyFrame) -> None:
        self.culled += cull_points(self.map, kf.id, self.cfg)
        if self.cfg.triangulate_neighbours:
            self.triangulated += triangulate_new_points(self.map, kf, self.cfg.triangulate_neighbours, self.K,
                                                        self.inv_sigma2, self.scale_factor,
                                                        self.cfg.triangulate_min_parallax_deg)
        if self.cfg.fuse_neighbours:
            self.fused += fuse_neighbours(self.map, kf, self.cfg.fuse_neighbours, self.geometry,
                                          self.cfg.fuse_radius_px, self.cfg.fuse_merge)
        self.n_processed += 1
        if not self.cfg.local_ba or len(self.map) < 2 or self.n_processed % self.cfg.local_ba_every:
            return
        local = [kf.id] + self.map.best_covisible(kf.id, self.cfg.local_ba_keyframes - 1)
        self.last_ba = local_bundle_adjust(self.map, local, self.K, self.bf, self.inv_sigma2,
                                           self.cfg.local_ba_iterations, self.huber_px)

    def global_bundle_adjust(self, iterations: int) -> BAStats | None:
        """All keyframes and points; the first keyframe holds the gauge."""
        if len(self.map) < 3:
            return None
        return local_bundle_adjust(self.map, list(range(len(self.map))), self.K, self.bf, self.inv_sigma2,
                                   iterations, self.huber_px)
