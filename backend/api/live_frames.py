"""One live session's incoming frames: checked like an upload's images, then kept in its sequence folder.

A frame is one binary WebSocket message::

    uint32 big-endian N | N bytes of JSON {"timestamp": seconds, "rgb": bytes, "depth": bytes} | colour | depth

colour a PNG or JPEG (8-bit grey, RGB or RGBA), depth a 16-bit single-channel PNG in the camera's depth
scale (TUM, Bonn: 5000 per metre), both the same size (at least 64x48), the same for the whole session,
timestamps strictly increasing. Images are fully verified (``storage.ingest.images``) before they are kept:
a frame is kept whole or not at all. A session holds at most as much as an upload may unpack to.
"""
from __future__ import annotations

import math
import os
import struct
from pathlib import Path

from storage.errors import Conflict, InvalidInput, PayloadTooLarge
from storage.faults import disk_full, insufficient_storage
from storage.ingest import upload_limits
from storage.ingest.images import ImageInfo, check_image
from storage.ingest.sequence import MIN_SIZE, read_groundtruth
from storage.jsonlimits import parse_json
from storage.live import LiveSpool, SpooledFrame
from storage.settings import Settings

MAX_FRAME_BYTES = 8 * 1024 * 1024
"""One frame's message (a 640x480 PNG pair is about 1.3 MB; uvicorn itself refuses messages over 16 MiB)."""
MAX_HEADER_BYTES = 4096
MAX_GROUNDTRUTH_CHARS = 8 * 1024 * 1024


