"""MSNET against the TFLite teachers on the real held-out person sets (issue 20), as a markdown table.

    .venv/bin/python bench/bench_msnet.py [--threads 1] [--checkpoint PT] [--no-teachers]
        [--cache /tmp/vtd_msnet_refs] [--overlays DIR] [--guided] [--bonn-every 10] [--sequence AUG_DIR ...]
        [--every 10] [--frames 300]

Sets (`worker/slam/segmentation/heldout.py`): COCO128 held-out, the CCP test split, the TUM walking_xyz frame,
every 10th bonn_crowd_dev frame against reference masks made by the int8 DeepLabV3 at 513 (cached in --cache,
outside the repo; that model's own Bonn column is therefore 1.0 by construction and measures nothing) and the
people-free 7-Scenes frames 900-999 (share of pixels marked potentially dynamic), and davis_movers_dev (the
mover against the potentially dynamic mask). Each cell: IoU (precision / recall), pixels pooled over the set.
The 21-class teacher row is the 257 teacher with all VOC classes, its default potentially dynamic classes marked.
`ms` is the median `segment()` time on the 640x480 Bonn frames (resize in, full-resolution labels out), all
models in the same run, on --threads threads.
With `--sequence` (generated sequences with truth), the pooled IoU, precision and recall of the potentially
dynamic mask against the true masks on every n-th frame. Timings on a shared machine vary with its load: the
load average is printed.
"""
from __future__ import annotations

import argparse
import os
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

TEACHERS = {
    "DeepLabV3-MNv2 257 (teacher)": "deeplabv3_257_mv_gpu.tflite",
    "DeepLabV3-MNv2 513 int8 (Bonn reference)": "deeplabv3_mnv2_pascal_quant.tflite",
    "MediaPipe selfie": "selfie_segmentation.tflite",
}


def pooled_scores(pairs) -> tuple[float, float, float]:
    """IoU, precision and recall of predicted masks against true ones, pixels pooled over (pred, truth) pairs."""
    import numpy as np

    inter = pred = true = 0
    for a, b in pairs:
        inter += int(np.logical_and(a, b).sum())
        pred += int(a.sum())
        true += int(b.sum())
    union = pred + true - inter
    nan = float("nan")
    return (inter / union if union else nan, inter / pred if pred else nan, inter / true if true else nan)


