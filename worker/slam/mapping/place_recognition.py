"""Loop candidates as ORB-SLAM2 detects them (LoopClosing::DetectLoop, KeyFrameDatabase::DetectLoopCandidates).

The keyframes' tf-idf vectors of the shipped vocabulary (`features.bow_database`) are compared with DBoW2's L1
score. A query's threshold is its lowest score against its own covisible keyframes (what "the same place"
scores here); candidates are keyframes not connected to it that share at least 80 % of the best candidate's
common words and reach that threshold; each candidate's score is accumulated over its covisible neighbours
that are candidates too, and groups within 75 % of the best accumulated score are kept, each represented by
its best keyframe. A candidate is accepted only when its covisibility group continues a group that was also
a candidate for the previous `consistency` keyframes: a single similar-looking view never closes a loop.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.slam.features.bow_database import KeyframeDatabase
from worker.slam.map.map import Map

CONNECTED_MIN_SHARED = 15
"""ORB-SLAM2's covisibility link: keyframes sharing at least this many points are 'connected'."""


def sync_database(db: KeyframeDatabase, slam_map: Map) -> None:
    """Index the map's keyframes the database has not seen yet (ids are insertion order in both)."""
    db.extend(kf.feats.desc for kf in slam_map.keyframes[len(db):])


def connected(slam_map: Map, kf_id: int) -> list[int]:
    """Keyframes connected to `kf_id` (ORB-SLAM2: >= 15 shared points, else its strongest one)."""
    linked = slam_map.best_covisible(kf_id, 10**9, CONNECTED_MIN_SHARED)
    return linked or slam_map.best_covisible(kf_id, 1)


@dataclass
class ConsistentGroup:
    """A candidate's covisibility group and for how many consecutive keyframes it has been a candidate."""

    members: set[int]
    count: int


class LoopDetector:
    """Loop candidates of each new keyframe, from a shared keyframe database."""

    def __init__(self, slam_map: Map, db: KeyframeDatabase, min_keyframe_gap: int, consistency: int) -> None:
        self.map, self.db = slam_map, db
        self.min_gap, self.consistency = min_keyframe_gap, consistency
        self.groups: list[ConsistentGroup] = []
        #: The last query's threshold and accepted candidates (for tests and the log).
        self.last_min_score = 0.0

    def candidates(self, kf_id: int) -> list[int]:
        """Scored and grouped candidates of keyframe `kf_id` (best group first), before the consistency test."""
        near = [j for j in connected(self.map, kf_id) if j < kf_id]
        if not near or kf_id < self.min_gap:
            return []
        scores, common = self.db.query(self.db.bows[kf_id], upto=kf_id)
        self.last_min_score = min_score = float(scores[near].min())
        old = np.zeros(kf_id, bool)
        old[: max(0, kf_id - self.min_gap + 1)] = True
        old[near] = False
        old &= common > 0
        if not old.any():
            return []
        old &= common > 0.8 * common[old].max()
        good = old & (scores >= min_score)
        best_acc, groups = 0.0, []
        for c in np.flatnonzero(good):
            members = [int(c)] + [j for j in self.map.best_covisible(int(c), 10) if j < kf_id and old[j]]
            acc = float(scores[members].sum())
            groups.append((acc, max(members, key=lambda j: scores[j])))
            best_acc = max(best_acc, acc)
        keep = sorted({(acc, rep) for acc, rep in groups if acc >= 0.75 * best_acc}, reverse=True)
        out: list[int] = []
        for _, rep in keep:
            if rep not in out:
                out.append(rep)
        return out

    def detect(self, kf_id: int) -> list[int]:
        """Candidates of `kf_id` whose group has been a candidate for `consistency` keyframes in a row."""
        cands = self.candidates(kf_id)
        current: list[ConsistentGroup] = []
        used = [False] * len(self.groups)
        enough: list[int] = []
        for cand in cands:
            members = {cand} | set(connected(self.map, cand))
            continued = False
            for i, g in enumerate(self.groups):
                if not members & g.members:
                    continue
                continued = True
                count = g.count + 1
                if not used[i]:
                    current.append(ConsistentGroup(members, count))
                    used[i] = True
                if count >= self.consistency and cand not in enough:
                    enough.append(cand)
            if not continued:
                current.append(ConsistentGroup(members, 0))
        self.groups = current
        return enough

    def reset(self) -> None:
        """Forget the consistent groups (after a loop is closed, as ORB-SLAM2 does)."""
        self.groups = []
