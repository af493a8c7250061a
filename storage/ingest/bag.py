"""Importing a ROS recording (ROS 1 ``.bag``, ROS 2 ``.db3``/``.mcap`` file or bag folder) as a TUM-layout
sequence, without a ROS installation (the pure-Python ``rosbags`` reader).

Topics are found automatically (``sensor_msgs/Image`` or ``CompressedImage``: depth by encoding, then by name;
``CameraInfo`` nearest the colour topic) or named by the caller. Colour: raw ``rgb8``/``bgr8``/``rgba8``/
``bgra8``/``mono8`` (written as PNG) or compressed JPEG/PNG (written as received). Depth: raw ``16UC1``/``mono16``
(millimetres) or ``32FC1`` (metres), or ``compressedDepth`` (12-byte header + PNG), written as 16-bit PNG at
:data:`DEPTH_SCALE` units per metre (NaN, 0 and depths beyond the PNG's range become 0, invalid). Each image
keeps its header stamp; colour and depth are then paired by time as TUM's lists are. ``camera.json`` comes from
CameraInfo (fx fy cx cy, width, height, plumb_bob distortion k1 k2 p1 p2 k3), ``groundtruth.txt`` from an
optional PoseStamped / TransformStamped / tf topic.

Everything is written to a staging folder beside ``out``, checked as an upload is
(:func:`storage.ingest.sequence.validate_sequence`) and renamed into place: a bag that fails leaves nothing.
``rosbags``, numpy and OpenCV are imported when a bag is read, never when this module is.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import struct
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from storage.errors import InvalidInput, PayloadTooLarge, StorageError
from storage.ingest.sequence import validate_sequence

if TYPE_CHECKING:
    import numpy as np

DEPTH_SCALE = 5000.0
"""Depth PNG units per metre (TUM's)."""
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
TRANSFORM_STAMPED = "geometry_msgs/msg/TransformStamped"
TF = "tf2_msgs/msg/TFMessage"
TF_OLD = "tf/msg/tfMessage"
GT_TYPES = (POSE_STAMPED, TRANSFORM_STAMPED, TF, TF_OLD)
IMAGE_TYPES = (IMAGE, COMPRESSED)
COLOUR_ENCODINGS = ("rgb8", "bgr8", "rgba8", "bgra8", "mono8", "8uc1", "8uc3", "8uc4")
DEPTH_ENCODINGS = ("16uc1", "mono16", "32fc1")
GT_HINTS = ("groundtruth", "ground_truth", "vicon", "mocap", "optitrack")
MAX_DEPTH_M = 65535 / DEPTH_SCALE


@dataclass(slots=True)
class BagImport:
    """What an import found and wrote."""

    bag_format: str
    """``ros1`` or ``ros2``."""
    rgb_topic: str
    depth_topic: str
    info_topic: str | None
    gt_topic: str | None
    rgb_frames: int = 0
    depth_frames: int = 0
    gt_poses: int = 0
    frames: int = 0
    """Associated colour/depth pairs."""
    camera: dict[str, Any] | None = None
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in self.__slots__}


@dataclass(frozen=True, slots=True)
class BagLimits:
    """Bounds on what an import may write (the api passes its upload limits)."""

    max_files: int | None = None
    max_bytes: int | None = None


MAGIC = {"ros1": b"#ROSBAG V2.0\n", "mcap": b"\x89MCAP0\r\n", "db3": b"SQLite format 3\x00"}
"""What an uploaded file starts with when it is a bag: ROS 1 ``.bag``, ROS 2 ``.mcap``, ROS 2 ``.db3``."""


