"""Procedural surface textures packed in one atlas, so a whole frame is sampled with a single `cv2.remap`.

Textures are busy on purpose: corners, text and blobs at several scales give an ORB tracker hundreds of stable
features at any distance in the room. A few cells are dark (screens, a rug) where a Kinect returns no depth.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

WORDS = ("EXIT", "LAB 3", "VTD", "SLAM", "NOTE", "2024", "ROOM", "TUM", "KEEP", "DESK", "A-12", "OK")


@dataclass(frozen=True)
class Cell:
    """Where one texture sits in the atlas (pixels) and how many texels cover one metre of surface."""

    x0: int
    y0: int
    w: int
    h: int
    texels_per_m: float


@dataclass
class TextureAtlas:
    """`image` RGB uint8 (H, W, 3); `cells[name]` locates each texture in it."""

    image: np.ndarray
    cells: dict[str, Cell]


def _noise(rng: np.random.Generator, h: int, w: int, scale: int) -> np.ndarray:
    """Smooth value noise in [0, 1], float32 (h, w)."""
    small = rng.random((max(2, h // scale), max(2, w // scale))).astype(np.float32)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC).clip(0, 1)


def _colour(rng: np.random.Generator, lo: int = 20, hi: int = 235) -> tuple[int, int, int]:
    r, g, b = (int(v) for v in rng.integers(lo, hi, 3))
    return r, g, b


def busy_texture(rng: np.random.Generator, h: int, w: int, base: tuple[int, int, int], density: float = 1.0,
                 text: bool = True) -> np.ndarray:
    """RGB uint8 (h, w, 3): a mottled base colour with rectangles, circles, lines and words drawn over it."""
    base_arr = np.asarray(base, np.float32)
    img = base_arr * (0.75 + 0.5 * _noise(rng, h, w, 48)[..., None])
    img = np.clip(img + 18 * (_noise(rng, h, w, 6)[..., None] - 0.5), 0, 255).astype(np.uint8)
    n = int(density * h * w / 2500)
    for _ in range(n):
        kind = rng.integers(0, 5)
        c = _colour(rng)
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        s = int(rng.integers(6, 60))
        if kind == 0:
            cv2.rectangle(img, (x, y), (x + s, y + int(rng.integers(6, 60))), c, -1)
        elif kind == 1:
            cv2.circle(img, (x, y), s // 2, c, -1)
        elif kind == 2:
            cv2.line(img, (x, y), (x + int(rng.integers(-80, 80)), y + int(rng.integers(-80, 80))), c, 3)
        elif kind == 3:
            cv2.rectangle(img, (x, y), (x + s, y + s), c, 2)
        elif text:
            cv2.putText(img, WORDS[int(rng.integers(len(WORDS)))], (x, y), cv2.FONT_HERSHEY_SIMPLEX,
                        float(rng.uniform(0.6, 1.6)), c, 2, cv2.LINE_AA)
    return img


def poster_wall(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """A plaster wall with framed posters and notes pinned to it."""
    img = busy_texture(rng, h, w, _colour(rng, 150, 220), density=0.35, text=False)
    for _ in range(max(3, w * h // 60000)):
        pw, ph = int(rng.integers(70, 220)), int(rng.integers(70, 200))
        x, y = int(rng.integers(0, max(1, w - pw))), int(rng.integers(0, max(1, h - ph)))
        img[y:y + ph, x:x + pw] = busy_texture(rng, ph, pw, _colour(rng), density=2.5)
        cv2.rectangle(img, (x, y), (x + pw, y + ph), (25, 25, 25), 3)
    return img


def wood_floor(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """Planks with grain and knots, plus scattered marks (floors need features too)."""
    base = np.asarray(_colour(rng, 90, 170), np.float32)
    grain = _noise(rng, h, w, 4)
    stripes = 0.5 + 0.5 * np.sin(np.arange(w, dtype=np.float32)[None, :] * 0.35 + 6 * _noise(rng, h, w, 40))
    img = base * (0.7 + 0.25 * stripes[..., None] + 0.2 * grain[..., None])
    img = np.clip(img, 0, 255).astype(np.uint8)
    plank = 40
    for x in range(0, w, plank):
        cv2.line(img, (x, 0), (x, h), (30, 20, 10), 2)
        for y in range(int(rng.integers(0, 120)), h, 160):
            cv2.line(img, (x, y), (x + plank, y), (30, 20, 10), 2)
    for _ in range(w * h // 3000):
        cv2.circle(img, (int(rng.integers(w)), int(rng.integers(h))), int(rng.integers(2, 7)), _colour(rng, 10, 90), -1)
    return img


def dark_texture(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """Near-black (a screen, a rug): the Kinect's projector pattern is lost here, so depth has holes."""
    img = (6 + 14 * _noise(rng, h, w, 16)[..., None]).repeat(3, 2).astype(np.uint8)
    cv2.rectangle(img, (2, 2), (w - 3, h - 3), (90, 90, 90), 3)
    return img


def build_atlas(rng: np.random.Generator, texels_per_m: float = 200.0) -> TextureAtlas:
    """All textures of the room: walls, floor, ceiling, furniture variants and dark surfaces."""
    specs: list[tuple[str, int, int, str]] = [
        ("wall0", 512, 1024, "poster"), ("wall1", 512, 1024, "poster"), ("wall2", 512, 1024, "poster"),
        ("wall3", 512, 1024, "poster"), ("floor", 1024, 1024, "wood"), ("ceiling", 256, 512, "plain"),
        ("furn0", 384, 384, "busy"), ("furn1", 384, 384, "busy"), ("furn2", 384, 384, "busy"),
        ("furn3", 384, 384, "busy"), ("dark", 128, 256, "dark"),
    ]
    width = 2048
    x = y = row_h = 0
    placed = []
    for name, h, w, kind in specs:  # simple shelf packing, left to right then down
        if x + w > width:
            x, y, row_h = 0, y + row_h, 0
        placed.append((name, x, y, h, w, kind))
        x, row_h = x + w, max(row_h, h)
    atlas = np.zeros((y + row_h, width, 3), np.uint8)
    cells = {}
    for name, x0, y0, h, w, kind in placed:
        if kind == "poster":
            tex = poster_wall(rng, h, w)
        elif kind == "wood":
            tex = wood_floor(rng, h, w)
        elif kind == "dark":
            tex = dark_texture(rng, h, w)
        elif kind == "plain":
            tex = busy_texture(rng, h, w, (215, 215, 210), density=0.3, text=False)
        else:
            tex = busy_texture(rng, h, w, _colour(rng, 60, 200), density=1.2)
        atlas[y0:y0 + h, x0:x0 + w] = tex
        cells[name] = Cell(x0, y0, w, h, texels_per_m)
    return TextureAtlas(atlas, cells)
