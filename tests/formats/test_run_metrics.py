import json
import math
from pathlib import Path

import pytest

from formats.errors import FormatError
from formats.run_metrics import (
    ErrorStats,
    RunMetrics,
    format_run_metrics,
    read_run_metrics,
    with_current_spelling,
    write_run_metrics,
)

STATS = {"rmse": 0.03, "mean": 0.02, "median": 0.02, "std": 0.01, "max": 0.06}
PIPELINE = {  # a metrics.json as run_pipeline writes it, key order included
    "frames": 30, "tracked": 29, "lost": 1, "relocalisations": 0, "new_maps": 0, "map_merges": 0,
    "established_switches": 0, "rescued_frames": 0, "last_pose_retries": 0, "frames_refit": 28, "frames_smoothed": 28,
    "keyframes": 2,
    "map_points": 656, "fused_observations": 0, "loops": 0, "loops_applied": 0, "fps": 6.76, "tracking_fps": None,
    "tracking_cpu_ms": 18.885, "timings_ms": {"read": 0.396, "tracking": 33.5}, "overlapped_stages": ["culling"],
    "dense_points": 13879, "stage_info": {"features_removed": 23.1}, "peak_rss_mb": 731.9,
    "camera": {"fx": 535.4, "dist": [0.0, 0.0], "name": "synthetic"}, "preset": "full", "start": 0,
    "tracked_fraction": 0.9667, "warnings": ["1 of 30 frames (3.3 %) were not tracked"], "smoothing_skipped": None,
    "version": "0.1.0", "commit": "8bdf8d68c02ddbe3c3f56e9aae6238f801917b4f",
    "culling": {"features_removed": 694, "truth": {"mask_iou": 0.17, "feature_precision": 0.85,
                                                   "feature_recall": 0.72, "frames_scored": {"mask": 29}}},
    "restoration": {"references": "both-sided", "truth": {"restoration_psnr": 20.5}},
    "ate": STATS, "matched_poses": 29,
    "rpe": {"mode": "fixed-delta", "delta_s": 1, "max_pairs": 0, "pairs": 12, "trans": STATS,
            "rot_deg": {**STATS, "rmse": 0.4}},
}


def test_pipeline_metrics_round_trip_byte_for_byte(tmp_path: Path):
    m = RunMetrics.from_dict(PIPELINE)
    assert format_run_metrics(m) == json.dumps(PIPELINE, indent=2)  # same keys, order, values (1 stays 1)
    assert list(m.stages) == ["culling", "restoration"] and m.ate == ErrorStats(**STATS)
    assert m.rpe is not None and m.rpe.rot_deg.rmse == 0.4 and m.rpe.delta_s == 1
    write_run_metrics(tmp_path / "metrics.json", m)
    assert read_run_metrics(tmp_path / "metrics.json") == m


def test_evaluation_error_nan_and_unknown_keys_are_kept():
    blob = {**{k: v for k, v in PIPELINE.items() if k not in ("ate", "matched_poses", "rpe")},
            "evaluation_error": "only 2 poses associate", "future_key": 3}
    blob["fps"] = math.nan
    assert format_run_metrics(RunMetrics.from_dict(blob)) == json.dumps(blob, indent=2)


def test_old_rpe_spellings_and_garbage_are_read():
    flat = RunMetrics.from_dict({"rpe": {"trans_rmse": 1, "rot_rmse": "2"}, "ate": "n/a", "tracked": "3"})
    assert flat.rpe is not None and (flat.rpe.trans.rmse, flat.rpe.rot_deg.rmse) == (1, 2.0)
    assert flat.ate is None and flat.tracked == 3 and flat.fps is None and flat.timings_ms == {}
    old = RunMetrics.from_dict({"rpe": {"trans": {"rmse": 0.011}, "rot": {"rmse": 0.3}}})
    assert old.rpe is not None and (old.rpe.trans.rmse, old.rpe.rot_deg.rmse) == (0.011, 0.3)


def test_truth_scores():
    assert RunMetrics.from_dict(PIPELINE).truth_scores().restoration_psnr == 20.5
    assert RunMetrics.from_dict(PIPELINE).truth_scores().mask_iou == 0.17
    assert RunMetrics.from_dict({"culling": {"truth": {"mask_iou": None}}}).truth_scores().mask_iou is None


def test_reader_rejects_non_objects(tmp_path: Path):
    (tmp_path / "m.json").write_text("[1]")
    with pytest.raises(FormatError, match="object"):
        read_run_metrics(tmp_path / "m.json")
    (tmp_path / "m.json").write_text("{")
    with pytest.raises(FormatError, match="not JSON"):
        read_run_metrics(tmp_path / "m.json")


def test_current_spelling_extends_old_rpe_and_leaves_current_blobs_alone():
    assert with_current_spelling(PIPELINE) == PIPELINE
    old = {"fps": 1.0, "rpe": {"trans": {"rmse": 0.011}, "rot": {"rmse": 0.3}}}
    got = with_current_spelling(old)
    assert got["rpe"]["rot"] == {"rmse": 0.3} and got["rpe"]["trans"] == {"rmse": 0.011}  # nothing renamed
    assert got["rpe"]["rot_deg"]["rmse"] == 0.3 and old["rpe"].keys() == {"trans", "rot"}  # the input is untouched
    assert with_current_spelling({"rpe": {"trans_rmse": 1}})["rpe"]["trans"]["rmse"] == 1


def test_groundtruth_frame_keys_round_trip_in_the_pipelines_order():
    """A Bonn run: `ate` in the published convention, `ate_corrected`, `rpe`/`rpe_frame` against the camera."""
    corrected = "camera (corrected from bonn-marker)"
    blob = {**PIPELINE, "groundtruth_frame": "bonn-marker",
            "ate_against": "bonn-marker (raw ground truth, published convention)",
            "ate_corrected_against": corrected, "rpe_against": corrected, "ate_corrected": {**STATS, "rmse": 0.031},
            "rpe_frame": {"mode": "fixed-frames", "delta_s": None, "max_pairs": 0, "pairs": 27, "trans": STATS,
                          "rot_deg": STATS, "delta_frames": 1}}
    m = RunMetrics.from_dict(blob)
    assert format_run_metrics(m) == json.dumps(blob, indent=2)
    assert m.stages.keys() == {"culling", "restoration"} and not m.extra
    assert m.groundtruth_frame == "bonn-marker" and m.rpe_against == corrected
    assert m.ate_corrected is not None and m.ate_corrected.rmse == 0.031
    assert m.rpe_frame is not None and m.rpe_frame.delta_frames == 1 and m.rpe_frame.mode == "fixed-frames"
    old = RunMetrics.from_dict(PIPELINE)  # a run made before the frame was recorded
    assert old.groundtruth_frame is None and old.ate_corrected is None and old.rpe_frame is None


def test_version_and_commit_are_read_and_an_older_run_gains_neither():
    m = RunMetrics.from_dict(PIPELINE)
    assert m.version == "0.1.0" and m.commit == PIPELINE["commit"] and "version" not in m.extra
    outside = {**PIPELINE, "commit": None}  # a run outside a git checkout: the key stays, null
    assert json.loads(format_run_metrics(RunMetrics.from_dict(outside)))["commit"] is None
    older = {k: v for k, v in PIPELINE.items() if k not in ("version", "commit")}
    assert format_run_metrics(RunMetrics.from_dict(older)) == json.dumps(older, indent=2)
