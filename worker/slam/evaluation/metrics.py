"""ATE and RPE the way TUM's evaluate_ate.py / evaluate_rpe.py report them, computed with evo.

ATE: associate at 0.02 s, rigid SE(3) Umeyama alignment (no scale), statistics of the translation error.
RPE: relative motion over 1 s as evaluate_rpe.py: every associated pose i is paired with the pose closest to
t_i + 1 s. evo pairs poses by frames, metres or degrees but not by time, so the pairs are chosen here and the
relative errors E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j) computed with evo's SE(3) helpers.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from evo.core import lie_algebra as lie
from evo.core import metrics, sync
from evo.core.trajectory import PoseTrajectory3D

from worker.slam.errors import EvaluationError
from worker.slam.io.trajectory import Trajectory


@dataclass(frozen=True)
class ErrorStats:
    rmse: float
    mean: float
    median: float
    std: float
    max: float


@dataclass(frozen=True)
class EvalResult:
    """ATE in metres; RPE translation in m per `rpe_delta_s`, rotation in degrees per `rpe_delta_s`."""

    ate: ErrorStats
    rpe_trans: ErrorStats | None
    rpe_rot: ErrorStats | None
    matched: int
    rpe_delta_s: float
    ate_errors: np.ndarray  # (matched,) per-pose translation error after alignment
    matched_timestamps: np.ndarray  # (matched,) estimate timestamps
    aligned_groundtruth: Trajectory  # the matched GT poses T_WC expressed in the estimate's world frame

    def to_dict(self) -> dict:
        """The metrics.json shape: `ate` {rmse, mean, median, std, max}, `rpe` {trans, rot, delta_s}."""
        out: dict = {"ate": asdict(self.ate), "matched_poses": self.matched}
        if self.rpe_trans is not None and self.rpe_rot is not None:
            out["rpe"] = {"trans": asdict(self.rpe_trans), "rot_deg": asdict(self.rpe_rot),
                          "delta_s": self.rpe_delta_s}
        return out


def _to_evo(traj: Trajectory) -> PoseTrajectory3D:
    return PoseTrajectory3D(poses_se3=list(traj.poses), timestamps=np.asarray(traj.timestamps))


def _stats(metric: metrics.PE) -> ErrorStats:
    s = metric.get_all_statistics()
    return ErrorStats(*(float(s[k]) for k in ("rmse", "mean", "median", "std", "max")))



def evaluate(groundtruth: Trajectory, estimate: Trajectory, max_diff: float = 0.02,
             rpe_delta_s: float = 1.0) -> EvalResult:
    """Compare an estimate with ground truth. Raises EvaluationError when fewer than 3 poses associate."""
    try:
        ref, est = sync.associate_trajectories(_to_evo(groundtruth), _to_evo(estimate), max_diff=max_diff)
    except sync.SyncException as exc:
        raise EvaluationError(f"trajectories do not associate: {exc}") from exc
    if ref.num_poses < 3:
        raise EvaluationError(f"only {ref.num_poses} poses associate within {max_diff} s; need at least 3")
    r_a, t_a, _ = est.align(ref, correct_scale=False)  # maps the estimate's world into the GT's
    T_ref_est = np.eye(4)
    T_ref_est[:3, :3], T_ref_est[:3, 3] = r_a, t_a
    gt_in_est = np.linalg.inv(T_ref_est) @ np.asarray(ref.poses_se3)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    rpe = _rpe(ref, est, rpe_delta_s)
    rpe_t, rpe_r = rpe if rpe else (None, None)
    return EvalResult(_stats(ape), rpe_t, rpe_r, ref.num_poses, rpe_delta_s,
                      np.asarray(ape.error), np.asarray(est.timestamps),
                      Trajectory(np.asarray(est.timestamps), gt_in_est))


def _stats_of(err: np.ndarray) -> ErrorStats:
    return ErrorStats(float(np.sqrt(np.mean(err**2))), float(np.mean(err)), float(np.median(err)),
                      float(np.std(err)), float(np.max(err)))


def _rpe(ref: PoseTrajectory3D, est: PoseTrajectory3D, delta_s: float) -> tuple[ErrorStats, ErrorStats] | None:
    """(translation m, rotation deg) statistics over pairs (i, j) with t_j closest to t_i + delta_s."""
    t = np.asarray(est.timestamps)
    j = np.clip(np.searchsorted(t, t + delta_s), 1, len(t) - 1)
    j = np.where(np.abs(t[j - 1] - (t + delta_s)) < np.abs(t[j] - (t + delta_s)), j - 1, j)
    keep = j > np.arange(len(t))
    trans, rot = [], []
    for i, k in zip(np.nonzero(keep)[0], j[keep]):
        e = lie.relative_se3(lie.relative_se3(ref.poses_se3[i], ref.poses_se3[k]),
                             lie.relative_se3(est.poses_se3[i], est.poses_se3[k]))
        trans.append(np.linalg.norm(e[:3, 3]))
        rot.append(np.degrees(lie.so3_log_angle(e[:3, :3])))
    if not trans:
        return None
    return _stats_of(np.asarray(trans)), _stats_of(np.asarray(rot))
