"""PNG/JPEG checks without an image library: sizes, bit depths, integrity, bombs."""
from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
import pytest

from storage.errors import InvalidInput
from storage.ingest.images import check_image


def _png(tmp_path, img, name="a.png", **params):
    path = tmp_path / name
    flags = [cv2.IMWRITE_PNG_COMPRESSION, 3]
    cv2.imwrite(str(path), img, flags)
    return path


def test_rgb_and_depth_pngs(tmp_path):
    rgb = check_image(_png(tmp_path, np.zeros((48, 64, 3), np.uint8)))
    assert (rgb.format, rgb.width, rgb.height, rgb.bit_depth, rgb.channels) == ("png", 64, 48, 8, 3)
    depth = check_image(_png(tmp_path, np.full((48, 64), 5000, np.uint16), "d.png"))
    assert (depth.bit_depth, depth.channels) == (16, 1)


def test_jpeg(tmp_path):
    path = tmp_path / "a.jpg"
    cv2.imwrite(str(path), np.full((30, 40, 3), 128, np.uint8))
    info = check_image(path)
    assert (info.format, info.width, info.height, info.bit_depth) == ("jpeg", 40, 30, 8)
    path.write_bytes(path.read_bytes()[:-2])
    with pytest.raises(InvalidInput, match="truncated JPEG"):
        check_image(path)


@pytest.mark.parametrize("cut", [40, 100, -20])
def test_truncated_or_corrupt_png(tmp_path, cut):
    path = _png(tmp_path, np.random.default_rng(0).integers(0, 255, (48, 64, 3), dtype=np.uint8))
    data = path.read_bytes()
    path.write_bytes(data[:cut] if cut > 0 else data[:cut] + data[cut:][::-1])
    with pytest.raises(InvalidInput):
        check_image(path)


def _chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def test_png_bomb_is_refused_from_its_header(tmp_path):
    ihdr = struct.pack(">IIBBBBB", 100_000, 100_000, 8, 2, 0, 0, 0)
    path = tmp_path / "bomb.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", zlib.compress(b"")) +
                     _chunk(b"IEND", b""))
    with pytest.raises(InvalidInput, match="too large"):
        check_image(path)


def test_png_whose_data_is_larger_than_its_header(tmp_path):
    ihdr = struct.pack(">IIBBBBB", 4, 4, 8, 0, 0, 0, 0)
    path = tmp_path / "liar.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) +
                     _chunk(b"IDAT", zlib.compress(bytes(10_000_000))) + _chunk(b"IEND", b""))
    with pytest.raises(InvalidInput, match="larger than its header"):
        check_image(path)


def test_not_an_image(tmp_path):
    path = tmp_path / "x.png"
    path.write_bytes(b"GIF89a....")
    with pytest.raises(InvalidInput, match="not a PNG or JPEG"):
        check_image(path)
