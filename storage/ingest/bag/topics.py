"""Which topics an import reads: colour and depth images (by the first message's encoding, then by name), the
CameraInfo nearest the colour topic and a ground-truth pose topic, or the ones the caller named (checked)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from storage.errors import InvalidInput, StorageError
from storage.ingest.bag.msgtypes import (
    CAMERA_INFO,
    DEPTH_ENCODINGS,
    GT_TYPES,
    IMAGE,
    IMAGE_TYPES,
    POSE_STAMPED,
    TRANSFORM_STAMPED,
)
from storage.ingest.bag.reader import bag_error

GT_HINTS = ("groundtruth", "ground_truth", "vicon", "mocap", "optitrack")


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


def _gt_name(topic: str) -> bool:
    """A pose topic whose name says it is ground truth (``/groundtruth``, ``/vicon/cam/pose``, ``/gt``)."""
    lower = topic.lower().replace("-", "_")
    return any(h in lower for h in GT_HINTS) or "gt" in lower.strip("/").split("/")


class Topics:
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
            raise bag_error(self.bag, exc) from None
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

    def choose(
        self, *, rgb: str | None, depth: str | None, info: str | None, gt: str | None
    ) -> tuple[str, str, str | None, str | None]:
        """(colour, depth, camera info or None, ground truth or None): the named ones, else the best found."""
        colours, depths = ([], []) if rgb and depth else self.images()
        rgb_topic = self.named(rgb, IMAGE_TYPES, "colour") if rgb else (colours[0] if colours else None)
        depth_topic = self.named(depth, IMAGE_TYPES, "depth") if depth else (depths[0] if depths else None)
        if rgb_topic is None:
            raise InvalidInput("the bag has no colour image topic (sensor_msgs/Image or CompressedImage with a "
                               "colour encoding); name one with --rgb", self.listing())
        if depth_topic is None:
            raise InvalidInput("the bag has no depth image topic (16UC1, 32FC1 or compressedDepth); name one "
                               "with --depth", self.listing())
        if rgb_topic == depth_topic:
            raise InvalidInput(f"colour and depth are both {rgb_topic!r}", self.listing())
        infos = [n for n, t in self.types.items() if t == CAMERA_INFO]
        info_topic = self.named(info, (CAMERA_INFO,), "camera info") if info else (
            max(sorted(infos), key=lambda n: _common_prefix(n, rgb_topic)) if infos else None)
        gt_topic = self.named(gt, GT_TYPES, "ground truth") if gt else next(
            (n for n, t in sorted(self.types.items()) if t in (POSE_STAMPED, TRANSFORM_STAMPED) and _gt_name(n)),
            None)
        return rgb_topic, depth_topic, info_topic, gt_topic
