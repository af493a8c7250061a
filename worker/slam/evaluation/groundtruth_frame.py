"""Scoring against a ground truth that may be the pose of something other than the camera.

A sequence's camera says what its `groundtruth.txt` is the pose of (`Camera.groundtruth_frame`, names in
`formats.catalog.GROUNDTRUTH_FRAMES`): `camera` (TUM, 7-Scenes, synthetic) or `bonn-marker` (Bonn RGB-D
Dynamic's motion-capture marker, moved to the camera by `worker.slam.io.bonn.correct_bonn_groundtruth`).

- ATE is reported twice: `ate` against the raw ground truth (the published convention: what papers report) and
  `ate_corrected` against the camera's; for a camera ground truth both are the same figures.
- RPE only against the camera's ground truth: against a marker it measures the marker's lever arm swinging
  with every rotation, not tracking (Bonn crowd: 0.13 m / 11 deg per second instead of 0.02 m / 0.6 deg).
  `rpe` is the drift per `rpe_delta_s` (1 s), `rpe_frame` per pose (consecutive estimate poses).
Each figure carries a label (`ate_against`, `ate_corrected_against`, `rpe_against`) saying what it was
measured against.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

from worker.slam.evaluation.metrics import EvalResult, evaluate
from worker.slam.evaluation.rpe import RpeMode, RpeResult, relative_pose_error
from worker.slam.io.bonn import correct_bonn_groundtruth
from worker.slam.io.trajectory import Trajectory

CAMERA = "camera"
TO_CAMERA: dict[str, Callable[[Trajectory], Trajectory]] = {"bonn-marker": correct_bonn_groundtruth}
"""Per non-camera ground-truth frame, the correction of its poses to the camera's T_WC."""


def camera_groundtruth(raw: Trajectory, frame: str) -> Trajectory:
    """The camera's ground truth T_WC from `raw` ground truth that is the pose of `frame`."""
    if frame == CAMERA:
        return raw
    try:
        return TO_CAMERA[frame](raw)
    except KeyError:
        raise ValueError(f"unknown ground-truth frame {frame!r}; known: {[CAMERA, *TO_CAMERA]}") from None


def labels(frame: str) -> dict[str, str]:
    """What each figure was measured against, as metrics.json says it."""
    if frame == CAMERA:
        return {"ate_against": CAMERA, "ate_corrected_against": CAMERA, "rpe_against": CAMERA}
    corrected = f"camera (corrected from {frame})"
    return {"ate_against": f"{frame} (raw ground truth, published convention)",
            "ate_corrected_against": corrected, "rpe_against": corrected}


@dataclass(frozen=True)
class FramedEvaluation:
    """`published`: scored against the raw ground truth (its `rpe` is not reported when the frame is not the
    camera's); `corrected`: against the camera's (the same object for a camera ground truth)."""

    frame: str
    published: EvalResult
    corrected: EvalResult
    rpe_frame: RpeResult | None

    def to_dict(self) -> dict:
        """metrics.json entries: `ate`, `matched_poses`, `rpe` (as before, `rpe` now always against the camera),
        then `groundtruth_frame`, the labels, `ate_corrected` and `rpe_frame` (absent when too short)."""
        out: dict = {"ate": asdict(self.published.ate), "matched_poses": self.published.matched}
        if self.corrected.rpe is not None:
            out["rpe"] = self.corrected.rpe.to_dict()
        out["groundtruth_frame"] = self.frame
        out.update(labels(self.frame))
        out["ate_corrected"] = asdict(self.corrected.ate)
        if self.rpe_frame is not None:
            out["rpe_frame"] = self.rpe_frame.to_dict()
        return out


def evaluate_framed(groundtruth: Trajectory, estimate: Trajectory, frame: str = CAMERA, max_diff: float = 0.02,
                    rpe_delta_s: float = 1.0) -> FramedEvaluation:
    """ATE against the raw and the camera's ground truth, RPE per `rpe_delta_s` and per pose against the
    camera's. Raises EvaluationError as `metrics.evaluate` does."""
    published = evaluate(groundtruth, estimate, max_diff, rpe_delta_s)
    camera_gt = camera_groundtruth(groundtruth, frame)
    corrected = published if camera_gt is groundtruth else evaluate(camera_gt, estimate, max_diff, rpe_delta_s)
    rpe_frame = relative_pose_error(camera_gt, estimate, RpeMode.FIXED_FRAMES, delta_frames=1)
    return FramedEvaluation(frame, published, corrected, rpe_frame)