def sniff_bag(path: Path) -> str | None:
    """``ros1``, ``mcap`` or ``db3`` by magic bytes; None for anything else (an archive)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(16)
    except OSError:
        return None
    return next((kind for kind, magic in MAGIC.items() if head.startswith(magic)), None)


def find_bag_folder(folder: Path) -> Path | None:
    """A ROS 2 bag folder (``metadata.yaml`` beside its .db3/.mcap files) at the top of an unpacked archive or
    in its one top-level folder; None otherwise."""
    if (folder / "metadata.yaml").is_file():
        return folder
    entries = [p for p in folder.iterdir() if not p.name.startswith(".") and p.name != "__MACOSX"]
    if len(entries) == 1 and entries[0].is_dir() and (entries[0] / "metadata.yaml").is_file():
        return entries[0]
    return None


def import_uploaded_bag(upload: Path, kind: str, out: Path, limits: BagLimits) -> BagImport:
    """:func:`import_bag` of an uploaded file (stored without its name) that :func:`sniff_bag` called ``kind``;
    the reader tells ROS 2's storages apart by suffix, so the file is renamed to carry one."""
    if kind in ("mcap", "db3"):
        upload = upload.rename(upload.with_name(f"{upload.name}.{kind}"))
    return import_bag(upload, out, limits=limits)


def is_ros1_bag(path: Path) -> bool:
    """Whether ``path`` starts with ROS 1's ``#ROSBAG V2.0`` magic."""
    return sniff_bag(path) == "ros1"


def import_bag(
    bag: Path,
    out: Path,
    *,
    rgb: str | None = None,
    depth: str | None = None,
    info: str | None = None,
    gt: str | None = None,
    gt_frames: tuple[str, str] | None = None,
    limits: BagLimits | None = None,
) -> BagImport:
    """Convert ``bag`` into the new sequence folder ``out`` (which must not exist); raises InvalidInput
    (PayloadTooLarge past ``limits``) and leaves no ``out`` on any failure."""
    bag, out = Path(bag), Path(out)
    if out.exists():
        raise InvalidInput(f"{out} exists already: the import writes a new folder", {"path": str(out)})
    if not bag.exists():
        raise InvalidInput(f"no bag at {bag}", {"path": str(bag)})
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.import-", dir=out.parent))
    try:
        result = _convert(bag, staging, rgb=rgb, depth=depth, info=info, gt=gt, gt_frames=gt_frames,
                          limits=limits or BagLimits())
        seq = validate_sequence(staging)
        result.frames = seq.frames
        os.rename(staging, out)
        return result
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


# --- reading -------------------------------------------------------------------------------------------------


def _bag_error(bag: Path, exc: BaseException) -> InvalidInput:
    # the reader's messages name files by absolute path: keep their names, never the server's folders
    text = re.sub(r"(?<![\w.])/(?:[^\s'\"/]+/)+", "", str(exc)).strip() or type(exc).__name__
    return InvalidInput(f"{bag.name} is not a readable ROS bag (truncated or corrupt?): {text[:300]}",
                        {"file": bag.name, "reason": type(exc).__name__})


def _open_reader(bag: Path) -> Any:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    ros1 = bag.is_file() and bag.suffix != ".mcap" and bag.suffix != ".db3"
    if ros1 and not is_ros1_bag(bag):
        raise InvalidInput(f"{bag.name} is not a ROS bag: no '#ROSBAG V2.0' header (ROS 1), and not a ROS 2 "
                           ".db3/.mcap file or bag folder", {"file": bag.name})
    # AnyReader picks ROS 1 by the .bag suffix: a ROS 1 bag under another name (or a ROS 2 folder named
    # *.bag) is read through a link
    path = bag
    if ros1 != (bag.suffix == ".bag"):
        link_dir = Path(tempfile.mkdtemp(prefix="vtd-bag-"))
        path = link_dir / ("input.bag" if ros1 else "input")
        os.symlink(bag.resolve(), path)
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.LATEST)
    reader = AnyReader([path], default_typestore=store)
    try:
        reader.open()
    except Exception as exc:  # rosbags' reader errors, struct/sqlite/EOF errors of a cut-off file
        raise _bag_error(bag, exc) from None
    finally:
        if path is not bag:
            shutil.rmtree(path.parent, ignore_errors=True)
    return reader


def _stamp(msg: Any, fallback_ns: int) -> float:
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is not None:
        t = stamp.sec + stamp.nanosec * 1e-9
        if t > 0:
            return t
    return fallback_ns * 1e-9


