"""One colour per segmentation class name, the same in the previews, the live frame, the 3D viewer and the
job page's legend (every layer may import this module; the pipeline, the viewer and the api agree on it), and
:func:`class_overlay`, a frame with its class map blended in.

PASCAL VOC's palette is the field's convention: class k of VOC's 21 gets the k-th colour of its bit-interleaved
palette (person (192, 128, 128), car (128, 128, 128), ...). A class VOC lacks (a COCO class such as `teddy bear`,
a checkpoint's own) gets a palette colour after VOC's 21, chosen by a checksum of its name, so it never changes
between runs.
"""

from __future__ import annotations

import zlib
from collections.abc import Iterable, Sequence

import numpy as np

from formats.class_names import VOC_CLASSES

MOVING_OUTLINE = (255, 32, 32)
"""RGB of the outline :func:`class_overlay` draws around the pixels judged moving."""

def voc_palette_colour(index: int) -> tuple[int, int, int]:
    """The ``index``-th colour (0..255) of PASCAL VOC's palette: the index's bits spread over R, G, B from the
    most significant bit down."""
    r = g = b = 0
    c = index
    for shift in range(7, -1, -1):
        r |= (c & 1) << shift
        g |= ((c >> 1) & 1) << shift
        b |= ((c >> 2) & 1) << shift
        c >>= 3
    return r, g, b


def class_colour(name: str) -> tuple[int, int, int]:
    """(r, g, b) uint8 values of class ``name``: VOC's own colour for a VOC class, else a stable palette colour
    past VOC's (by CRC-32 of the name)."""
    if name in VOC_CLASSES:
        return voc_palette_colour(VOC_CLASSES.index(name))
    return voc_palette_colour(len(VOC_CLASSES) + zlib.crc32(name.encode()) % (256 - len(VOC_CLASSES)))


def hex_colour(name: str) -> str:
    """``#rrggbb`` of :func:`class_colour`, for HTML."""
    return "#{:02x}{:02x}{:02x}".format(*class_colour(name))


def legend(present: Iterable[str], dynamic: Iterable[str]) -> list[dict[str, object]]:
    """Legend entries ``{"name", "colour": "#rrggbb", "dynamic": bool}`` of the classes in ``present`` (in their
    order, background and repeats left out), potentially dynamic ones (``dynamic``) first."""
    dyn = set(dynamic)
    names = list(dict.fromkeys(n for n in present if n != "background"))
    names.sort(key=lambda n: n not in dyn)  # stable: keeps the given order within each group
    return [{"name": n, "colour": hex_colour(n), "dynamic": n in dyn} for n in names]


def present_classes(labels: np.ndarray, classes: Sequence[str]) -> tuple[str, ...]:
    """The names among ``classes`` (in their order, background included) with at least one pixel in ``labels``
    (H, W) uint8 indices into ``classes``."""
    counts = np.bincount(labels.ravel(), minlength=len(classes))
    return tuple(c for c, n in zip(classes, counts, strict=False) if n)


def class_overlay(rgb: np.ndarray, labels: np.ndarray, classes: Sequence[str], dynamic: Iterable[str],
                  moving: np.ndarray | None = None, alpha: float = 0.55, faint: float = 0.2) -> np.ndarray:
    """``rgb`` (H, W, 3) uint8 RGB with its class map ``labels`` (H, W) uint8 (indices into ``classes``, 0 =
    background) blended in: the pixels of potentially dynamic classes (``dynamic``) in their colour at ``alpha``,
    those of every other non-background class at ``faint`` (0: not drawn: they are not masked); ``moving``
    (H, W) bool, when given, outlined in :data:`MOVING_OUTLINE`. Returns a new (H, W, 3) uint8 RGB image."""
    if labels.shape != rgb.shape[:2]:
        raise ValueError(f"labels {labels.shape} do not match the image {rgb.shape[:2]}")
    k = max(len(classes), int(labels.max(initial=0)) + 1)
    colours = np.zeros((k, 3), np.float32)
    weights = np.zeros(k, np.float32)
    dyn = set(dynamic)
    for i, name in enumerate(classes):
        if i and name != "background":
            colours[i], weights[i] = class_colour(name), alpha if name in dyn else faint
    w = weights[labels][..., None]
    out = (rgb.astype(np.float32) * (1.0 - w) + colours[labels] * w + 0.5).astype(np.uint8)
    if moving is not None and moving.shape == labels.shape:
        out[_outline(moving.astype(bool))] = MOVING_OUTLINE
    return out


def _outline(mask: np.ndarray, width: int = 2) -> np.ndarray:
    """(H, W) bool: the pixels of ``mask`` within ``width`` pixels of its edge (a square erosion, in numpy)."""
    inner = mask.copy()
    for _ in range(width):
        shrunk = inner.copy()
        shrunk[1:] &= inner[:-1]
        shrunk[:-1] &= inner[1:]
        shrunk[:, 1:] &= inner[:, :-1]
        shrunk[:, :-1] &= inner[:, 1:]
        inner = shrunk
    return mask & ~inner
