"""A run's trajectory scored against the sequence's ground truth (ATE, RPE)."""
from __future__ import annotations

from dataclasses import dataclass

from worker.slam.config import EvalConfig
from worker.slam.errors import EvaluationError
from worker.slam.io.trajectory import Trajectory


@dataclass(frozen=True)
class RunEvaluation:
    metrics: dict
    """The metrics.json entries (`ate`, `rpe`, ...; or `evaluation_error` when it could not be scored)."""
    aligned_groundtruth: Trajectory | None = None
    """Ground truth aligned onto the estimate; None when it could not be scored."""
    ate_errors: dict[float, float] | None = None
    """Per-frame ATE (m) by timestamp rounded to 6 decimals; None when it could not be scored."""


def evaluate_run(groundtruth: Trajectory, traj: Trajectory, cfg: EvalConfig,
                 groundtruth_frame: str = "camera") -> RunEvaluation:
    """Score `traj` against `groundtruth` (the pose of `groundtruth_frame`, see
    `worker.slam.evaluation.groundtruth_frame`) with the run's `eval` settings; a failure is reported, not
    raised. The aligned ground truth and per-frame errors are the published-convention ATE's (raw truth)."""
    from worker.slam.evaluation.groundtruth_frame import evaluate_framed  # evo is heavy: only with truth

    try:
        ev = evaluate_framed(groundtruth, traj, groundtruth_frame, cfg.max_diff_s, cfg.rpe_delta_s)
    except EvaluationError as exc:
        return RunEvaluation({"groundtruth_frame": groundtruth_frame, "evaluation_error": exc.message})
    pub = ev.published
    errors = {round(float(t), 6): float(e) for t, e in zip(pub.matched_timestamps, pub.ate_errors)}
    return RunEvaluation(ev.to_dict(), pub.aligned_groundtruth, errors)