def _encoding(msg: Any, msgtype: str) -> str:
    return str(msg.encoding if msgtype == IMAGE else msg.format).lower()


def _is_depth_encoding(encoding: str, msgtype: str) -> bool:
    if msgtype == IMAGE:
        return encoding in DEPTH_ENCODINGS
    return "compresseddepth" in encoding or "16uc1" in encoding or "32fc1" in encoding


def _common_prefix(a: str, b: str) -> int:
    parts_a, parts_b = a.strip("/").split("/"), b.strip("/").split("/")
    n = 0
    for x, y in zip(parts_a, parts_b):
        if x != y:
            break
        n += 1
    return n


class _Topics:
    def __init__(self, reader: Any, bag: Path) -> None:
        self.reader = reader
        self.bag = bag
        self.types: dict[str, str] = {name: str(t.msgtype) for name, t in reader.topics.items()}

    def connections(self, topic: str) -> list[Any]:
        return [c for c in self.reader.connections if c.topic == topic]

    def first(self, topic: str) -> Any | None:
        try:
            for conn, _t, raw in self.reader.messages(connections=self.connections(topic)):
                return self.reader.deserialize(raw, conn.msgtype)
        except StorageError:
            raise
        except Exception as exc:
            raise _bag_error(self.bag, exc) from None
        return None

    def named(self, topic: str, wanted: tuple[str, ...], role: str) -> str:
        if topic not in self.types:
            raise InvalidInput(f"the bag has no topic {topic!r} (for {role})", {"topic": topic, **self.listing()})
        if self.types[topic] not in wanted:
            raise InvalidInput(f"topic {topic!r} is {self.types[topic]}, not {' or '.join(wanted)} (for {role})",
                               {"topic": topic, **self.listing()})
        return topic

    def listing(self) -> dict[str, Any]:
        return {"topics": {k: v for k, v in sorted(self.types.items())[:50]}}

    def images(self) -> tuple[list[str], list[str]]:
        """Colour and depth candidates, best first: by the first message's encoding, then by name."""
        colour: list[tuple[int, str]] = []
        depth: list[tuple[int, str]] = []
        for name, msgtype in sorted(self.types.items()):
            if msgtype not in IMAGE_TYPES:
                continue
            lower = name.lower()
            msg = self.first(name)
            enc = _encoding(msg, msgtype) if msg is not None else ""
            if _is_depth_encoding(enc, msgtype) or (not enc and "depth" in lower):
                depth.append((0 if "registered" in lower or "aligned" in lower else 1, name))
            elif "depth" not in lower and "disparity" not in lower and "ir" not in lower.split("/"):
                score = 0 if any(k in lower for k in ("rgb", "color", "colour")) else 1
                colour.append((score + (0 if msgtype == IMAGE else 2), name))
        return [n for _s, n in sorted(colour)], [n for _s, n in sorted(depth)]


# --- decoding --------------------------------------------------------------------------------------------------


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


def _colour(msg: Any, msgtype: str) -> tuple[bytes | np.ndarray, str, tuple[int, int]]:
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


def _depth(msg: Any, msgtype: str) -> tuple[np.ndarray, int]:
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


def _camera(msg: Any, topic: str, notes: list[str]) -> dict[str, Any] | None:
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


# --- converting ----------------------------------------------------------------------------------------------


def _write(path: Path, data: bytes) -> None:
    """One image file; an OSError (a full disk) passes through: the upload maps it to a 507."""
    path.write_bytes(data)


