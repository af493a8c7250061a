"""Uploads the pipeline could never track are refused at ingest: frames smaller than ORB's pyramid needs, and
depth with no valid pixel (decided on a sample of frames, from the PNG's filtered data, without decoding)."""
from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from storage.errors import InvalidInput
from storage.ingest.images import _ADAM7, png_is_blank
from storage.ingest.sequence import MIN_SIZE, validate_sequence
from tests.backend.api.data import write_sequence


def _png_by_hand(path: Path, rows: list[bytes], width: int, height: int, interlace: int = 0) -> Path:
    """A 16-bit grey PNG from raw (filtered) scanlines, filter bytes included."""
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    ihdr = struct.pack(">IIBBBBB", width, height, 16, 0, 0, 0, interlace)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"".join(rows)))
                     + chunk(b"IEND", b""))
    return path


def test_blank_png_is_told_from_the_filtered_data(tmp_path):
    zeros = tmp_path / "z.png"
    cv2.imwrite(str(zeros), np.zeros((48, 64), np.uint16))
    assert png_is_blank(zeros)
    one = np.zeros((48, 64), np.uint16)
    one[47, 63] = 1  # the very last sample
    cv2.imwrite(str(tmp_path / "one.png"), one)
    assert not png_is_blank(tmp_path / "one.png")
    ramp = np.tile(np.arange(64, dtype=np.uint16) * 100, (48, 1))  # cv2 picks Sub/Up/Paeth filters for it
    cv2.imwrite(str(tmp_path / "ramp.png"), ramp)
    assert not png_is_blank(tmp_path / "ramp.png")
    # every row filtered (Up, Paeth) with zero residuals: still all zero
    hand = _png_by_hand(tmp_path / "hand.png", [bytes([2 + k % 3]) + bytes(8) for k in range(3)], 4, 3)
    assert png_is_blank(hand) and cv2.imread(str(hand), cv2.IMREAD_UNCHANGED).max() == 0
    # interlaced (Adam7): the last pass's last sample non-zero, every other sample zero
    passes = [((4 - x0 + dx - 1) // dx, (3 - y0 + dy - 1) // dy) for x0, y0, dx, dy in _ADAM7]
    rows = [b"\x00" + bytes(2 * w) for w, h in passes if w and h for _ in range(h)]
    rows[-1] = rows[-1][:-1] + b"\x07"
    adam7 = _png_by_hand(tmp_path / "adam7.png", rows, 4, 3, interlace=1)
    assert cv2.imread(str(adam7), cv2.IMREAD_UNCHANGED).max() == 7 and not png_is_blank(adam7)
    rows[-1] = rows[-1][:-1] + b"\x00"
    assert png_is_blank(_png_by_hand(tmp_path / "adam7z.png", rows, 4, 3, interlace=1))


def test_frames_smaller_than_the_pipeline_needs_are_refused(tmp_path):
    seq = write_sequence(tmp_path / "tiny", n=4, size=(32, 24), camera_json=False)
    with pytest.raises(InvalidInput, match=r"images are 32x24; the pipeline needs at least 64x48") as info:
        validate_sequence(seq, {"preset": "tum1"})
    assert info.value.detail == {"image_size": [32, 24], "min_size": list(MIN_SIZE)}
    ok = write_sequence(tmp_path / "small", n=4, size=MIN_SIZE, camera_json=False)
    assert validate_sequence(ok, {"preset": "tum1"}).width == MIN_SIZE[0]


def test_all_invalid_depth_is_refused_but_one_valid_sample_is_enough(tmp_path):
    seq = write_sequence(tmp_path / "seq", n=12)
    depths = sorted((seq / "depth").iterdir())
    for p in depths:
        cv2.imwrite(str(p), np.zeros((120, 160), np.uint16))
    with pytest.raises(InvalidInput, match=r"depth.txt: every sampled depth image \(5 of 12\) is all 0"):
        validate_sequence(seq)
    patch = np.zeros((120, 160), np.uint16)
    patch[50:60, 70:80] = 5000
    cv2.imwrite(str(depths[-1]), patch)  # the last frame is always in the sample
    assert validate_sequence(seq).frames == 12
