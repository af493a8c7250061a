"""Checking PNG and JPEG files without an image library: header, size, bit depth, and data integrity.

PNG files are fully verified (chunk CRCs, the zlib stream decompressed in bounded pieces to exactly the
size the header promises, row filter bytes); JPEG files structurally (markers, frame header, end of
image). Sizes are read from the header before any pixel data is touched (decompression bombs).
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

from storage.errors import InvalidInput

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
MAX_PIXELS = 4096 * 4096
_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
_ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2))


@dataclass(frozen=True, slots=True)
class ImageInfo:
    format: str  # "png" | "jpeg"
    width: int
    height: int
    bit_depth: int
    channels: int
    color_type: int | None = None  # PNG only


def _bad(label: str, message: str) -> InvalidInput:
    return InvalidInput(f"{label}: {message}", {"file": label})


def _too_large(label: str, width: int, height: int) -> InvalidInput:
    return _bad(label, f"image is too large ({width}x{height} = {width * height} pixels; "
                       f"the limit is {MAX_PIXELS} pixels, e.g. 4096x4096)")


def check_image(path: Path, *, verify: bool = True, label: str | None = None) -> ImageInfo:
    """Header facts of a PNG or JPEG file; with ``verify`` the whole file's integrity too.

    ``label`` names the file in errors (the sequence-relative path, e.g. ``rgb/1.png``); default its name.
    """
    label = label or path.name
    data = path.read_bytes() if verify else _head(path)
    if data[:8] == PNG_MAGIC:
        return _png(label, data, verify)
    if data[:2] == b"\xff\xd8":
        return _jpeg(label, data, verify)
    raise _bad(label, "not a PNG or JPEG image")


def _head(path: Path) -> bytes:
    with open(path, "rb") as fh:
        return fh.read(65536)


def _png(label: str, data: bytes, verify: bool) -> ImageInfo:
    if len(data) < 33 or data[12:16] != b"IHDR":
        raise _bad(label, "truncated PNG header")
    width, height, depth, ctype, _comp, _filt, interlace = struct.unpack(">IIBBBBB", data[16:29])
    if ctype not in _PNG_CHANNELS or depth not in (1, 2, 4, 8, 16) or width == 0 or height == 0:
        raise _bad(label, "invalid PNG header")
    if width * height > MAX_PIXELS:
        raise _too_large(label, width, height)
    info = ImageInfo("png", width, height, depth, _PNG_CHANNELS[ctype], ctype)
    if verify:
        _verify_png(label, data, info, interlace)
    return info


def _raw_size(info: ImageInfo, interlace: int) -> int:
    bpp = info.channels * info.bit_depth

    def rows(w: int, h: int) -> int:
        return 0 if w == 0 or h == 0 else h * (1 + (w * bpp + 7) // 8)

    if not interlace:
        return rows(info.width, info.height)
    total = 0
    for x0, y0, dx, dy in _ADAM7:
        total += rows((info.width - x0 + dx - 1) // dx, (info.height - y0 + dy - 1) // dy)
    return total


def _verify_png(label: str, data: bytes, info: ImageInfo, interlace: int) -> None:
    pos, idat, seen_end = 8, [], False
    while pos + 12 <= len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind = data[pos + 4 : pos + 8]
        body = data[pos + 8 : pos + 8 + length]
        crc = data[pos + 8 + length : pos + 12 + length]
        if len(body) != length or len(crc) != 4:
            raise _bad(label, "truncated PNG")
        if zlib.crc32(kind + body) != struct.unpack(">I", crc)[0]:
            raise _bad(label, f"PNG chunk {kind.decode('latin-1')!r} is corrupt (CRC mismatch)")
        if kind == b"IDAT":
            idat.append(body)
        elif kind == b"IEND":
            seen_end = True
            break
        pos += 12 + length
    if not seen_end or not idat:
        raise _bad(label, "truncated PNG (no image data or no end)")
    expected = _raw_size(info, interlace)
    dec = zlib.decompressobj()
    size = 0
    stream = b"".join(idat)
    try:
        while True:  # bounded pieces: a lying stream can never expand past `expected`+1 bytes
            piece = dec.decompress(stream, max(1, expected + 1 - size))
            stream = dec.unconsumed_tail
            size += len(piece)
            if not interlace and piece:
                _check_filters(label, piece, size - len(piece), info)
            if size > expected:
                raise _bad(label, "PNG data is larger than its header says")
            if dec.eof or not stream:
                break
    except zlib.error as exc:
        raise _bad(label, f"PNG data is corrupt ({exc})") from None
    if size != expected or not dec.eof:
        raise _bad(label, f"PNG data is truncated ({size} of {expected} bytes)")


def _check_filters(label: str, piece: bytes, offset: int, info: ImageInfo) -> None:
    stride = 1 + (info.width * info.channels * info.bit_depth + 7) // 8
    first = (-offset) % stride
    if any(b > 4 for b in piece[first::stride]):
        raise _bad(label, "PNG data is corrupt (bad row filter)")


def _jpeg(label: str, data: bytes, verify: bool) -> ImageInfo:
    i, info, sos = 2, None, None
    while i + 4 <= len(data):
        if data[i] != 0xFF:
            raise _bad(label, "corrupt JPEG (bad marker)")
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        (seg_len,) = struct.unpack(">H", data[i + 2 : i + 4])
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            if i + 10 > len(data):
                raise _bad(label, "truncated JPEG header")
            precision = data[i + 4]
            height, width = struct.unpack(">HH", data[i + 5 : i + 9])
            info = ImageInfo("jpeg", width, height, precision, data[i + 9])
        if marker == 0xDA:
            sos = i
            break
        i += 2 + seg_len
    if info is None or info.width == 0 or info.height == 0:
        raise _bad(label, "JPEG without a valid frame header")
    if info.width * info.height > MAX_PIXELS:
        raise _too_large(label, info.width, info.height)
    if verify and (sos is None or data.rfind(b"\xff\xd9") < sos):
        raise _bad(label, "truncated JPEG (no end of image)")
    return info


def png_is_blank(path: Path, *, label: str | None = None) -> bool:
    """True when every sample of the PNG is 0 (a depth image with no valid pixel), decided on the filtered
    data: a PNG row filter predicts 0 from zeros, so the pixels are all 0 exactly when every filtered byte
    (row filter types aside) is. Decompresses in bounded pieces, to the size the header promises."""
    label = label or path.name
    data = path.read_bytes()
    info = _png(label, data, verify=False)
    interlace = data[28]
    pos, idat = 8, []
    while pos + 12 <= len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        if data[pos + 4 : pos + 8] == b"IDAT":
            idat.append(data[pos + 8 : pos + 8 + length])
        pos += 12 + length
    expected = _raw_size(info, interlace)
    try:
        raw = zlib.decompressobj().decompress(b"".join(idat), expected + 1)
    except zlib.error as exc:
        raise _bad(label, f"PNG data is corrupt ({exc})") from None
    bpp = info.channels * info.bit_depth
    passes = [(info.width, info.height)] if not interlace else [
        ((info.width - x0 + dx - 1) // dx, (info.height - y0 + dy - 1) // dy) for x0, y0, dx, dy in _ADAM7]
    offset = nonzero_filters = 0
    for w, h in passes:
        if w == 0 or h == 0:
            continue
        stride = 1 + (w * bpp + 7) // 8
        filters = raw[offset : offset + stride * h : stride]
        nonzero_filters += len(filters) - filters.count(0)
        offset += stride * h
    return len(raw) - raw.count(0) == nonzero_filters
