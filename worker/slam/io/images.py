"""Decoding colour and depth images with the checks a user's upload needs."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from worker.slam.errors import SequenceFormatError

# A decompression bomb guard: the header's size is checked before OpenCV allocates the pixels.
MAX_PIXELS = 4096 * 4096


def header_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG or JPEG header without decoding pixels; None for other formats."""
    if data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) >= 24:
        return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    if data[:2] == b"\xff\xd8":
        i = 2
        while i + 9 < len(data):
            if data[i] != 0xFF:
                return None
            marker = data[i + 1]
            seg_len = int.from_bytes(data[i + 2:i + 4], "big")
            if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):  # start of frame
                return int.from_bytes(data[i + 7:i + 9], "big"), int.from_bytes(data[i + 5:i + 7], "big")
            i += 2 + seg_len
    return None


def _read(path: Path) -> np.ndarray:
    if not path.is_file():
        raise SequenceFormatError("image file is missing", path=path)
    data = np.fromfile(path, dtype=np.uint8)
    if data.size == 0:
        raise SequenceFormatError("image file is empty", path=path)
    size = header_size(data[:65536].tobytes())
    if size is not None and size[0] * size[1] > MAX_PIXELS:
        raise SequenceFormatError(f"image is too large ({size[0]}x{size[1]})", path=path)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise SequenceFormatError("not a decodable image", path=path)
    if img.shape[0] * img.shape[1] > MAX_PIXELS:
        raise SequenceFormatError(f"image is too large ({img.shape[1]}x{img.shape[0]})", path=path)
    return img


def read_rgb(path: Path) -> np.ndarray:
    """Colour image as RGB uint8 (H, W, 3). Grey images are expanded; 16-bit or alpha images are rejected."""
    img = _read(path)
    if img.dtype != np.uint8:
        raise SequenceFormatError(f"colour image must be 8-bit, got {img.dtype}", path=path)
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
    elif img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    elif img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    else:
        raise SequenceFormatError(f"colour image has {img.shape[2]} channels", path=path)
    return img


def read_depth(path: Path, depth_scale: float) -> np.ndarray:
    """Depth as float32 metres (H, W), 0 = invalid. Only single-channel 16-bit PNG-like depth is accepted."""
    img = _read(path)
    if img.ndim != 2:
        raise SequenceFormatError(f"depth image must be single-channel, got {img.shape[2]} channels", path=path)
    if img.dtype != np.uint16:
        raise SequenceFormatError(f"depth image must be 16-bit, got {img.dtype} (8-bit depth loses range)",
                                  path=path)
    return img.astype(np.float32) / np.float32(depth_scale)