class _Writer:
    def __init__(self, root: Path, limits: BagLimits) -> None:
        self.root = root
        self.limits = limits
        self.files = 0
        self.bytes = 0
        self.lists: dict[str, list[tuple[float, str]]] = {"rgb": [], "depth": []}
        self.skipped = {"rgb": 0, "depth": 0}
        (root / "rgb").mkdir()
        (root / "depth").mkdir()

    def _count(self, size: int) -> None:
        self.files += 1
        self.bytes += size
        if self.limits.max_files is not None and self.files > self.limits.max_files:
            raise PayloadTooLarge(f"the bag holds more than {self.limits.max_files} images",
                                  {"max_files": self.limits.max_files})
        if self.limits.max_bytes is not None and self.bytes > self.limits.max_bytes:
            raise PayloadTooLarge(f"the bag's images take more than {self.limits.max_bytes} bytes",
                                  {"max_bytes": self.limits.max_bytes})

    def add(self, kind: str, t: float, payload: bytes | np.ndarray, suffix: str) -> bool:
        import cv2

        listed = self.lists[kind]
        name = f"{t:.6f}"
        if listed and (t <= listed[-1][0] or listed[-1][1] == f"{kind}/{name}{suffix}"):
            self.skipped[kind] += 1  # a repeated or out-of-order stamp: TUM lists strictly increase
            return False
        if not isinstance(payload, bytes):
            ok, encoded = cv2.imencode(suffix, payload)
            if not ok:
                raise StorageError(f"could not encode a {kind} image as {suffix}")
            payload = encoded.tobytes()
        rel = f"{kind}/{name}{suffix}"
        self._count(len(payload))
        _write(self.root / rel, payload)
        listed.append((t, rel))
        return True

    def write_lists(self) -> None:
        for kind, listed in self.lists.items():
            lines = [f"# {kind} images imported from a ROS bag", "# timestamp filename"]
            lines += [f"{t:.6f} {rel}" for t, rel in listed]
            (self.root / f"{kind}.txt").write_text("\n".join(lines) + "\n", encoding="utf-8")


