"""MSNET against the TFLite teachers: accuracy on real frames and CPU latency at 640x480, as a markdown table.

    .venv/bin/python bench/bench_msnet.py [--threads 1] [--repeats 3] [--checkpoint PT] [--overlays /tmp/msnet_overlays]
        [--sequence AUG_DIR ...] [--every 10] [--frames 300]

Columns: person IoU on the TUM fr3 walking_xyz frame (reference mask in ../shared); person IoU and mIoU on the
held-out COCO128 split (every 5th image, never trained on); person agreement (IoU of the two person masks,
pooled over frames) with the DeepLabV3-257 teacher on the 10 fr3 walking_halfsphere frames (the `cpu-tum` recipe
trains on these frames with this teacher's labels, so for its checkpoint this column is a training-set figure,
not a held-out one; walking_xyz and the COCO held-out split are never trained on); with `--sequence`
(generated sequences with truth), the pooled IoU, precision and recall of the potentially dynamic mask against
the true masks on every n-th frame; median latency of `segment()` on 640x480 frames (resize in, full-resolution
labels and probabilities out). MSNET runs twice: as shipped (bilinear upsampling of its probabilities) and with
the optional guided upsampling (`guided_radius` 13, `guided.CHOSEN_RADIUS`).
Teachers missing from ../shared/models are skipped. Timings on a shared machine vary with its load: the load
average is printed.
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
    "DeepLabV3-MNv2 513 int8": "deeplabv3_mnv2_pascal_quant.tflite",
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


def pooled_iou(pairs) -> float:
    return pooled_scores(pairs)[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=Path(os.environ.get("VTD_SHARED_DIR", "../shared")))
    ap.add_argument("--checkpoint", type=Path, default=None, help="MSNET weights (default: shipped)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--overlays", type=Path, default=None, help="write overlay PNGs here")
    ap.add_argument("--sequence", type=Path, action="append", default=[],
                    help="a sequence with truth masks (`vtdslam augment` / `synth` output); repeatable")
    ap.add_argument("--every", type=int, default=10, help="use every n-th frame of the first --frames")
    ap.add_argument("--frames", type=int, default=300)
    args = ap.parse_args()

    import cv2
    import numpy as np
    import torch

    from worker.slam.camera import parse_camera
    from worker.slam.io.images import read_rgb
    from worker.slam.io.sequence import Sequence
    from worker.slam.segmentation import SegmenterConfig, make_segmenter
    from worker.slam.segmentation.guided import CHOSEN_RADIUS
    from worker.slam.segmentation.msnet.checkpoint import load_model
    from worker.slam.segmentation.evaluate import evaluate_segmenter, labelled_samples, measure_latency, overlay, \
        tum_person_mask
    from worker.slam.segmentation.train.datasets import load_yolo_seg, split_holdout
    from worker.slam.truth import load_truth

    torch.set_num_threads(args.threads)
    cv2.setNumThreads(args.threads)
    data = args.shared / "data"
    xyz = data / "tum_frames" / "fr3_walking_xyz"
    xyz_rgb = read_rgb(next(xyz.glob("rgb_*.png")))
    xyz_gt = tum_person_mask(cv2.imread(str(next(xyz.glob("person_mask_*.png"))), cv2.IMREAD_UNCHANGED))
    half = [read_rgb(p) for p in sorted((data / "tum_frames" / "fr3_walking_halfsphere").glob("*.png"))]
    held = split_holdout(load_yolo_seg(data / "coco128_seg", {0: "person", 56: "chair"}), 5)[1]
    classes = ("background", "person", "chair")
    truth_frames = []  # (rgb, true dynamic mask) of every n-th frame of the given sequences
    for root in args.sequence:
        seq, truth = Sequence(root, parse_camera("7scenes")), load_truth(root)
        if truth is None:
            ap.error(f"{root} has no truth/ folder")
        truth_frames += [(read_rgb(seq.frames[i].rgb_path), truth.mask(i))  # RGB only: depth is not needed
                         for i in range(0, min(args.frames, len(seq)), args.every)]

    ckpt = str(args.checkpoint) if args.checkpoint else None
    segmenters = {
        "MSNET (ours)": make_segmenter(SegmenterConfig(checkpoint=ckpt, device="cpu", threads=args.threads)),
        "MSNET + guided upsampling (option)": make_segmenter(SegmenterConfig(
            checkpoint=ckpt, device="cpu", threads=args.threads, guided_radius=CHOSEN_RADIUS)),
    }
    for name, file in TEACHERS.items():
        if (args.shared / "models" / file).is_file():
            segmenters[name] = make_segmenter(SegmenterConfig(
                backend="tflite-teacher", model_path=str(args.shared / "models" / file), threads=args.threads))
    teacher = next((s for n, s in segmenters.items() if "teacher" in n), None)
    teacher_half = [teacher.segment(f).class_mask("person") for f in half] if teacher else None

    rows = []
    for name, seg in segmenters.items():
        r_xyz = seg.segment(xyz_rgb)
        iou_xyz = pooled_iou([(r_xyz.class_mask("person"), xyz_gt)])
        m = evaluate_segmenter(seg, labelled_samples(held, classes), classes)
        half_res = [seg.segment(f) for f in half]
        agree = pooled_iou(zip((r.class_mask("person") for r in half_res), teacher_half)) if teacher_half else None
        lat = measure_latency(seg, half + [xyz_rgb], repeats=args.repeats)
        miou = np.mean([v for k, v in m.iou.items() if v is not None and k in seg.classes])
        pairs = [(seg.segment(rgb).dynamic_mask(), gt) for rgb, gt in truth_frames]
        aug = pooled_scores(pairs) if pairs else None
        rows.append((name, iou_xyz, m.iou["person"], miou, agree, aug, lat))
        if args.overlays:
            args.overlays.mkdir(parents=True, exist_ok=True)
            tag = re.sub(r"\W+", "_", name.split("(")[0].strip().lower())
            for i, (rgb, res) in enumerate([(xyz_rgb, r_xyz), (half[0], half_res[0]), (half[9], half_res[9])]):
                out = overlay(rgb, res.labels, res.classes)
                cv2.imwrite(str(args.overlays / f"{i}_{tag}.png"), cv2.cvtColor(out, cv2.COLOR_RGB2BGR))

    f = lambda v: "n/a" if v is None else f"{v:.3f}"  # noqa: E731
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs; {args.threads} thread(s); "
          f"COCO128 held-out: {len(held)} images; halfsphere: {len(half)} frames")
    targets = load_model(args.checkpoint)[1].get("train_config", {}).get("target_frames") or []
    if targets:
        print(f"MSNET was trained on {', '.join(targets)} with teacher labels: its halfsphere agreement is a "
              "TRAINING-set figure, not a held-out one.")
    print()
    if truth_frames:
        print(f"Sequences with truth: {len(truth_frames)} frames (every {args.every}th of the first {args.frames} of "
              f"{', '.join(p.name for p in args.sequence)}); IoU / precision / recall of the potentially dynamic "
              "mask (person and chair) against the true moving-people masks, pooled over frames.")
    print()
    print("| model | person IoU walking_xyz | person IoU COCO held-out | mIoU COCO held-out | "
          "person agreement w/ teacher (halfsphere) | dynamic mask IoU (P / R), sequences | "
          "latency 640x480 (ms/frame) |")
    print("|---|---|---|---|---|---|---|")
    for name, a, b, c, d, g, e in rows:
        seqs = f"{g[0]:.3f} ({g[1]:.2f} / {g[2]:.2f})" if g else "–"
        print(f"| {name} | {f(a)} | {f(b)} | {f(c)} | {f(d)} | {seqs} | {e:.1f} |")


if __name__ == "__main__":
    main()
