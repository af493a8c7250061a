"""A run's files in its output folder (names from `formats.artifacts`)."""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from formats import artifacts
from formats.frame_stats import write_frame_stats
from formats.ply import write_ply
from formats.run_metrics import RunMetrics, write_run_metrics
from formats.version import provenance
from worker.slam.config import PipelineConfig
from worker.slam.io.trajectory import write_tum_trajectory
from worker.slam.run.result import RunResult


def write_outputs(result: RunResult, config: PipelineConfig, out: Path) -> None:
    """trajectory.txt (the tracked frames' poses), keyframes.txt (TUM), map.ply, metrics.json, config.json (both
    with the code's ``version`` and ``commit``), the
    aligned ground truth when there is one, the frame statistics and the preview images (JPEG)."""
    out.mkdir(parents=True, exist_ok=True)
    lost = int((~result.tracked).sum())
    write_tum_trajectory(out / artifacts.TRAJECTORY, result.trajectory,
                         header="VTD-SLAM trajectory T_WC (every frame)" if not lost else
                         f"VTD-SLAM trajectory T_WC (the tracked frames; {lost} of {len(result.tracked)} not tracked)")
    write_tum_trajectory(out / artifacts.KEYFRAMES, result.keyframes, header="VTD-SLAM keyframes T_WC")
    xyz, rgb = result.cloud if result.cloud is not None else (np.zeros((0, 3)), np.zeros((0, 3), np.uint8))
    write_ply(out / artifacts.MAP, xyz, rgb)
    write_run_metrics(out / artifacts.METRICS, RunMetrics.from_dict(result.metrics))
    # the config, then the code that ran it (`Catalog.config_from_dict` reads the file back, ignoring those two)
    (out / artifacts.CONFIG).write_text(json.dumps({**config.to_dict(), **provenance()}, indent=2))
    if result.aligned_groundtruth is not None:
        write_tum_trajectory(out / artifacts.GROUNDTRUTH_ALIGNED, result.aligned_groundtruth,
                             header="ground truth T_WC aligned onto the estimate (SE(3) Umeyama)")
    write_frame_stats(out / artifacts.FRAME_STATS, result.frame_stats)
    for index, images in result.previews.items():
        for kind, img in images.items():
            cv2.imwrite(str(out / artifacts.frame_image(index, kind)), cv2.cvtColor(img, cv2.COLOR_RGB2BGR),
                        [cv2.IMWRITE_JPEG_QUALITY, 85])
