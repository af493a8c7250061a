"""The pipelined worker against the plain one, interleaved on the same frames; print markdown.

    .venv/bin/python bench/bench_pipelined.py --max-frames 150 --reps 2

Variants (issue 23): `plain` (segmentation on the tracking thread, every frame with a hole restored) against
`pipelined` (segmentation of frame k+1 on its own thread while frame k is culled and tracked, restoration only
for keyframes, previews and frames whose keypoint depth reads the hole), on `no-restoration` and `full`, with
`orb-only` in every repetition for the ratio. Runs alternate, so a shared machine's load falls on both alike;
each run is its own spawned process. The table gives every run's fps, fps / orb-only of the same repetition and
the load around it, and whether trajectory.txt, keyframes.txt and map.ply are byte-identical to `plain`'s.
Benchmarks print figures; they assert nothing.
"""
from __future__ import annotations

import argparse
import filecmp
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from bench_realtime import _in_child, _shared, _synth  # noqa: E402
from sequence_spec import split_spec  # noqa: E402

VARIANTS: dict[str, tuple[dict[str, Any], bool]] = {
    # name: (config overrides, prepare_ahead)
    "plain": ({"restoration.on_demand": False}, False),
    "pipelined": ({"restoration.on_demand": True}, True),
}
OUTPUTS = ("trajectory.txt", "keyframes.txt", "map.ply")


def run_variant(seq_dir: str, camera: str | None, preset: str, overrides: dict, prepare_ahead: bool, max_frames: int,
                out: str) -> dict:
    """Child process: one pipeline run writing its outputs to `out`; its metrics."""
    from sequence_spec import camera_of

    from worker.slam.io.sequence import Sequence
    from worker.slam.pipeline import run_pipeline
    from worker.slam.presets import get_preset

    cfg = get_preset(preset, overrides if preset != "orb-only" else None)
    res = run_pipeline(Sequence(seq_dir, camera_of(camera)), cfg, out, max_frames=max_frames,
                       prepare_ahead=prepare_ahead)
    return res.metrics


def _f(x: float | None, nd: int = 2) -> str:
    return "-" if x is None else f"{x:.{nd}f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--sequence", action="append", help="DIR[:CAMERA] (default: bonn_crowd_dev:bonn from "
                    "../shared and the synthetic room)")
    ap.add_argument("--presets", default="no-restoration,full")
    ap.add_argument("--max-frames", type=int, default=150)
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--no-synth", action="store_true")
    args = ap.parse_args()
    presets = args.presets.split(",")
    print("| sequence | rep | preset | variant | fps | fps / orb-only | restoration ms/frame | frames restored "
          "| segmentation ms (wait) | outputs as plain | load 1 min (before → after) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        seqs = list(args.sequence or [f"{_shared() / 'data' / 'bonn_crowd_dev'}:bonn"])
        if not args.no_synth:
            seqs.append(_synth(work, args.max_frames))
        for spec in seqs:
            seq_dir, camera = split_spec(spec)
            name = Path(seq_dir).name
            for rep in range(args.reps):
                load = os.getloadavg()[0]
                orb = _in_child(run_variant, seq_dir, camera, "orb-only", {}, True, args.max_frames,
                                str(work / f"{name}-{rep}-orb"))
                print(f"| {name} | {rep + 1} | orb-only | - | {_f(orb['fps'])} | 1.00 | - | - | - | - "
                      f"| {load:.2f} → {os.getloadavg()[0]:.2f} |", flush=True)
                for preset in presets:
                    for variant, (overrides, ahead) in VARIANTS.items():
                        out = work / f"{name}-{rep}-{preset}-{variant}"
                        load = os.getloadavg()[0]
                        m = _in_child(run_variant, seq_dir, camera, preset, overrides, ahead, args.max_frames,
                                      str(out))
                        plain = work / f"{name}-{rep}-{preset}-plain"
                        same = all(filecmp.cmp(plain / f, out / f, shallow=False) for f in OUTPUTS)
                        t, rest = m["timings_ms"], m.get("restoration", {})
                        seg = (f"{_f(t.get('segmentation'), 1)} ({_f(t.get('segmentation_wait'), 1)})"
                               if "segmentation" in t else "-")
                        print(f"| {name} | {rep + 1} | {preset} | {variant} | {_f(m['fps'])} "
                              f"| {_f(m['fps'] / orb['fps'])} | {_f(t.get('restoration'), 1)} "
                              f"| {rest.get('restored_frames', '-')} | {seg} | {'identical' if same else 'DIFFER'} "
                              f"| {load:.2f} → {os.getloadavg()[0]:.2f} |", flush=True)


if __name__ == "__main__":
    main()
