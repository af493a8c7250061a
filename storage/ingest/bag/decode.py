"""Decoding messages: colour images (raw or JPEG/PNG), depth images (raw 16UC1/32FC1 or compressedDepth) to
16-bit PNG units, CameraInfo to a ``camera.json`` dict, and pose/tf messages to TUM poses."""

from __future__ import annotations

import math
import struct
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

from storage.errors import InvalidInput
from storage.ingest.bag.msgtypes import COLOUR_ENCODINGS, COMPRESSED, IMAGE, POSE_STAMPED, TF, TF_OLD, TRANSFORM_STAMPED

if TYPE_CHECKING:
    import numpy as np

DEPTH_SCALE = 5000.0
"""Depth PNG units per metre (TUM's)."""
MAX_DEPTH_M = 65535 / DEPTH_SCALE


def stamp_of(msg: Any, fallback_ns: int) -> float:
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is not None:
        t = stamp.sec + stamp.nanosec * 1e-9
        if t > 0:
            return t
    return fallback_ns * 1e-9


def _raw_array(msg: Any, dtype: Any, channels: int) -> np.ndarray:
    import numpy as np

    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8)
    itemsize = np.dtype(dtype).itemsize
    row = w * channels * itemsize
    if h <= 0 or w <= 0 or step < row or data.size < step * (h - 1) + row:
        raise InvalidInput(f"a {msg.encoding} image says {w}x{h} (step {step}) but holds {data.size} bytes",
                           {"encoding": str(msg.encoding)})
    if data.size < step * h:
        data = np.concatenate([data, np.zeros(step * h - data.size, np.uint8)])
    rows = data[: step * h].reshape(h, step)[:, :row]
    arr = np.ascontiguousarray(rows).view(np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<"))
    arr = arr.astype(np.dtype(dtype).newbyteorder("="), copy=False)
    return arr.reshape(h, w, channels) if channels > 1 else arr.reshape(h, w)


def decode_colour(msg: Any, msgtype: str) -> tuple[bytes | np.ndarray, str, tuple[int, int]]:
    """(bytes to write as is, or a BGR/grey array to encode; file suffix; (width, height))."""
    import cv2
    import numpy as np

    if msgtype == COMPRESSED:
        data = bytes(msg.data)
        fmt = str(msg.format).lower()
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise InvalidInput(f"a compressed colour image ({msg.format!r}) does not decode", {"format": msg.format})
        if img.dtype != np.uint8:
            raise InvalidInput(f"compressed colour images must be 8-bit, got {img.dtype} ({msg.format!r})",
                               {"format": msg.format})
        suffix = ".png" if data[:8] == b"\x89PNG\r\n\x1a\n" else ".jpg" if data[:2] == b"\xff\xd8" else ""
        if not suffix:
            raise InvalidInput(f"unsupported compressed colour format {fmt!r} (JPEG and PNG are read)",
                               {"format": msg.format})
        return data, suffix, (img.shape[1], img.shape[0])
    enc = str(msg.encoding).lower()
    if enc in ("rgb8", "bgr8", "8uc3"):
        arr = _raw_array(msg, np.uint8, 3)
        arr = arr[..., ::-1] if enc == "rgb8" else arr
    elif enc in ("rgba8", "bgra8", "8uc4"):
        arr = _raw_array(msg, np.uint8, 4)[..., :3]
        arr = arr[..., ::-1] if enc == "rgba8" else arr
    elif enc in ("mono8", "8uc1"):
        arr = _raw_array(msg, np.uint8, 1)
    else:
        raise InvalidInput(f"unsupported colour encoding {msg.encoding!r} (read: {', '.join(COLOUR_ENCODINGS)})",
                           {"encoding": str(msg.encoding)})
    return np.ascontiguousarray(arr), ".png", (arr.shape[1], arr.shape[0])


def _to_units(metres: np.ndarray) -> tuple[np.ndarray, int]:
    """Metres -> uint16 at DEPTH_SCALE; NaN/inf/<= 0 and depths past the PNG's range -> 0 (and their count)."""
    import numpy as np

    m = np.asarray(metres, dtype=np.float64)
    units = np.rint(np.nan_to_num(m, nan=0.0, posinf=0.0, neginf=0.0) * DEPTH_SCALE)
    far = units > 65535
    units[far | (units < 0)] = 0
    return units.astype(np.uint16), int(far.sum())


def decode_depth(msg: Any, msgtype: str) -> tuple[np.ndarray, int]:
    """(uint16 depth at DEPTH_SCALE, pixels dropped as too far)."""
    import cv2
    import numpy as np

    if msgtype == IMAGE:
        enc = str(msg.encoding).lower()
        if enc in ("16uc1", "mono16"):
            mm = _raw_array(msg, np.uint16, 1)
            return _to_units(np.where(mm == 0, np.nan, mm / 1000.0))
        if enc == "32fc1":
            return _to_units(_raw_array(msg, np.float32, 1))
        raise InvalidInput(f"unsupported depth encoding {msg.encoding!r} (read: 16UC1 in mm, 32FC1 in m)",
                           {"encoding": str(msg.encoding)})
    fmt = str(msg.format)
    data = bytes(msg.data)
    lower = fmt.lower()
    if "compresseddepth" in lower:
        if "rvl" in lower:
            raise InvalidInput(f"unsupported depth format {fmt!r} (compressedDepth PNG is read, not RVL)",
                               {"format": fmt})
        if len(data) < 12:
            raise InvalidInput("a compressedDepth image is shorter than its 12-byte header", {"format": fmt})
        _kind, quant_a, quant_b = struct.unpack("<iff", data[:12])
        img = cv2.imdecode(np.frombuffer(data[12:], np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None or img.dtype != np.uint16 or img.ndim != 2:
            raise InvalidInput(f"a compressedDepth image ({fmt!r}) does not decode to a 16-bit PNG", {"format": fmt})
        if "32fc1" in lower:  # inverse depth, quantised: depth = A / (v - B); 0 is invalid
            v = img.astype(np.float64)
            with np.errstate(divide="ignore", invalid="ignore"):
                metres = np.where(img == 0, np.nan, quant_a / (v - quant_b))
            return _to_units(metres)
        if "16uc1" in lower or ";" not in fmt:
            return _to_units(np.where(img == 0, np.nan, img / 1000.0))
        raise InvalidInput(f"unsupported compressedDepth format {fmt!r} (16UC1 and 32FC1 are read)", {"format": fmt})
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None or img.dtype != np.uint16 or img.ndim != 2:
        raise InvalidInput(f"unsupported compressed depth format {fmt!r} (compressedDepth, or a 16-bit PNG in mm)",
                           {"format": fmt})
    return _to_units(np.where(img == 0, np.nan, img / 1000.0))


def decode_camera(msg: Any, topic: str, notes: list[str]) -> dict[str, Any] | None:
    k = [float(v) for v in (msg.k if hasattr(msg, "k") else msg.K)]  # ROS 2 names them k, d; ROS 1 K, D
    d = [float(v) for v in (msg.d if hasattr(msg, "d") else msg.D)]
    model = str(msg.distortion_model)
    fx, fy, cx, cy = k[0], k[4], k[2], k[5]
    if fx <= 0 or fy <= 0:
        notes.append(f"{topic}: CameraInfo holds no calibration (K is zero); no camera.json written")
        return None
    cam: dict[str, Any] = {"name": f"bag {topic}"[:64], "fx": fx, "fy": fy, "cx": cx, "cy": cy,
                           "depth_scale": DEPTH_SCALE}
    if int(msg.width) > 0 and int(msg.height) > 0:
        cam["width"], cam["height"] = int(msg.width), int(msg.height)
    if any(v != 0 for v in d):
        extra = d[5:]
        if model not in ("plumb_bob", "rational_polynomial") or any(v != 0 for v in extra):
            raise InvalidInput(f"{topic}: distortion model {model!r} with coefficients {d[:8]} is not supported "
                               "(plumb_bob k1 k2 p1 p2 k3 is)", {"distortion_model": model})
        cam["dist"] = (d + [0.0] * 5)[:5]
    return cam


def _pose(msg: Any, msgtype: str) -> tuple[list[float], list[float]]:
    if msgtype == POSE_STAMPED:
        p, q = msg.pose.position, msg.pose.orientation
        return [p.x, p.y, p.z], [q.x, q.y, q.z, q.w]
    t, q = msg.transform.translation, msg.transform.rotation
    return [t.x, t.y, t.z], [q.x, q.y, q.z, q.w]


def gt_poses(
    msg: Any, msgtype: str, t_ns: int
) -> Iterator[tuple[float, list[float], list[float], tuple[str, str] | None]]:
    """(stamp, position, quaternion xyzw, tf's (parent, child) frames or None) of each pose in ``msg``."""
    if msgtype in (TF, TF_OLD):
        for tr in msg.transforms:
            pos, quat = _pose(tr, TRANSFORM_STAMPED)
            yield stamp_of(tr, t_ns), pos, quat, (str(tr.header.frame_id), str(tr.child_frame_id))
        return
    pos, quat = _pose(msg, msgtype)
    if all(math.isfinite(v) for v in (*pos, *quat)):
        yield stamp_of(msg, t_ns), pos, quat, None
