"""Geometric crops, photometric jitter and copy-paste of object cut-outs onto backgrounds.

All functions take an explicit `np.random.Generator`, so a sample is a pure function of its seed.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

IGNORE = 255


@dataclass(frozen=True)
class Cutout:
    """An object to paste: RGB crop (h, w, 3) uint8, its 0/1 mask (h, w) uint8 and class index."""

    rgb: np.ndarray
    mask: np.ndarray
    label: int


def random_affine(rng: np.random.Generator, src_hw: tuple[int, int], out_hw: tuple[int, int],
                  scale_range: tuple[float, float]) -> np.ndarray:
    """2x3 matrix mapping source pixels to an output crop: random zoom, position and horizontal flip.

    scale 1 means the source's shorter fit fills the output (aspect kept); > 1 zooms in.
    """
    (sh, sw), (oh, ow) = src_hw, out_hw
    s = max(oh / sh, ow / sw) * rng.uniform(*scale_range)
    # Offsets keep the crop inside the image when it is larger than the output; else centre-jitter it.
    tx = rng.uniform(min(0.0, ow - sw * s), max(0.0, ow - sw * s))
    ty = rng.uniform(min(0.0, oh - sh * s), max(0.0, oh - sh * s))
    a = np.array([[s, 0.0, tx], [0.0, s, ty]])
    if rng.random() < 0.5:
        a = np.array([[-1.0, 0.0, ow], [0.0, 1.0, 0.0]]) @ np.vstack([a, [0, 0, 1]])
    return a


def warp(img: np.ndarray, a: np.ndarray, out_hw: tuple[int, int], nearest: bool = False,
         border: int = 0, src_scale: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """Apply `a` (defined on the full-resolution source) to `img`, which may be on a coarser grid whose pixels
    are src_scale = (sx, sy) source pixels wide (the teacher's output grid)."""
    m = a @ np.diag([src_scale[0], src_scale[1], 1.0])
    flags = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    out = cv2.warpAffine(img, m, (out_hw[1], out_hw[0]), flags=flags, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=border)
    return out[..., None] if out.ndim == 2 and img.ndim == 3 else out


def color_jitter(rng: np.random.Generator, rgb: np.ndarray, strength: float = 0.25,
                 channel_gain: float = 0.0) -> np.ndarray:
    """Brightness, contrast and saturation jitter plus mild noise, and optionally a per-channel gain of up to
    +-channel_gain (white balance); RGB uint8 in and out."""
    x = rgb.astype(np.float32)
    if channel_gain > 0:
        x = x * rng.uniform(1 - channel_gain, 1 + channel_gain, 3).astype(np.float32)
    x = x * rng.uniform(1 - strength, 1 + strength) + rng.uniform(-20, 20) * strength * 4
    mean = x.mean()
    x = (x - mean) * rng.uniform(1 - strength, 1 + strength) + mean
    grey = x.mean(-1, keepdims=True)
    x = (x - grey) * rng.uniform(1 - strength, 1 + strength) + grey
    x += rng.normal(0.0, 3.0, x.shape).astype(np.float32)
    return np.clip(x, 0, 255).astype(np.uint8)


def paste(rng: np.random.Generator, rgb: np.ndarray, hard: np.ndarray, soft: np.ndarray, cut: Cutout,
          height_frac: tuple[float, float]) -> None:
    """Paste `cut` in place, scaled to a random fraction of the image height, bottom edge in the lower part
    (people and chairs stand on the floor; some are cut off by the frame's bottom as in hand-held footage)."""
    oh, ow = hard.shape
    ch, cw = cut.mask.shape
    s = rng.uniform(*height_frac) * oh / ch
    nh, nw = max(int(ch * s), 4), max(int(cw * s), 4)
    if nw >= 2 * ow:
        return
    crgb = cv2.resize(cut.rgb, (nw, nh), interpolation=cv2.INTER_AREA)
    cmask = cv2.resize(cut.mask.astype(np.float32), (nw, nh), interpolation=cv2.INTER_LINEAR)
    if rng.random() < 0.5:
        crgb, cmask = crgb[:, ::-1], cmask[:, ::-1]
    # A slightly soft edge hides the polygon's jaggies, which the network could otherwise learn to detect.
    alpha = cv2.GaussianBlur(cmask, (3, 3), 0)
    x0 = int(rng.uniform(-nw * 0.3, ow - nw * 0.7))
    y1 = int(rng.uniform(0.55, 1.35) * oh)
    y0 = y1 - nh
    ya, yb, xa, xb = max(y0, 0), min(y1, oh), max(x0, 0), min(x0 + nw, ow)
    if yb <= ya or xb <= xa:
        return
    sub = (slice(ya - y0, yb - y0), slice(xa - x0, xb - x0))
    a = alpha[sub][..., None]
    region = rgb[ya:yb, xa:xb].astype(np.float32)
    src = crgb[sub].astype(np.float32)
    if rng.random() < 0.7:  # soften like the background's camera, so sharpness is no cue for "pasted"
        src = cv2.GaussianBlur(src, (0, 0), rng.uniform(0.5, 1.5)).astype(np.float32, copy=False)
    src = match_colours(rng, src, cmask[sub] > 0.5, rgb.astype(np.float32))
    rgb[ya:yb, xa:xb] = np.clip(a * src + (1 - a) * region, 0, 255).astype(np.uint8)
    inside = cmask[sub] > 0.5
    hard[ya:yb, xa:xb][inside] = cut.label
    one_hot = np.zeros(soft.shape[-1], dtype=soft.dtype)
    one_hot[cut.label] = 255
    soft[ya:yb, xa:xb][inside] = one_hot


def match_colours(rng: np.random.Generator, src: np.ndarray, mask: np.ndarray, background: np.ndarray
                  ) -> np.ndarray:
    """Move the cut-out's per-channel mean and spread part of the way to the background's (Reinhard-style),
    so that a different camera's colour balance does not mark pasted objects."""
    if mask.sum() < 16:
        return src
    t = rng.uniform(0.2, 0.6)
    mu_s, sd_s = src[mask].mean(0), src[mask].std(0) + 1.0
    mu_b, sd_b = background.reshape(-1, 3).mean(0), background.reshape(-1, 3).std(0) + 1.0
    scale = (1 - t) + t * sd_b / sd_s
    return (src - mu_s) * scale + (1 - t) * mu_s + t * mu_b


def soften(rng: np.random.Generator, rgb: np.ndarray) -> np.ndarray:
    """Down- then up-sample: the soft look of a Kinect-class colour camera, applied to any source image."""
    h, w = rgb.shape[:2]
    f = rng.uniform(0.45, 0.8)
    small = cv2.resize(rgb, (max(int(w * f), 8), max(int(h * f), 8)), interpolation=cv2.INTER_AREA)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)


def extract_cutouts(rgb: np.ndarray, masks: list[tuple[np.ndarray, int]], min_height: int,
                    min_area: int) -> list[Cutout]:
    """Tight crops of the instances big enough to look right when scaled up."""
    out = []
    for mask, label in masks:
        ys, xs = np.nonzero(mask)
        if ys.size < min_area or ys.max() - ys.min() + 1 < min_height:
            continue
        y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
        out.append(Cutout(rgb[y0:y1, x0:x1].copy(), mask[y0:y1, x0:x1].copy(), label))
    return out
