"""A plain re-implementation of TUM's evaluate_rpe.py (2013, J. Sturm), the golden tests' reference.

Written from the script's algorithm, step by step and independently of `worker.slam.evaluation`: its own file
reader (the script's transform44 quaternion formula), its binary-search `find_closest_index`, 4x4 inverses for
`ominus`. One change: no random sub-sampling of pairs (the script with `--max_pairs 0`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class TumRpe:
    trans: np.ndarray  # (pairs,) metres
    rot_deg: np.ndarray  # (pairs,) degrees


def read_trajectory(path: Path) -> dict[float, np.ndarray]:
    """stamp -> 4x4 pose; comment lines, zero quaternions and NaN lines are skipped as the script does."""
    traj: dict[float, np.ndarray] = {}
    for line in path.read_text().replace(",", " ").replace("\t", " ").split("\n"):
        if not line or line[0] == "#":
            continue
        v = [float(x) for x in line.split()]
        if v[4:8] == [0, 0, 0, 0] or any(np.isnan(v)):
            continue
        traj[v[0]] = _transform44(v)
    return traj


def _transform44(v: list[float]) -> np.ndarray:
    q = np.array(v[4:8], dtype=np.float64)  # x y z w
    q *= np.sqrt(2.0 / np.dot(q, q))
    q = np.outer(q, q)
    return np.array([
        [1.0 - q[1, 1] - q[2, 2], q[0, 1] - q[2, 3], q[0, 2] + q[1, 3], v[1]],
        [q[0, 1] + q[2, 3], 1.0 - q[0, 0] - q[2, 2], q[1, 2] - q[0, 3], v[2]],
        [q[0, 2] - q[1, 3], q[1, 2] + q[0, 3], 1.0 - q[0, 0] - q[1, 1], v[3]],
        [0.0, 0.0, 0.0, 1.0]])


def find_closest_index(values: list[float], t: float) -> int:
    """The script's binary search: the closest element met on the search path."""
    beginning, end, best = 0, len(values), 0
    difference = abs(values[0] - t)
    while beginning < end:
        middle = (end + beginning) // 2
        if abs(values[middle] - t) < difference:
            difference = abs(values[middle] - t)
            best = middle
        if t == values[middle]:
            return middle
        if values[middle] > t:
            end = middle
        else:
            beginning = middle + 1
    return best


def _ominus(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """inv(a) @ b for 4x4 or stacked (..., 4, 4) poses."""
    return np.linalg.inv(a) @ b


def evaluate_rpe(traj_gt: dict[float, np.ndarray], traj_est: dict[float, np.ndarray],
                 fixed_delta: bool, delta: float = 1.0) -> TumRpe:
    """The script's evaluate_trajectory with offset 0, scale 1, delta unit seconds, no pair sampling."""
    stamps_gt = sorted(traj_gt)
    stamps_est = sorted(traj_est)
    n = len(stamps_est)
    gt_max_time_difference = 2 * float(np.median(np.diff(stamps_gt)))
    gt_of = [stamps_gt[find_closest_index(stamps_gt, s)] for s in stamps_est]
    ok = np.array([abs(g - s) <= gt_max_time_difference for g, s in zip(gt_of, stamps_est)])
    if fixed_delta:
        pairs = []
        for a in range(n):
            b = find_closest_index(stamps_est, stamps_est[a] + delta)
            if b != n - 1:
                pairs.append((a, b))
        i, j = np.array(pairs, dtype=np.int64).T
    else:  # all n * n ordered pairs (i == j included), as index grids rather than a list of tuples
        i, j = (a.ravel() for a in np.meshgrid(np.arange(n), np.arange(n), indexing="ij"))
    keep = ok[i] & ok[j]  # the script skips a pair whose ground-truth lookup is too far in time
    i, j = i[keep], j[keep]
    est = np.stack([traj_est[s] for s in stamps_est])
    gt = np.stack([traj_gt[g] for g in gt_of])
    trans, rot = [], []
    for start in range(0, len(i), 100_000):  # stacked 4x4 products, in chunks to bound memory
        s = slice(start, start + 100_000)
        error44 = _ominus(_ominus(est[j[s]], est[i[s]]), _ominus(gt[j[s]], gt[i[s]]))
        trans.append(np.linalg.norm(error44[:, :3, 3], axis=1))
        cos = (np.trace(error44[:, :3, :3], axis1=1, axis2=2) - 1) / 2
        rot.append(np.degrees(np.arccos(np.minimum(1, np.maximum(-1, cos)))))
    return TumRpe(np.concatenate(trans), np.concatenate(rot))