class FrameReceiver:
    """Checks and keeps the frames of ``spool``'s session (one client, one thread at a time)."""

    def __init__(self, spool: LiveSpool, settings: Settings) -> None:
        self.spool = spool
        self.folder = spool.folder
        limits = upload_limits(settings)
        self.max_bytes, self.max_frames = limits.max_bytes, limits.max_files // 2
        self.frames = 0
        self.bytes = 0
        self.size: tuple[int, int] | None = None
        self.last_t = -math.inf

    def add(self, message: bytes, arrival: float) -> SpooledFrame:
        """Check and keep one frame message; raises InvalidInput / PayloadTooLarge saying what is wrong."""
        if len(message) > MAX_FRAME_BYTES:
            raise PayloadTooLarge(f"frame {self.frames}: {len(message)} bytes; a frame may have at most "
                                  f"{MAX_FRAME_BYTES} bytes", {"max_frame_bytes": MAX_FRAME_BYTES})
        if self.bytes + len(message) > self.max_bytes or self.frames >= self.max_frames:
            raise PayloadTooLarge("the session is full (it may hold as much as an upload unpacks to)",
                                  {"max_bytes": self.max_bytes, "max_frames": self.max_frames})
        t, rgb, depth = self._split(message)
        ext = ".jpg" if rgb[:2] == b"\xff\xd8" else ".png"
        name = f"{t:.6f}"
        rgb_rel, depth_rel = f"rgb/{name}{ext}", f"depth/{name}.png"
        tmp_rgb, tmp_depth = self.folder / "rgb" / f".{name}.tmp", self.folder / "depth" / f".{name}.tmp"
        frame = SpooledFrame(self.frames, t, round(arrival, 6), rgb_rel, depth_rel)
        try:
            tmp_rgb.write_bytes(rgb)
            tmp_depth.write_bytes(depth)
            self._check(check_image(tmp_rgb, label=rgb_rel), check_image(tmp_depth, label=depth_rel), depth_rel)
            os.replace(tmp_rgb, self.folder / rgb_rel)
            os.replace(tmp_depth, self.folder / depth_rel)
            self.spool.append(frame)
        except OSError as exc:  # the disk filled up, or the session's sequence was deleted meanwhile
            if disk_full(exc):
                raise insufficient_storage("keeping a live frame") from exc
            raise Conflict(f"{label_of(frame)}: the session's sequence cannot be written ({exc.strerror or exc}); "
                           "was it deleted?") from exc
        finally:
            tmp_rgb.unlink(missing_ok=True)
            tmp_depth.unlink(missing_ok=True)
        self.frames += 1
        self.bytes += len(message)
        self.last_t = t
        return frame

    def _split(self, message: bytes) -> tuple[float, bytes, bytes]:
        label = f"frame {self.frames}"
        if len(message) < 4:
            raise InvalidInput(f"{label}: too short for a frame message")
        (n,) = struct.unpack(">I", message[:4])
        if n > MAX_HEADER_BYTES or 4 + n > len(message):
            raise InvalidInput(f"{label}: the header length {n} is impossible")
        try:
            head = parse_json(message[4:4 + n].decode("utf-8"), f"{label} header")
        except UnicodeDecodeError:
            raise InvalidInput(f"{label}: the header is not UTF-8 JSON") from None
        if not isinstance(head, dict):
            raise InvalidInput(f"{label}: the header must be a JSON object")
        t, n_rgb, n_depth = head.get("timestamp"), head.get("rgb"), head.get("depth")
        if not isinstance(t, int | float) or isinstance(t, bool) or not math.isfinite(t) or t < 0:
            raise InvalidInput(f"{label}: 'timestamp' must be a finite number of seconds >= 0")
        if t <= self.last_t:
            raise InvalidInput(f"{label}: timestamp {t} is not after the previous frame's ({self.last_t})",
                               {"timestamp": t, "previous": self.last_t})
        if not (_count(n_rgb) and _count(n_depth)):
            raise InvalidInput(f"{label}: 'rgb' and 'depth' must be the images' byte counts")
        assert isinstance(n_rgb, int) and isinstance(n_depth, int)
        body = message[4 + n:]
        if len(body) != n_rgb + n_depth:
            raise InvalidInput(f"{label}: the header promises {n_rgb} + {n_depth} image bytes, the message has "
                               f"{len(body)}")
        return float(t), body[:n_rgb], body[n_rgb:]

    def _check(self, c: ImageInfo, d: ImageInfo, depth_label: str) -> None:
        label = f"frame {self.frames}"
        if c.bit_depth != 8 or c.color_type == 4:
            raise InvalidInput(f"{label}: colour images must be 8-bit grey, RGB or RGBA (PNG or JPEG)")
        if d.format != "png" or d.bit_depth != 16 or d.channels != 1:
            raise InvalidInput(f"{label}: depth images must be 16-bit single-channel PNG", {"file": depth_label})
        if (c.width, c.height) != (d.width, d.height):
            raise InvalidInput(f"{label}: depth is {d.width}x{d.height} but colour is {c.width}x{c.height}")
        if self.size is None and (c.width < MIN_SIZE[0] or c.height < MIN_SIZE[1]):
            raise InvalidInput(f"{label}: images are {c.width}x{c.height}; the pipeline needs at least "
                               f"{MIN_SIZE[0]}x{MIN_SIZE[1]} pixels")
        if self.size is not None and self.size != (c.width, c.height):
            raise InvalidInput(f"{label}: images are {c.width}x{c.height} but the session's are "
                               f"{self.size[0]}x{self.size[1]}")
        self.size = (c.width, c.height)

    def control(self, text: str) -> str:
        """A text message: ``{"type": "end"}``, ``{"type": "ping"}`` or ``{"type": "groundtruth", "text": TUM
        lines}``; its type."""
        if len(text) > MAX_GROUNDTRUTH_CHARS + 1024:
            raise PayloadTooLarge(f"a text message may have at most {MAX_GROUNDTRUTH_CHARS} characters")
        msg = parse_json(text, "message")
        kind = msg.get("type") if isinstance(msg, dict) else None
        if kind in ("end", "ping"):
            return kind
        if kind == "groundtruth" and isinstance(msg.get("text"), str):
            self._groundtruth(msg["text"])
            return kind
        raise InvalidInput('text messages are {"type": "end"}, {"type": "ping"} or '
                           '{"type": "groundtruth", "text": "..."}')

    def _groundtruth(self, text: str) -> None:
        """groundtruth.txt of the session (TUM), checked as an upload's; a bad one leaves none."""
        path: Path = self.folder / "groundtruth.txt"
        path.write_text(text, encoding="utf-8")
        try:
            read_groundtruth(self.folder)
        except BaseException:
            path.unlink(missing_ok=True)
            raise


def _count(v: object) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v > 0


def label_of(frame: SpooledFrame) -> str:
    return f"frame {frame.index}"
