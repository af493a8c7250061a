"""Does MSNET's transformer do work? Per checkpoint, on COCO128's held-out split (VOC classes from its polygons):

    .venv/bin/python bench/bench_msnet_heads.py --checkpoint A.pt [--checkpoint B.pt ...] [--threads 1]

- `presence`: the class head's per-image presence probability for classes present in an image (>= 0.2 % of its
  pixels) against classes absent from it: mean of each, and the AUC (the chance that a present class outscores an
  absent one; 0.5 = the head says nothing). Only for checkpoints with the "presence" head.
- `class head varies`: the spread over images of the class head's output (std over images, mean over classes and
  entries), relative to its mean magnitude; 0 = the same output for every image.
- `decoder varies`: the same for the decoder's mask embeddings.
- `pixels changed`: share of pixels whose predicted class changes when every image's decoder outputs (class
  logits and mask embeddings) are replaced by their average over the images: what the per-image decoder adds.
- `mIoU`: mean IoU over the classes present in the set, at the network's input size.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def auc(pos: list[float], neg: list[float]) -> float:
    """Mann-Whitney AUC: P(a present class scores above an absent one), ties counted half."""
    import numpy as np

    if not pos or not neg:
        return float("nan")
    p, n = np.asarray(pos)[:, None], np.asarray(neg)[None, :]
    return float((p > n).mean() + 0.5 * (p == n).mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=Path(os.environ.get("VTD_SHARED_DIR", "../shared")))
    ap.add_argument("--checkpoint", type=Path, action="append", default=[], help="MSNET weights (repeatable; "
                    "default: the shipped one)")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()

    import cv2
    import numpy as np
    import torch

    from worker.slam.io.images import read_rgb
    from worker.slam.segmentation.classes import COCO_TO_VOC, VOC_CLASSES
    from worker.slam.segmentation.evaluate import confusion, metrics_from_confusion
    from worker.slam.segmentation.msnet.checkpoint import default_checkpoint, load_model
    from worker.slam.segmentation.train.config import load_train_config
    from worker.slam.segmentation.train.data import load_labelled
    from worker.slam.segmentation.train.datasets import semantic_mask, split_holdout
    from worker.slam.segmentation.train.losses import PRESENCE_MIN_SHARE

    torch.set_num_threads(args.threads)
    cfg = load_train_config("cpu-voc", shared_dir=str(args.shared))
    held = split_holdout(load_labelled(cfg), cfg.holdout_every)[1]
    print(f"load average {os.getloadavg()[0]:.1f}; COCO128 held-out: {len(held)} images, VOC classes "
          f"({len(COCO_TO_VOC)} COCO classes mapped)")
    print()
    print("| checkpoint | classes | presence present / absent (AUC) | class head varies | decoder varies "
          "| pixels changed | mIoU |")
    print("|---|---|---|---|---|---|---|")
    for path in args.checkpoint or [default_checkpoint()]:
        model, _ = load_model(path)
        classes, (h, w) = model.cfg.classes, model.cfg.input_size
        feats, truths = [], []
        with torch.inference_mode():
            for item in held:
                rgb = cv2.resize(read_rgb(item.image), (w, h), interpolation=cv2.INTER_AREA)
                x = torch.from_numpy(rgb).permute(2, 0, 1)[None].float().div(255)
                feats.append(model.forward_features(x))
                voc = cv2.resize(semantic_mask(item, VOC_CLASSES), (w, h), interpolation=cv2.INTER_NEAREST)
                truths.append(voc)
            cls = torch.cat([f.class_logits for f in feats])  # (N, M) or (N, M, M)
            emb = torch.cat([f.mask_embed for f in feats])  # (N, M, D)
            mean_cls, mean_emb = cls.mean(0, keepdim=True), emb.mean(0, keepdim=True)
            changed = total = 0
            cm = np.zeros((len(classes), len(classes)), np.int64)
            for f, truth in zip(feats, truths):
                own = model.forward_head(f, (h, w)).logits.argmax(1)[0].numpy()
                avg = model.forward_head(f._replace(class_logits=mean_cls, mask_embed=mean_emb), (h, w))
                changed += int((avg.logits.argmax(1)[0].numpy() != own).sum())
                total += own.size
                ours = np.array([classes.index(c) if c in classes else 0 for c in VOC_CLASSES], np.uint8)[truth]
                cm += confusion(own, ours, len(classes))
        spread = lambda t: float(t.std(0).mean() / t.abs().mean().clamp_min(1e-9))  # noqa: E731
        pres = "–"
        if model.cfg.class_head == "presence":
            prob = torch.sigmoid(cls).numpy()
            pos: list[float] = []
            neg: list[float] = []
            for p, truth in zip(prob, truths):
                share = np.bincount(truth.ravel(), minlength=len(VOC_CLASSES)) / truth.size
                for k, name in enumerate(classes[1:], 1):
                    present = name in VOC_CLASSES and share[VOC_CLASSES.index(name)] >= PRESENCE_MIN_SHARE
                    (pos if present else neg).append(float(p[k]))
            pres = f"{np.mean(pos):.2f} / {np.mean(neg):.3f} ({auc(pos, neg):.3f})"
        m = metrics_from_confusion(cm, classes, len(held))
        print(f"| {path.name} | {len(classes)} | {pres} | {spread(cls):.3f} | {spread(emb):.3f} "
              f"| {100 * changed / total:.1f} % | {m.miou:.3f} |")


if __name__ == "__main__":
    main()
