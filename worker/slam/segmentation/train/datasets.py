"""Labelled image sets: YOLO-seg polygon folders, COCO JSON files (lists of instances) and mask folders
(one binary mask PNG per image, e.g. the CCP person photos).

Polygon sets map their own category ids onto the model's class names; instances of other categories are dropped
(they count as background), which is what a 3-class person/chair/background model needs.
"""
from __future__ import annotations

import hashlib
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
    mask: Path | None = None
    """A binary mask PNG (> 127 = `mask_label`) instead of polygons."""
    mask_label: str = "person"
    mask_min: int = 128
    """Mask pixels >= this are the labelled object (128 for 0/255 masks, 1 for id maps such as synthetic truth)."""
    partial: bool = False
    """Only the main subject is labelled (CCP): other pixels of its class may be unlabelled, so the background
    is not a certain negative where a teacher sees that class."""

    @property
    def labels(self) -> frozenset[str]:
        """The class names this image labels (a mask folder's main subject, or its polygons' classes)."""
        if self.mask is not None:
            return frozenset((self.mask_label,))
        return frozenset(inst.label for inst in self.instances)


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


def load_mask_folder(root: Path, label: str, partial: bool = True) -> list[LabelledImage]:
    """`root/images/NAME.jpg` with `root/masks/NAME.png` (255 = the labelled object, 0 = the rest)."""
    images = sorted(p for p in (root / "images").glob("*") if p.suffix.lower() in IMAGE_SUFFIXES)
    if not images:
        raise ConfigError(f"no images under {root / 'images'} (images/ + masks/ layout expected)")
    out = []
    for img in images:
        mask = root / "masks" / f"{img.stem}.png"
        if not mask.is_file():
            raise SequenceFormatError("image has no mask", path=mask)
        out.append(LabelledImage(img, _image_size(mask), mask=mask, mask_label=label, partial=partial))
    return out


def hash_split(items: list[LabelledImage], test_fraction: float, val_fraction: float, seed: int = 0
               ) -> tuple[list[LabelledImage], list[LabelledImage], list[LabelledImage]]:
    """(train, val, test) by a seeded hash of each file name: an image's split never depends on which other
    images exist, so adding or removing files moves nobody across splits."""
    def u(item: LabelledImage) -> float:
        digest = hashlib.sha256(f"{seed}:{item.image.name}".encode()).digest()
        return int.from_bytes(digest[:8], "big") / 2.0 ** 64

    train: list[LabelledImage] = []
    val: list[LabelledImage] = []
    test: list[LabelledImage] = []
    for item in sorted(items, key=lambda i: str(i.image)):
        x = u(item)
        (test if x < test_fraction else val if x < test_fraction + val_fraction else train).append(item)
    return train, val, test


def read_mask(item: LabelledImage) -> np.ndarray:
    """(H, W) uint8 0/1 of a mask-folder item."""
    assert item.mask is not None, "only for mask-folder items"
    m = cv2.imread(str(item.mask), cv2.IMREAD_GRAYSCALE)
    if m is None:
        raise SequenceFormatError("not a decodable mask image", path=item.mask)
    return (m >= item.mask_min).astype(np.uint8)


def object_masks(item: LabelledImage, classes: tuple[str, ...]) -> list[tuple[np.ndarray, int]]:
    """(0/1 mask, class index) per labelled object; classes not in `classes` get index 0 (background)."""
    def idx(label: str) -> int:
        return classes.index(label) if label in classes else 0

    if item.mask is not None:
        return [(read_mask(item), idx(item.mask_label))]
    return [(instance_mask(i, item.size), idx(i.label)) for i in item.instances]


def instance_mask(inst: Instance, size: tuple[int, int]) -> np.ndarray:
    """(H, W) uint8 0/1 mask of one instance."""
    mask = np.zeros(size, dtype=np.uint8)
    cv2.fillPoly(mask, [np.round(p).astype(np.int32) for p in inst.polygons], 1)
    return mask


def semantic_mask(item: LabelledImage, classes: tuple[str, ...]) -> np.ndarray:
    """(H, W) uint8 class indices. Larger instances are drawn first so small ones in front stay visible."""
    out = np.zeros(item.size, dtype=np.uint8)
    if item.mask is not None:
        out[read_mask(item) > 0] = classes.index(item.mask_label)
        return out
    for inst in sorted(item.instances, key=lambda i: -cv2.contourArea(i.polygons[0])):
        out[instance_mask(inst, item.size) > 0] = classes.index(inst.label)
    return out


def split_holdout(items: list[LabelledImage], every: int) -> tuple[list[LabelledImage], list[LabelledImage]]:
    """Deterministic train / held-out split: every `every`-th image (sorted by path) is held out."""
    items = sorted(items, key=lambda i: str(i.image))
    held = [it for k, it in enumerate(items) if k % every == 0]
    return [it for k, it in enumerate(items) if k % every != 0], held
