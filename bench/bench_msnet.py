"""MSNET against the TFLite teachers: accuracy on real frames and CPU latency at 640x480, as a markdown table.

    .venv/bin/python bench/bench_msnet.py [--threads 1] [--repeats 3] [--checkpoint PT] [--overlays /tmp/msnet_overlays]

Columns: person IoU on the TUM fr3 walking_xyz frame (reference mask in ../shared); person IoU and mIoU on the
held-out COCO128 split (every 5th image, never trained on); person agreement (IoU of the two person masks,
pooled over frames) with the DeepLabV3-257 teacher on the 10 fr3 walking_halfsphere frames (the `cpu-tum` recipe
trains on these frames with this teacher's labels, so for its checkpoint this column is a training-set figure,
not a held-out one; walking_xyz and the COCO held-out split are never trained on); median latency of
`segment()` on 640x480 frames (resize in, full-resolution labels and probabilities out). Teachers missing from
../shared/models are skipped. Timings on a shared machine vary with its load: the load average is printed.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

TEACHERS = {
    "DeepLabV3-MNv2 257 (teacher)": "deeplabv3_257_mv_gpu.tflite",
    "DeepLabV3-MNv2 513 int8": "deeplabv3_mnv2_pascal_quant.tflite",
    "MediaPipe selfie": "selfie_segmentation.tflite",
}


def pooled_iou(pairs) -> float:
    import numpy as np

    inter = union = 0
    for a, b in pairs:
        inter += np.logical_and(a, b).sum()
        union += np.logical_or(a, b).sum()
    return float(inter / union) if union else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=Path(os.environ.get("VTD_SHARED_DIR", "../shared")))
    ap.add_argument("--checkpoint", type=Path, default=None, help="MSNET weights (default: shipped)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--overlays", type=Path, default=None, help="write overlay PNGs here")
    args = ap.parse_args()

    import cv2
    import numpy as np
    import torch

    from worker.slam.io.images import read_rgb
    from worker.slam.segmentation import SegmenterConfig, make_segmenter
    from worker.slam.segmentation.msnet.checkpoint import load_model
    from worker.slam.segmentation.evaluate import evaluate_segmenter, labelled_samples, measure_latency, overlay, \
        tum_person_mask
    from worker.slam.segmentation.train.datasets import load_yolo_seg, split_holdout

    torch.set_num_threads(args.threads)
    cv2.setNumThreads(args.threads)
    data = args.shared / "data"
    xyz = data / "tum_frames" / "fr3_walking_xyz"
    xyz_rgb = read_rgb(next(xyz.glob("rgb_*.png")))
    xyz_gt = tum_person_mask(cv2.imread(str(next(xyz.glob("person_mask_*.png"))), cv2.IMREAD_UNCHANGED))
    half = [read_rgb(p) for p in sorted((data / "tum_frames" / "fr3_walking_halfsphere").glob("*.png"))]
    held = split_holdout(load_yolo_seg(data / "coco128_seg", {0: "person", 56: "chair"}), 5)[1]
    classes = ("background", "person", "chair")

    segmenters = {"MSNET (ours)": make_segmenter(SegmenterConfig(
        checkpoint=str(args.checkpoint) if args.checkpoint else None, device="cpu", threads=args.threads))}
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
        rows.append((name, iou_xyz, m.iou["person"], miou, agree, lat))
        if args.overlays:
            args.overlays.mkdir(parents=True, exist_ok=True)
            tag = name.split("(")[0].strip().lower().replace(" ", "_")
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
    print("| model | person IoU walking_xyz | person IoU COCO held-out | mIoU COCO held-out | "
          "person agreement w/ teacher (halfsphere) | latency 640x480 (ms/frame) |")
    print("|---|---|---|---|---|---|")
    for name, a, b, c, d, e in rows:
        print(f"| {name} | {f(a)} | {f(b)} | {f(c)} | {f(d)} | {e:.1f} |")


if __name__ == "__main__":
    main()
