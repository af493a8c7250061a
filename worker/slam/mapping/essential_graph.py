"""ORB-SLAM2's essential graph over the keyframes: spanning tree, strong covisibility and loop edges.

The spanning tree links each keyframe to its parent, the earlier keyframe it shares the most points with (the
previous keyframe when it shares none, e.g. the first keyframe of a map started after a loss); strong
covisibility adds every pair sharing at least `strong` points. Each edge's measurement is the two keyframes'
relative pose before the correction: a loop correction bends the map only where the loop edges pull.
"""
from __future__ import annotations

import numpy as np

from worker.slam.geometry.se3 import inv
from worker.slam.map.map import Map

Edge = tuple[int, int, np.ndarray, float]
"""(i, j, Z_ij (4,4): T_i^-1 T_j measured, weight)."""


def spanning_parents(slam_map: Map) -> np.ndarray:
    """(n,) parent keyframe id of each keyframe (-1 for keyframe 0)."""
    parent = np.full(len(slam_map), -1, np.int64)
    for i in range(1, len(slam_map)):
        earlier = [(w, j) for j, w in slam_map.covis.get(i, {}).items() if j < i]
        parent[i] = max(earlier)[1] if earlier else i - 1
    return parent


def essential_edges(slam_map: Map, poses: np.ndarray, strong: int) -> list[Edge]:
    """Spanning-tree and strong-covisibility edges, measured on `poses` (n,4,4) T_WC."""
    parent = spanning_parents(slam_map)
    pairs = {(int(p), i) for i, p in enumerate(parent) if p >= 0}
    for i, nb in slam_map.covis.items():
        pairs |= {(i, j) for j, w in nb.items() if i < j and w >= strong}
    return [(i, j, inv(poses[i]) @ poses[j], 1.0) for i, j in sorted(pairs)]
