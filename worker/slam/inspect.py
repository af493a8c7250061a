"""A summary of a sequence folder: the figures `vtdslam inspect` and the upload page show."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from worker.slam.camera import Camera, parse_camera
from worker.slam.io.sequence import Sequence


def inspect_sequence(folder: Path, camera: str | dict | Camera | None = None, samples: int = 10) -> dict:
    """Frames, duration, depth validity (fraction of valid pixels over evenly spaced samples), GT coverage."""
    cam = camera if isinstance(camera, Camera) or camera is None else parse_camera(camera)
    seq = Sequence(folder, cam)
    picks = np.unique(np.linspace(0, len(seq) - 1, max(1, min(samples, len(seq)))).round().astype(int))
    valid, medians = [], []
    for i in picks:
        depth = seq[int(i)].depth
        ok = depth > 0
        valid.append(float(ok.mean()))
        if ok.any():
            medians.append(float(np.median(depth[ok])))
    gt_idx, _ = seq.groundtruth_for_frames()
    c = seq.camera
    return {
        "frames": len(seq),
        "rgb_listed": seq.n_rgb,
        "depth_listed": seq.n_depth,
        "duration_s": round(seq.duration, 3),
        "fps": round((len(seq) - 1) / seq.duration, 2) if seq.duration > 0 else None,
        "resolution": f"{c.width}x{c.height}",
        "depth_valid": round(float(np.mean(valid)), 4),
        "depth_median_m": round(float(np.median(medians)), 3) if medians else None,
        "groundtruth": seq.groundtruth is not None,
        "gt_poses": len(seq.groundtruth) if seq.groundtruth is not None else 0,
        "gt_coverage": round(len(gt_idx) / len(seq), 4),
        "camera": f"{c.name} ({seq.camera_source}) fx={c.fx:g} fy={c.fy:g} cx={c.cx:g} cy={c.cy:g} "
                  f"scale={c.depth_scale:g}" + ("" if c.depth_registered else " depth not registered to colour"),
    }
