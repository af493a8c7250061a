"""Relative pose error exactly as TUM's `evaluate_rpe.py` computes it, in both of its modes.

The script, for an estimate P and ground truth Q (camera-to-world poses):
- takes every estimate pose (sorted by time; one pose per timestamp) and looks each up in the ground truth
  by the closest timestamp, dropping a pair when either lookup is more than twice the ground truth's median
  sampling interval away (not the 0.02 s association of the ATE);
- pairs (i, j): with `--fixed_delta`, j is the estimate pose closest in time to t_i + delta, and a pair whose
  j is the last pose is dropped (that is where every late i lands); with `--delta_unit f` the delta counts
  estimate poses instead (j = i + delta: 1 pairs consecutive poses, the frame-to-frame drift); without
  `--fixed_delta` (the script's default), all ordered pairs (i, j), i == j included;
- E = (P_i^-1 P_j) (Q_i^-1 Q_j)^-1; the translation error is |t(E)| in metres, the rotation error the angle of
  R(E) (arccos((tr R - 1) / 2)), reported here in degrees.
Pair sub-sampling: the script keeps `--max_pairs` (default 10000) random pairs when it has more, which makes
its all-pairs figures depend on Python's generator. Here `max_pairs` defaults to 0, every pair (the script
with `--max_pairs 0`, exact and reproducible); a positive value samples the same way (uniform pairs with
replacement in all-pairs mode, a subset in fixed-delta mode) with a fixed-seed numpy generator, which bounds
the memory for long trajectories (all pairs of N poses hold N^2 errors).

Why not evo's `metrics.RPE`: it pairs by frames, metres or angles but not by time; its `all_pairs` means
every start index at one fixed delta, not every pair; and its error inv(Q_rel) P_rel has the same angle but
not the same translation as TUM's P_rel inv(Q_rel) (TUM's error on (i, j) is the inverse of evo's on (j, i),
which a test checks against evo's `RPE.rpe_base`).
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import asdict, dataclass
from enum import StrEnum

import numpy as np

from worker.slam.evaluation.stats import ErrorStats, error_stats
from worker.slam.io.trajectory import Trajectory

_BLOCK_PAIRS = 200_000  # pairs per vectorised chunk in all-pairs mode (bounded memory)


class RpeMode(StrEnum):
    FIXED_DELTA = "fixed-delta"  # evaluate_rpe.py --fixed_delta --delta D (drift per D seconds)
    FIXED_FRAMES = "fixed-frames"  # evaluate_rpe.py --fixed_delta --delta_unit f --delta D (per D poses)
    ALL_PAIRS = "all-pairs"  # evaluate_rpe.py's default (without its random sub-sampling)


@dataclass(frozen=True)
class RpeResult:
    """Translation error in metres and rotation error in degrees over `pairs` pose pairs."""

    mode: RpeMode
    delta_s: float | None  # the fixed interval; None in all-pairs and fixed-frames modes
    max_pairs: int  # the sampling bound asked for; 0 = every pair
    pairs: int  # pairs evaluated (those with ground truth at both ends)
    trans: ErrorStats
    rot_deg: ErrorStats
    delta_frames: int | None = None  # the fixed number of poses in fixed-frames mode, else None

    def to_dict(self) -> dict:
        out = {"mode": self.mode.value, "delta_s": self.delta_s, "max_pairs": self.max_pairs,
               "pairs": self.pairs, "trans": asdict(self.trans), "rot_deg": asdict(self.rot_deg)}
        if self.delta_frames is not None:
            out["delta_frames"] = self.delta_frames
        return out


def relative_pose_error(groundtruth: Trajectory, estimate: Trajectory, mode: RpeMode = RpeMode.FIXED_DELTA,
                        delta_s: float = 1.0, max_pairs: int = 0, delta_frames: int = 1) -> RpeResult | None:
    """TUM's RPE of `estimate` against `groundtruth`; None when fewer than 2 pairs remain (the script fails).
    `max_pairs` > 0 samples that many pairs when there are more (0: every pair). `delta_s` is used in
    fixed-delta mode, `delta_frames` in fixed-frames mode."""
    if mode is RpeMode.FIXED_DELTA and delta_s <= 0:
        raise ValueError(f"delta_s must be positive, got {delta_s}")
    if mode is RpeMode.FIXED_FRAMES and delta_frames < 1:
        raise ValueError(f"delta_frames must be >= 1, got {delta_frames}")
    if max_pairs < 0:
        raise ValueError(f"max_pairs must be >= 0, got {max_pairs}")
    rng = np.random.default_rng(0)
    t_gt, q = _by_timestamp(groundtruth)
    t_est, p = _by_timestamp(estimate)
    if len(t_gt) < 2 or len(t_est) < 2:
        return None
    gt_idx = _closest(t_gt, t_est)
    max_gap = 2.0 * float(np.median(np.diff(t_gt)))
    has_gt = np.abs(t_gt[gt_idx] - t_est) <= max_gap
    q = q[gt_idx]  # (N_est, 4, 4) the ground truth at each estimate pose (valid where has_gt)
    n = len(t_est)
    chunks: Iterator[tuple[np.ndarray, np.ndarray]]
    if mode in (RpeMode.FIXED_DELTA, RpeMode.FIXED_FRAMES):
        if mode is RpeMode.FIXED_DELTA:
            j = _closest(t_est, t_est + delta_s)
        else:  # the script's index_est = range(n): the closest index to i + delta, clipped to the last
            j = np.minimum(np.arange(n) + delta_frames, n - 1)
        i = np.nonzero(j != n - 1)[0]
        if 0 < max_pairs < len(i):  # sampled before the ground-truth check, as the script does
            i = np.sort(rng.choice(i, max_pairs, replace=False))
        j = j[i]
        keep = has_gt[i] & has_gt[j]
        chunks = iter([(i[keep], j[keep])])
    elif 0 < max_pairs < n * n:
        i, j = rng.integers(0, n, (2, max_pairs))
        keep = has_gt[i] & has_gt[j]
        chunks = iter([(i[keep], j[keep])])
    else:
        chunks = _all_pairs(np.nonzero(has_gt)[0])
    trans, rot = _errors(p, q, chunks)
    if len(trans) < 2:
        return None
    return RpeResult(mode, delta_s if mode is RpeMode.FIXED_DELTA else None, max_pairs, len(trans),
                     error_stats(trans), error_stats(rot),
                     delta_frames if mode is RpeMode.FIXED_FRAMES else None)


def _by_timestamp(traj: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """(N,) sorted unique timestamps and their (N,4,4) poses; a repeated timestamp keeps its last pose (the
    script reads a trajectory into a dict)."""
    t = np.asarray(traj.timestamps, np.float64)
    rev = np.arange(len(t))[::-1]
    _, first_in_rev = np.unique(t[rev], return_index=True)  # sorted by time
    keep = rev[first_in_rev]
    return t[keep], np.asarray(traj.poses, np.float64)[keep]


def _closest(sorted_t: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Index of the value of `sorted_t` closest to each query (the earlier one on an exact tie)."""
    hi = np.clip(np.searchsorted(sorted_t, query), 0, len(sorted_t) - 1)
    lo = np.maximum(hi - 1, 0)
    return np.where(np.abs(sorted_t[lo] - query) <= np.abs(sorted_t[hi] - query), lo, hi)


