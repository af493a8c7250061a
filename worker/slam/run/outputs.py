"""A run's files in its output folder (names from `formats.artifacts`)."""
from __future__ import annotations

import json
import logging
from pathlib import Path

import cv2
import numpy as np

from formats import artifacts
from formats.frame_stats import write_frame_stats
from formats.ply import write_ply
from formats.run_metrics import RunMetrics, write_run_metrics
from formats.version import provenance
from worker.slam.config import PipelineConfig
from worker.slam.evaluation.plots import write_figures
from worker.slam.io.trajectory import write_tum_trajectory
from worker.slam.run.result import RunResult

log = logging.getLogger(__name__)


def write_outputs(result: RunResult, config: PipelineConfig, out: Path) -> None:
    """trajectory.txt (the tracked frames' poses), keyframes.txt (TUM), map.ply, metrics.json and config.json (both
    with the code's ``version`` and ``commit``), the aligned ground truth when there is one, the frame statistics,
    the preview images (JPEG) and the figures (`artifacts.FIGURES`, PNG). A figure that cannot be drawn is logged
    and named in metrics.json's warnings; it never fails the run."""
    out.mkdir(parents=True, exist_ok=True)
    lost = int((~result.tracked).sum())
    write_tum_trajectory(out / artifacts.TRAJECTORY, result.trajectory,
                         header="VTD-SLAM trajectory T_WC (every frame)" if not lost else
                         f"VTD-SLAM trajectory T_WC (the tracked frames; {lost} of {len(result.tracked)} not tracked)")
    write_tum_trajectory(out / artifacts.KEYFRAMES, result.keyframes, header="VTD-SLAM keyframes T_WC")
    xyz, rgb = result.cloud if result.cloud is not None else (np.zeros((0, 3)), np.zeros((0, 3), np.uint8))
    write_ply(out / artifacts.MAP, xyz, rgb)
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
    metrics = result.metrics
    warning = _write_figures(result, out)
    if warning is not None:
        metrics = {**metrics, "warnings": [*metrics.get("warnings", []), warning]}
    write_run_metrics(out / artifacts.METRICS, RunMetrics.from_dict(metrics))


def _write_figures(result: RunResult, out: Path) -> str | None:
    """The run's figures; the warning to record when they could not be drawn (None: they were)."""
    try:
        rows = [r for r in result.frame_stats if r.get("ate_error") is not None and r.get("timestamp") is not None]
        errors = (np.array([float(r["timestamp"]) for r in rows]), np.array([float(r["ate_error"]) for r in rows]))
        write_figures(out, result.trajectory, result.aligned_groundtruth, errors if rows else None,
                      result.metrics.get("timings_ms"))
    except Exception as exc:  # noqa: BLE001 - figures are for looking at: never worth a failed run
        log.warning("figures not drawn: %s: %s", type(exc).__name__, exc, exc_info=True)
        return f"figures not drawn: {type(exc).__name__}: {exc}"
    return None
