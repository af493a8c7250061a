"""ATE and RPE the way TUM's evaluate_ate.py / evaluate_rpe.py report them.

ATE (with evo): associate at `max_diff` (0.02 s), rigid SE(3) Umeyama alignment (no scale), statistics of the
translation error. RPE: TUM's own algorithm (see `rpe.py`), fixed delta or all pairs, on the unassociated
trajectories as the script does.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from evo.core import metrics, sync
from evo.core.geometry import GeometryException
from evo.core.trajectory import PoseTrajectory3D

from worker.slam.errors import EvaluationError
from worker.slam.evaluation.rpe import RpeMode, RpeResult, relative_pose_error
from worker.slam.evaluation.stats import ErrorStats
from worker.slam.io.trajectory import Trajectory

__all__ = ["ErrorStats", "EvalResult", "RpeMode", "evaluate", "to_evo"]


@dataclass(frozen=True)
class EvalResult:
    """ATE in metres; RPE (None when the trajectory is too short for it) as `rpe.RpeResult`."""

    ate: ErrorStats
    rpe: RpeResult | None
    matched: int
    ate_errors: np.ndarray  # (matched,) per-pose translation error after alignment
    matched_timestamps: np.ndarray  # (matched,) estimate timestamps
    aligned_groundtruth: Trajectory  # the matched GT poses T_WC expressed in the estimate's world frame

    def to_dict(self) -> dict:
        """The metrics.json shape: `ate` {rmse, mean, median, std, max}, `matched_poses`, `rpe` {trans,
        rot_deg, mode, delta_s, max_pairs, pairs} (absent when there is no RPE)."""
        out: dict = {"ate": asdict(self.ate), "matched_poses": self.matched}
        if self.rpe is not None:
            out["rpe"] = self.rpe.to_dict()
        return out


def to_evo(traj: Trajectory) -> PoseTrajectory3D:
    """The trajectory as evo's (poses T_WC, timestamps)."""
    return PoseTrajectory3D(poses_se3=list(traj.poses), timestamps=np.asarray(traj.timestamps))


def _stats(metric: metrics.PE) -> ErrorStats:
    s = metric.get_all_statistics()
    return ErrorStats(*(float(s[k]) for k in ("rmse", "mean", "median", "std", "max")))


def evaluate(groundtruth: Trajectory, estimate: Trajectory, max_diff: float = 0.02, rpe_delta_s: float = 1.0,
             rpe_mode: RpeMode = RpeMode.FIXED_DELTA, rpe_max_pairs: int = 0) -> EvalResult:
    """Compare an estimate with ground truth. RPE: see `rpe.relative_pose_error` (`rpe_delta_s` is used in
    fixed-delta mode only; `rpe_max_pairs` 0 = every pair).

    Raises EvaluationError when fewer than 3 poses associate or when the associated positions make the rigid
    alignment undefined (e.g. an estimate that never moved).
    """
    try:
        ref, est = sync.associate_trajectories(to_evo(groundtruth), to_evo(estimate), max_diff=max_diff)
    except sync.SyncException as exc:
        raise EvaluationError(f"trajectories do not associate: {exc}") from exc
    if ref.num_poses < 3:
        raise EvaluationError(f"only {ref.num_poses} poses associate within {max_diff} s; need at least 3")
    for name, t in (("estimate", est), ("ground truth", ref)):
        if not np.isfinite(np.asarray(t.poses_se3)).all():  # numpy's SVD would not converge on them
            raise EvaluationError(f"the {name} has non-finite poses; ATE and RPE are unavailable",
                                  detail={"reason": "non_finite_poses"})
    try:
        return _compare(groundtruth, estimate, ref, est, rpe_mode, rpe_delta_s, rpe_max_pairs)
    except (np.linalg.LinAlgError, ValueError, ArithmeticError) as exc:  # a run keeps its outputs regardless
        raise EvaluationError(f"the metrics could not be computed: {type(exc).__name__}: {exc}",
                              detail={"reason": "numerical_failure"}) from exc


def _compare(groundtruth: Trajectory, estimate: Trajectory, ref: PoseTrajectory3D, est: PoseTrajectory3D,
             rpe_mode: RpeMode, rpe_delta_s: float, rpe_max_pairs: int) -> EvalResult:
    """ATE after SE(3) alignment and RPE of the associated ``ref`` / ``est`` poses."""
    try:
        r_a, t_a, _ = est.align(ref, correct_scale=False)  # maps the estimate's world into the GT's
    except GeometryException as exc:
        raise EvaluationError(_degenerate_message(np.asarray(ref.positions_xyz), np.asarray(est.positions_xyz)),
                              detail={"reason": "degenerate_alignment"}) from exc
    T_ref_est = np.eye(4)
    T_ref_est[:3, :3], T_ref_est[:3, 3] = r_a, t_a
    gt_in_est = np.linalg.inv(T_ref_est) @ np.asarray(ref.poses_se3)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    rpe = relative_pose_error(groundtruth, estimate, rpe_mode, rpe_delta_s, rpe_max_pairs)
    if not np.isfinite(np.asarray(ape.error)).all():
        raise EvaluationError("the aligned errors are not finite (poses too far apart to compare)",
                              detail={"reason": "non_finite_errors"})
    return EvalResult(_stats(ape), rpe, ref.num_poses, np.asarray(ape.error), np.asarray(est.timestamps),
                      Trajectory(np.asarray(est.timestamps), gt_in_est))


def _degenerate_message(gt_xyz: np.ndarray, est_xyz: np.ndarray) -> str:
    """Why Umeyama failed, in terms of the two (N,3) associated position sets."""

    def shape(xyz: np.ndarray) -> str:
        centred = xyz - xyz.mean(axis=0)
        extent = float(np.max(np.linalg.norm(centred, axis=1)))
        if extent < 1e-9:
            return "all at one point (it never moved)"
        rank = int(np.linalg.matrix_rank(centred, tol=1e-9 * max(1.0, extent)))
        return f"on a line (extent {extent:.3g} m)" if rank < 2 else f"spread over {extent:.3g} m"

    return (f"SE(3) alignment is undefined for these {len(est_xyz)} associated poses: estimate positions "
            f"{shape(est_xyz)}, ground-truth positions {shape(gt_xyz)}")
