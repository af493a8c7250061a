"""Frames per second of the dynamic-sequence generators at 640x480, as a markdown table.

    .venv/bin/python bench/bench_generators.py [--frames 60]

Rows: synthetic rendering alone (room + walkers + Kinect model, in memory), synthetic generation to disk
(PNG encoding included), augmented-real compositing alone and to disk (needs ../shared or VTD_SHARED_DIR).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def timed(fn, n: int) -> float:
    t = time.perf_counter()
    fn()
    return n / (time.perf_counter() - t)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--people", type=int, default=2)
    args = ap.parse_args()
    n = args.frames
    from worker.slam.synth.generator import SynthConfig, SyntheticWorld, generate_synthetic

    shared = Path(os.environ.get("VTD_SHARED_DIR", Path(__file__).resolve().parents[2] / "shared"))
    rows = []
    for path in ("walk", "auto"):
        cfg = SynthConfig(frames=n, people=args.people, trajectory=path, shared_dir=shared)
        world = SyntheticWorld(cfg)
        world.frame(0)  # warm-up
        fps = timed(lambda w=world: [w.frame(i) for i in range(n)], n)
        rows.append((f"synth render ({world.source.split(':')[0]}, {args.people} people)", fps))
    with tempfile.TemporaryDirectory() as tmp:
        cfg = SynthConfig(frames=n, people=args.people, trajectory="walk")
        rows.append(("synth generate to disk (5 PNGs/frame)", timed(lambda: generate_synthetic(tmp, cfg), n)))
    seq, coco = shared / "data/7scenes_redkitchen", shared / "data/coco128_seg"
    if (seq / "rgb.txt").is_file() and (coco / "labels").is_dir():
        from worker.slam.augment.generator import AugmentConfig, AugmentedSequence, generate_augmented

        acfg = AugmentConfig(frames=n, people=args.people)
        aug = AugmentedSequence(seq, coco, acfg)
        rows.append((f"augment composite (7-Scenes, {args.people} people)",
                     timed(lambda: [aug.frame(i) for i in range(n)], n)))
        with tempfile.TemporaryDirectory() as tmp:
            rows.append(("augment generate to disk", timed(lambda: generate_augmented(seq, coco, tmp, acfg), n)))
    else:
        rows.append(("augment (no ../shared data)", float("nan")))
    print(f"| generator ({n} frames, 640x480) | frames/s |\n|---|---:|")
    for name, fps in rows:
        print(f"| {name} | {fps:.1f} |")


if __name__ == "__main__":
    main()