def _all_pairs(valid: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Every ordered pair of `valid` indices, in chunks of about _BLOCK_PAIRS."""
    rows = max(1, _BLOCK_PAIRS // max(1, len(valid)))
    for start in range(0, len(valid), rows):
        i = valid[start:start + rows]
        yield np.repeat(i, len(valid)), np.tile(valid, len(i))


def _errors(p: np.ndarray, q: np.ndarray,
            chunks: Iterator[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Translation (m) and angle (deg) of E = (P_i^-1 P_j)(Q_i^-1 Q_j)^-1 for index pairs (i, j).

    Closed forms (no 4x4 inverses): |t(E)| = |R_Pj^T (t_Pj - t_Pi) - R_Qj^T (t_Qj - t_Qi)| (the norm of
    t(E) rotated by R_Pj^T), and tr R(E) = <M_i, M_j> (Frobenius) with M = R_P R_Q^T.
    """
    rp, tp, rq, tq = p[:, :3, :3], p[:, :3, 3], q[:, :3, :3], q[:, :3, 3]
    m = rp @ rq.transpose(0, 2, 1)
    trans, rot = [], []
    for i, j in chunks:
        a = np.einsum("nkl,nk->nl", rp[j], tp[j] - tp[i])
        b = np.einsum("nkl,nk->nl", rq[j], tq[j] - tq[i])
        trans.append(np.linalg.norm(a - b, axis=1))
        trace = np.einsum("nkl,nkl->n", m[i], m[j])
        rot.append(np.degrees(np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0))))
    if not trans:
        return np.zeros(0), np.zeros(0)
    return np.concatenate(trans), np.concatenate(rot)
