"""Labelled image sets as lists of instances: YOLO-seg polygon folders and COCO JSON files.

Both map their own category ids onto the model's class names; instances of other categories are dropped (they
count as background), which is what a 3-class person/chair/background model needs.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from worker.slam.errors import ConfigError, SequenceFormatError

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp")


@dataclass(frozen=True)
class Instance:
    """One object: its class name and polygons in pixel coordinates (each (N, 2) float32, x then y)."""

    label: str
    polygons: tuple[np.ndarray, ...]


@dataclass(frozen=True)
class LabelledImage:
    image: Path
    size: tuple[int, int]
    """(height, width) the polygons refer to."""
    instances: tuple[Instance, ...] = field(default_factory=tuple)


def parse_yolo_seg_line(line: str, size: tuple[int, int], id_to_label: dict[int, str], path: Path,
                        lineno: int) -> Instance | None:
    """`cls x1 y1 x2 y2 ...` (normalised) -> Instance in pixels; None when the class is not one of ours."""
    parts = line.split()
    if len(parts) < 7 or len(parts) % 2 == 0:
        raise SequenceFormatError("YOLO-seg line needs a class and at least 3 (x, y) points", path=path,
                                  line=lineno)
    try:
        cls = int(parts[0])
        xy = np.asarray(parts[1:], dtype=np.float32).reshape(-1, 2)
    except ValueError as exc:
        raise SequenceFormatError(f"YOLO-seg line is not numeric: {exc}", path=path, line=lineno) from exc
    if cls not in id_to_label:
        return None
    h, w = size
    return Instance(id_to_label[cls], (xy * np.array([w, h], dtype=np.float32),))


def _image_size(path: Path) -> tuple[int, int]:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise SequenceFormatError("not a decodable image", path=path)
    return img.shape[0], img.shape[1]


def load_yolo_seg(root: Path, id_to_label: dict[int, str]) -> list[LabelledImage]:
    """`root/images/**/name.jpg` with `root/labels/**/name.txt`; an image without a label file is background."""
    images = sorted(p for p in (root / "images").rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES)
    if not images:
        raise ConfigError(f"no images under {root / 'images'} (YOLO-seg layout expected)")
    out = []
    for img in images:
        size = _image_size(img)
        label = root / "labels" / img.relative_to(root / "images").with_suffix(".txt")
        instances = []
        if label.is_file():
            for i, line in enumerate(label.read_text().splitlines(), 1):
                if line.strip():
                    inst = parse_yolo_seg_line(line, size, id_to_label, label, i)
                    if inst is not None:
                        instances.append(inst)
        out.append(LabelledImage(img, size, tuple(instances)))
    return out


def load_coco_json(annotations: Path, image_dir: Path, name_to_label: dict[str, str]) -> list[LabelledImage]:
    """COCO instances JSON (polygon segmentations; RLE crowd regions are skipped). Categories match by name."""
    try:
        data = json.loads(annotations.read_text())
        cats = {c["id"]: name_to_label[c["name"]] for c in data["categories"] if c["name"] in name_to_label}
        per_image: dict[int, list[Instance]] = {im["id"]: [] for im in data["images"]}
        for ann in data["annotations"]:
            seg = ann.get("segmentation")
            if ann["category_id"] in cats and isinstance(seg, list) and seg:
                polys = tuple(np.asarray(p, dtype=np.float32).reshape(-1, 2) for p in seg if len(p) >= 6)
                if polys:
                    per_image[ann["image_id"]].append(Instance(cats[ann["category_id"]], polys))
        return [LabelledImage(image_dir / im["file_name"], (int(im["height"]), int(im["width"])),
                              tuple(per_image[im["id"]])) for im in data["images"]]
    except (KeyError, TypeError, ValueError) as exc:
        raise SequenceFormatError(f"malformed COCO annotation file: {exc}", path=annotations) from exc


def instance_mask(inst: Instance, size: tuple[int, int]) -> np.ndarray:
    """(H, W) uint8 0/1 mask of one instance."""
    mask = np.zeros(size, dtype=np.uint8)
    cv2.fillPoly(mask, [np.round(p).astype(np.int32) for p in inst.polygons], 1)
    return mask


def semantic_mask(item: LabelledImage, classes: tuple[str, ...]) -> np.ndarray:
    """(H, W) uint8 class indices. Larger instances are drawn first so small ones in front stay visible."""
    out = np.zeros(item.size, dtype=np.uint8)
    for inst in sorted(item.instances, key=lambda i: -cv2.contourArea(i.polygons[0])):
        out[instance_mask(inst, item.size) > 0] = classes.index(inst.label)
    return out


def split_holdout(items: list[LabelledImage], every: int) -> tuple[list[LabelledImage], list[LabelledImage]]:
    """Deterministic train / held-out split: every `every`-th image (sorted by path) is held out."""
    items = sorted(items, key=lambda i: str(i.image))
    held = [it for k, it in enumerate(items) if k % every == 0]
    return [it for k, it in enumerate(items) if k % every != 0], held