def _convert(
    bag: Path, root: Path, *, rgb: str | None, depth: str | None, info: str | None, gt: str | None,
    gt_frames: tuple[str, str] | None, limits: BagLimits,
) -> BagImport:
    import json

    reader = _open_reader(bag)
    try:
        topics = _Topics(reader, bag)
        colours, depths = ([], []) if rgb and depth else topics.images()
        rgb_topic = topics.named(rgb, IMAGE_TYPES, "colour") if rgb else (colours[0] if colours else None)
        depth_topic = topics.named(depth, IMAGE_TYPES, "depth") if depth else (depths[0] if depths else None)
        if rgb_topic is None:
            raise InvalidInput("the bag has no colour image topic (sensor_msgs/Image or CompressedImage with a "
                               "colour encoding); name one with --rgb", topics.listing())
        if depth_topic is None:
            raise InvalidInput("the bag has no depth image topic (16UC1, 32FC1 or compressedDepth); name one "
                               "with --depth", topics.listing())
        if rgb_topic == depth_topic:
            raise InvalidInput(f"colour and depth are both {rgb_topic!r}", topics.listing())
        infos = [n for n, t in topics.types.items() if t == CAMERA_INFO]
        info_topic = topics.named(info, (CAMERA_INFO,), "camera info") if info else (
            max(sorted(infos), key=lambda n: _common_prefix(n, rgb_topic)) if infos else None)
        gt_topic = topics.named(gt, GT_TYPES, "ground truth") if gt else next(
            (n for n, t in sorted(topics.types.items()) if t in (POSE_STAMPED, TRANSFORM_STAMPED) and _gt_name(n)),
            None)
        result = BagImport("ros1" if not reader.is2 else "ros2", rgb_topic, depth_topic, info_topic, gt_topic)
        if info_topic is None:
            result.notes.append("no CameraInfo topic: no camera.json written (give the camera when running)")
        writer = _Writer(root, limits)
        gt_lines: list[str] = []
        tf_pair: tuple[str, str] | None = gt_frames
        far = 0
        wanted = {rgb_topic, depth_topic} | {t for t in (info_topic, gt_topic) if t}
        conns = [c for c in reader.connections if c.topic in wanted]
        for conn, t_ns, raw in _messages(reader, conns, bag):
            try:
                msg = reader.deserialize(raw, conn.msgtype)
            except Exception as exc:
                raise _bag_error(bag, exc) from None
            if conn.topic == rgb_topic:
                payload, suffix, _size = _colour(msg, conn.msgtype)
                result.rgb_frames += writer.add("rgb", _stamp(msg, t_ns), payload, suffix)
            elif conn.topic == depth_topic:
                units, dropped = _depth(msg, conn.msgtype)
                far += dropped
                result.depth_frames += writer.add("depth", _stamp(msg, t_ns), units, ".png")
            elif info_topic is not None and conn.topic == info_topic:
                if result.camera is None and not any(n.startswith(f"{info_topic}:") for n in result.notes):
                    result.camera = _camera(msg, info_topic, result.notes)
            elif conn.topic == gt_topic:
                for stamp, pos, quat, pair in _gt_poses(msg, conn.msgtype, t_ns):
                    if conn.msgtype in (TF, TF_OLD):
                        tf_pair = tf_pair or pair
                        if pair != tf_pair:
                            continue
                    gt_lines.append(f"{stamp:.6f} " + " ".join(f"{v + 0.0:.9g}" for v in (*pos, *quat)))
        if not result.rgb_frames:
            raise InvalidInput(f"colour topic {rgb_topic!r} holds no images", {"topic": rgb_topic})
        if not result.depth_frames:
            raise InvalidInput(f"depth topic {depth_topic!r} holds no images", {"topic": depth_topic})
        writer.write_lists()
        for kind, n in writer.skipped.items():
            if n:
                result.notes.append(f"{n} {kind} images skipped: their header stamp repeats or precedes the one "
                                    "before (TUM lists strictly increase)")
        if far:
            result.notes.append(f"{far} depth pixels beyond {MAX_DEPTH_M:.3f} m were marked invalid (0)")
        if result.camera is not None:
            (root / "camera.json").write_text(json.dumps(result.camera, indent=2) + "\n", encoding="utf-8")
        if gt_topic is not None:
            if not gt_lines:
                wanted_pair = f" {tf_pair[0]} -> {tf_pair[1]}" if tf_pair else ""
                raise InvalidInput(f"ground-truth topic {gt_topic!r} holds no poses{wanted_pair}", {"topic": gt_topic})
            gt_lines.sort(key=lambda line: float(line.split()[0]))
            header = f"# ground truth from {gt_topic}" + (f" ({tf_pair[0]} -> {tf_pair[1]})" if tf_pair else "")
            (root / "groundtruth.txt").write_text("\n".join([header, "# timestamp tx ty tz qx qy qz qw", *gt_lines])
                                                  + "\n", encoding="utf-8")
            result.gt_poses = len(gt_lines)
        return result
    finally:
        try:
            reader.close()
        except Exception:  # a reader that failed half-way may not close cleanly; the error raised wins
            pass


def _messages(reader: Any, conns: list[Any], bag: Path) -> Iterator[tuple[Any, int, bytes]]:
    it = iter(reader.messages(connections=conns))
    while True:
        try:
            item = next(it)
        except StopIteration:
            return
        except StorageError:
            raise
        except Exception as exc:  # a chunk cut off or corrupt mid-file
            raise _bag_error(bag, exc) from None
        yield item


def _gt_poses(msg: Any, msgtype: str, t_ns: int) -> Iterator[tuple[float, list[float], list[float],
                                                                    tuple[str, str] | None]]:
    if msgtype in (TF, TF_OLD):
        for tr in msg.transforms:
            pos, quat = _pose(tr, TRANSFORM_STAMPED)
            yield _stamp(tr, t_ns), pos, quat, (str(tr.header.frame_id), str(tr.child_frame_id))
        return
    pos, quat = _pose(msg, msgtype)
    if all(math.isfinite(v) for v in (*pos, *quat)):
        yield _stamp(msg, t_ns), pos, quat, None


def _gt_name(topic: str) -> bool:
    """A pose topic whose name says it is ground truth (``/groundtruth``, ``/vicon/cam/pose``, ``/gt``)."""
    lower = topic.lower().replace("-", "_")
    return any(h in lower for h in GT_HINTS) or "gt" in lower.strip("/").split("/")
