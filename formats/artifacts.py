"""Names of the files a run writes into its output folder (the artifact store keeps them flat, one folder a run)."""

from __future__ import annotations

import re

TRAJECTORY = "trajectory.txt"
"""Every tracked frame's pose, TUM format (formats.trajectory); a frame never tracked has none."""
KEYFRAMES = "keyframes.txt"
"""The keyframes' poses, TUM format."""
MAP = "map.ply"
"""The dense map (formats.ply)."""
METRICS = "metrics.json"
"""The run's figures, ATE and RPE (formats.run_metrics)."""
CONFIG = "config.json"
"""The full config snapshot the run used."""
GROUNDTRUTH_ALIGNED = "groundtruth_aligned.txt"
"""Ground truth expressed in the estimate's frame (only when the sequence has ground truth)."""
FRAME_STATS = "frame_stats.csv"
"""Per-frame figures (formats.frame_stats)."""
LOG = "log.txt"
"""The worker's log lines of the job."""
PREVIEW = "preview.png"
"""The top view of the trajectory the dashboard shows before the 3D viewer loads."""

PLOT_TRAJECTORY_TOP = "plot_trajectory_top.png"
"""Figure: the estimate (and the aligned ground truth) seen from above, the x-z plane."""
PLOT_XYZ = "plot_xyz.png"
"""Figure: x, y and z over time, estimate against aligned ground truth."""
PLOT_ATE_ERROR = "plot_ate_error.png"
"""Figure: the absolute trajectory error per pose over time (only with ground truth)."""
PLOT_TIMINGS = "plot_timings.png"
"""Figure: mean time per pipeline stage."""
FIGURES = (PLOT_TRAJECTORY_TOP, PLOT_XYZ, PLOT_ATE_ERROR, PLOT_TIMINGS)
"""The figures a run (``vtdslam run``, a job) and ``vtdslam eval --plot`` write, those that have data."""

PIPELINE_OUTPUTS = (TRAJECTORY, KEYFRAMES, MAP, METRICS, CONFIG)
"""What every pipeline run writes (``vtdslam run`` and a job alike)."""

PARTIAL_STATE = "partial.json"
"""While a job runs: its latest frames (index, timestamp, arrival, position, tracked) and counts (worker.snapshots)."""
PARTIAL_TRAJECTORY = "partial_trajectory.txt"
"""While a job runs: the tracked frames' poses so far, as tracked (TUM)."""
PARTIAL_KEYFRAMES = "partial_keyframes.txt"
"""While a job runs: the keyframes so far (TUM)."""
PARTIAL_MAP = "partial_map.ply"
"""While a job runs: the map so far (the keyframes' points at their current poses, formats.ply)."""
PARTIAL_FRAME_RGB = "partial_frame_rgb.jpg"
"""While a job runs: the latest snapshot's colour image."""
PARTIAL_FRAME_MASK = "partial_frame_mask.jpg"
"""While a job runs: the latest snapshot's frame with its masks: coloured by segmentation class (potentially dynamic
classes strongly, the others faintly; partial.json's ``frame_legend`` lists them), the moving pixels outlined in red;
without classes, potentially dynamic pixels yellow and moving ones red."""
PARTIALS = (PARTIAL_STATE, PARTIAL_TRAJECTORY, PARTIAL_KEYFRAMES, PARTIAL_MAP, PARTIAL_FRAME_RGB, PARTIAL_FRAME_MASK)
"""The snapshot files of a running job; removed when it ends (its final artifacts replace them)."""

_FRAME_IMAGE = re.compile(r"^frame_(\d{6,})_([a-z]+)\.(jpg|png)$")


def frame_image(index: int, kind: str) -> str:
    """The name of frame ``index``'s preview image of ``kind`` (rgb, classes, mask, restored)."""
    return f"frame_{index:06d}_{kind}.jpg"


def parse_frame_image(name: str) -> tuple[int, str] | None:
    """(index, kind) of a :func:`frame_image` name (``.png`` accepted too); None for any other name."""
    m = _FRAME_IMAGE.match(name)
    return (int(m.group(1)), m.group(2)) if m else None
