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


def evaluate_run(groundtruth: Trajectory, traj: Trajectory, cfg: EvalConfig) -> RunEvaluation:
    """Score `traj` against `groundtruth` with the run's `eval` settings; a failure is reported, not raised."""
    from worker.slam.evaluation.metrics import evaluate  # evo is heavy: imported only when there is truth

    try:
        ev = evaluate(groundtruth, traj, cfg.max_diff_s, cfg.rpe_delta_s)
    except EvaluationError as exc:
        return RunEvaluation({"evaluation_error": exc.message})
    errors = {round(float(t), 6): float(e) for t, e in zip(ev.matched_timestamps, ev.ate_errors)}
    return RunEvaluation(ev.to_dict(), ev.aligned_groundtruth, errors)
