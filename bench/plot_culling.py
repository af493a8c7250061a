"""Why the adaptive threshold: per frame, the motion scores d of matched points on static and on moving pixels
(truth masks) against Δd = f(H) from the tracker's pose covariance. Writes a PNG and prints a summary table.

    .venv/bin/python bench/plot_culling.py SEQ_WITH_TRUTH --camera 7scenes --out culling.png [--max-frames 300]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worker.slam.camera import parse_camera  # noqa: E402
from worker.slam.dynamic.stage import CullingStage  # noqa: E402
from worker.slam.io.sequence import Sequence  # noqa: E402
from worker.slam.pipeline import run_pipeline  # noqa: E402
from worker.slam.presets import get_preset  # noqa: E402
from worker.slam.segmentation.stage import SegmentationStage  # noqa: E402
from worker.slam.truth import load_truth  # noqa: E402


class Recorder:
    """Wraps the culling stage and keeps, per frame, the scores of matches on static / moving truth pixels."""

    name = "culling"

    def __init__(self, stage: CullingStage, truth) -> None:
        self.stage, self.truth = stage, truth
        self.history_frames = stage.history_frames  # the past frames culling reads from the run's history
        self.rows: list[tuple[int, float, np.ndarray, np.ndarray]] = []

    def process(self, frame, inputs, ctx):
        inputs = self.stage.process(frame, inputs, ctx)
        res = self.stage.last
        if res is not None:
            mask = self.truth.mask(frame.index)
            h, w = mask.shape
            p = np.rint(res.cur_points).astype(int)
            on = mask[p[:, 1].clip(0, h - 1), p[:, 0].clip(0, w - 1)]
            self.rows.append((frame.index, res.threshold_px, res.scores[~on], res.scores[on]))
        return inputs

    def summary(self) -> dict:
        return self.stage.summary()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequence", type=Path)
    ap.add_argument("--camera", default=None)
    ap.add_argument("--out", type=Path, default=Path("culling.png"))
    ap.add_argument("--max-frames", type=int, default=300)
    args = ap.parse_args()
    seq = Sequence(args.sequence, parse_camera(args.camera) if args.camera else None)
    truth = load_truth(args.sequence)
    if truth is None:
        raise SystemExit(f"{args.sequence} has no truth/ folder")
    cfg = get_preset("no-restoration")
    rec = Recorder(CullingStage(cfg, seq.camera), truth)
    run_pipeline(seq, cfg, None, max_frames=args.max_frames, stages=[SegmentationStage(cfg, seq.camera), rec])

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    idx = np.array([r[0] for r in rec.rows])
    thr = np.array([r[1] for r in rec.rows])
    med = lambda a: float(np.median(a)) if len(a) else np.nan  # noqa: E731
    p90 = lambda a: float(np.percentile(a, 90)) if len(a) else np.nan  # noqa: E731
    st_med, st_p90 = np.array([med(r[2]) for r in rec.rows]), np.array([p90(r[2]) for r in rec.rows])
    dy_med = np.array([med(r[3]) for r in rec.rows])
    fig, ax = plt.subplots(figsize=(10, 4.5), dpi=110)
    ax.plot(idx, st_med, color="0.45", lw=1, label="static points: median d")
    ax.plot(idx, st_p90, color="0.7", lw=1, ls="--", label="static points: 90th percentile d")
    ax.plot(idx, dy_med, color="tab:red", lw=1, label="points on moving people: median d")
    ax.plot(idx, thr, color="tab:blue", lw=2, label="adaptive threshold Δd = f(H)")
    ax.set_yscale("log")
    ax.set_xlabel("frame")
    ax.set_ylabel("epipolar / reprojection score d (px)")
    ax.set_title(f"{args.sequence.name}: motion scores vs the adaptive threshold (10-frame baseline)")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out)
    has = ~np.isnan(dy_med)
    print("| frames | Δd median (px) | Δd range | static median d | static p90 d | moving median d "
          "| frames where moving median > Δd |")
    print("|---|---|---|---|---|---|---|")
    print(f"| {len(idx)} | {np.median(thr):.2f} | {thr.min():.2f}–{thr.max():.2f} | {np.nanmedian(st_med):.2f} | "
          f"{np.nanmedian(st_p90):.2f} | {np.nanmedian(dy_med):.2f} | "
          f"{np.sum(dy_med[has] > thr[has])}/{has.sum()} |")
    print(f"plot: {args.out}")


if __name__ == "__main__":
    main()
