"""Real people (and other movers) cut out of COCO images along their polygon labels (YOLO-seg text files,
COCO-80 class ids, 0 = person).

Only whole, upright, unclipped people make believable walkers: the filter keeps tall, narrow instances that do
not touch the image border. Other classes (animals, vehicles, chairs ...) have any shape: they are kept when
whole (off the border), big enough and not too fragmented.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from worker.slam.augment.movers import PERSON
from worker.slam.errors import SequenceFormatError


@dataclass(frozen=True)
class Sprite:
    """A cut-out person: `rgb` RGB uint8 (h, w, 3), `mask` uint8 (h, w) 0/1, `bulge` float32 (h, w) in [0, 1]
    (how far a pixel lies inside the silhouette, used to round the billboard's depth), `source` image name,
    `coco_id` its COCO-80 class."""

    rgb: np.ndarray
    mask: np.ndarray
    bulge: np.ndarray
    source: str
    coco_id: int = PERSON

    @property
    def aspect(self) -> float:
        """width / height."""
        return self.mask.shape[1] / self.mask.shape[0]


@dataclass(frozen=True)
class SpriteFilter:
    """Which COCO person instances are usable."""

    min_height_px: int = 180
    """Smallest bounding-box height in the COCO image (small cut-outs look blurred when a person is near)."""
    min_height_over_width: float = 1.5
    """Upright, whole-body people are tall and narrow."""
    min_fill: float = 0.3
    """Polygon area / box area (rejects fragments left by occluders)."""
    border_px: int = 3
    """Instances closer than this to the image border are clipped people: skipped."""
    min_colourfulness: float = 4.0
    """Mean |R-G| + |G-B| inside the person; rejects black-and-white photographs."""
    object_min_size_px: int = 80
    """Other classes: smallest longer side of the bounding box in the COCO image."""
    object_min_fill: float = 0.1
    """Other classes: polygon area / box area (a bicycle or a chair is mostly holes)."""


def _instances(label_file: Path, width: int, height: int,
               classes: frozenset[str]) -> list[tuple[int, np.ndarray]]:
    """(class id, (K, 2) float pixel polygon) of the instances of `classes` (ids as text) in one label file."""
    polys = []
    for lineno, line in enumerate(label_file.read_text().splitlines(), 1):
        parts = line.split()
        if not parts or parts[0] not in classes:
            continue
        vals = np.asarray(parts[1:], dtype=np.float64)
        if len(vals) < 6 or len(vals) % 2:
            raise SequenceFormatError("polygon needs an even number (>= 6) of coordinates", path=label_file,
                                      line=lineno)
        polys.append((int(parts[0]), vals.reshape(-1, 2) * [width, height]))
    return polys


def load_sprites(coco_dir: Path | str, filt: SpriteFilter = SpriteFilter(),
                 classes: tuple[int, ...] = (PERSON,)) -> list[Sprite]:
    """All usable instances of COCO-80 `classes` (default: people) of a YOLO-seg folder (`images/<split>/*.jpg`,
    `labels/<split>/*.txt`), sorted by file name, then in label-file order."""
    root = Path(coco_dir)
    labels = sorted(root.glob("labels/**/*.txt"))
    if not labels:
        raise SequenceFormatError("no YOLO-seg label files under labels/", path=root)
    wanted = frozenset(str(c) for c in classes)
    sprites = []
    for lab in labels:
        text = lab.read_text()
        if not any(line.split()[:1] and line.split()[0] in wanted for line in text.splitlines()):
            continue
        img_path = root / "images" / lab.relative_to(root / "labels").with_suffix(".jpg")
        img = cv2.imread(str(img_path), cv2.IMREAD_COLOR) if img_path.is_file() else None
        if img is None:
            continue  # a label without its image: nothing to cut
        for cls, poly in _instances(lab, img.shape[1], img.shape[0], wanted):
            sprite = _cut(img, cls, poly, filt, img_path.name)
            if sprite is not None:
                sprites.append(sprite)
    return sprites


def _shape_ok(cls: int, bw: float, bh: float, filt: SpriteFilter) -> bool:
    """Whole upright people are tall and narrow; other classes only need to be big enough."""
    if cls == PERSON:
        return bh >= filt.min_height_px and bh >= filt.min_height_over_width * bw
    return max(bw, bh) >= filt.object_min_size_px


def _cut(img: np.ndarray, cls: int, poly: np.ndarray, filt: SpriteFilter, source: str) -> Sprite | None:
    """The sprite of one instance polygon (K, 2) of BGR `img`, or None when the filter rejects it."""
    h, w = img.shape[:2]
    x0, y0 = poly.min(axis=0)
    x1, y1 = poly.max(axis=0)
    b = filt.border_px
    if not _shape_ok(cls, x1 - x0, y1 - y0, filt):
        return None
    if x0 < b or y0 < b or x1 > w - 1 - b or y1 > h - 1 - b:
        return None
    c0, r0, c1, r1 = int(x0), int(y0), int(np.ceil(x1)) + 1, int(np.ceil(y1)) + 1
    mask = np.zeros((r1 - r0, c1 - c0), np.uint8)
    cv2.fillPoly(mask, [np.round(poly - [c0, r0]).astype(np.int32)], 1)
    if mask.mean() < (filt.min_fill if cls == PERSON else filt.object_min_fill):
        return None
    dist = cv2.distanceTransform(mask, cv2.DIST_L2, 5)
    bulge = np.sqrt(dist / max(float(dist.max()), 1e-6)).astype(np.float32)
    rgb = cv2.cvtColor(img[r0:r1, c0:c1], cv2.COLOR_BGR2RGB)
    inside = rgb[mask > 0].astype(np.int16)
    colourful = np.abs(inside[:, 0] - inside[:, 1]).mean() + np.abs(inside[:, 1] - inside[:, 2]).mean()
    if colourful < filt.min_colourfulness:
        return None
    return Sprite(rgb, mask, bulge, source, cls)