def cell(s) -> str:
    f = lambda v: "n/a" if v is None else f"{v:.3f}"  # noqa: E731
    if s.iou is None and s.recall is None:  # a people-free set
        return f"{100 * s.marked:.2f} % marked"
    return f"{f(s.iou)} ({f(s.precision)} / {f(s.recall)})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=Path(os.environ.get("VTD_SHARED_DIR", "../shared")))
    ap.add_argument("--checkpoint", type=Path, default=None, help="MSNET weights (default: shipped)")
    ap.add_argument("--no-teachers", action="store_true", help="MSNET only (e.g. comparing checkpoints)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/vtd_msnet_refs"),
                    help="where the Bonn reference masks are made once (never inside the repo)")
    ap.add_argument("--bonn-every", type=int, default=10)
    ap.add_argument("--guided", action="store_true", help="also MSNET with guided upsampling (the option)")
    ap.add_argument("--overlays", type=Path, default=None,
                    help="write overlay PNGs (3 images per set, spread over it) here")
    ap.add_argument("--sequence", type=Path, action="append", default=[],
                    help="a sequence with truth masks (`vtdslam augment` / `synth` output); repeatable")
    ap.add_argument("--every", type=int, default=10, help="use every n-th frame of the first --frames")
    ap.add_argument("--frames", type=int, default=300)
    args = ap.parse_args()

    import cv2
    import torch

    from worker.slam.camera import parse_camera
    from worker.slam.io.images import read_rgb
    from worker.slam.io.sequence import Sequence
    from worker.slam.segmentation import SegmenterConfig, make_segmenter
    from worker.slam.segmentation.evaluate import overlay
    from worker.slam.segmentation.guided import CHOSEN_RADIUS
    from worker.slam.segmentation.heldout import build_sets, score_set
    from worker.slam.truth import load_truth

    torch.set_num_threads(args.threads)
    cv2.setNumThreads(args.threads)
    if args.cache.resolve().is_relative_to(Path(__file__).resolve().parents[1]):
        ap.error("--cache must be outside the repository (reference masks are never committed)")
    sets = build_sets(args.shared, args.cache, args.bonn_every)
    truth_frames = []  # (rgb, true dynamic mask) of every n-th frame of the given sequences
    for root in args.sequence:
        seq, truth = Sequence(root, parse_camera("7scenes")), load_truth(root)
        if truth is None:
            ap.error(f"{root} has no truth/ folder")
        truth_frames += [(read_rgb(seq.frames[i].rgb_path), truth.mask(i))  # RGB only: depth is not needed
                         for i in range(0, min(args.frames, len(seq)), args.every)]

    ckpt = str(args.checkpoint) if args.checkpoint else None
    segmenters = {"MSNET (ours)": make_segmenter(SegmenterConfig(checkpoint=ckpt, device="cpu",
                                                                 threads=args.threads))}
    if args.guided:
        segmenters["MSNET + guided upsampling (option)"] = make_segmenter(SegmenterConfig(
            checkpoint=ckpt, device="cpu", threads=args.threads, guided_radius=CHOSEN_RADIUS))
    for name, file in ({} if args.no_teachers else TEACHERS).items():
        if (args.shared / "models" / file).is_file():
            segmenters[name] = make_segmenter(SegmenterConfig(
                backend="tflite-teacher", model_path=str(args.shared / "models" / file), threads=args.threads))
    voc_teacher = args.shared / "models" / TEACHERS["DeepLabV3-MNv2 257 (teacher)"]
    # all 21 VOC classes, the default potentially dynamic ones marked (issue 57)
    if voc_teacher.is_file() and not args.no_teachers:
        segmenters["DeepLabV3-MNv2 257 (teacher), 21 classes"] = make_segmenter(SegmenterConfig(
            backend="tflite-teacher", model_path=str(voc_teacher), threads=args.threads, full_voc=True))

    rows = []
    for name, seg in segmenters.items():
        scores = {s.name: score_set(seg, s) for s in sets}
        aug = pooled_scores([(seg.segment(rgb).dynamic_mask(), gt) for rgb, gt in truth_frames]) \
            if truth_frames else None
        rows.append((name, scores, aug))
        if args.overlays:
            args.overlays.mkdir(parents=True, exist_ok=True)
            tag = re.sub(r"\W+", "_", name.split("(")[0].strip().lower())
            for s in sets:
                for k, item in enumerate(s.images[::max(len(s.images) // 3, 1)][:3]):  # spread out
                    rgb = read_rgb(item.image)
                    res = seg.segment(rgb)
                    out = overlay(rgb, res.labels, res.classes)
                    cv2.imwrite(str(args.overlays / f"{s.name}_{k}_{tag}.png"), cv2.cvtColor(out, cv2.COLOR_RGB2BGR))

    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs; {args.threads} thread(s); "
          f"{sum(len(s.images) for s in sets)} images")
    for s in sets:
        print(f"- {s.name}: {len(s.images)} images ({s.note})")
    if truth_frames:
        print(f"- sequences with truth: {len(truth_frames)} frames (every {args.every}th of the first {args.frames}"
              f" of {', '.join(p.name for p in args.sequence)}); each model's potentially dynamic mask")
    print()
    ref = next((sc["bonn-crowd"].ms_median for n, sc, _ in rows if n.endswith("(teacher)")), None)
    print("| model | " + " | ".join(s.name for s in sets) + (" | sequences" if truth_frames else "")
          + " | ms/frame 640x480 | × teacher's time |")
    print("|---|" + "---|" * (len(sets) + 2 + bool(truth_frames)))
    for name, scores, aug in rows:
        seqs = f" | {aug[0]:.3f} ({aug[1]:.2f} / {aug[2]:.2f})" if aug else ""
        ms = scores["bonn-crowd"].ms_median
        ratio = f"{ms / ref:.2f}" if ref else "–"
        print(f"| {name} | " + " | ".join(cell(scores[s.name]) for s in sets) + f"{seqs} | {ms:.1f} | {ratio} |")


if __name__ == "__main__":
    main()
