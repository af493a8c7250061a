"""The import itself: a bag's chosen topics read in one pass into a staging folder beside ``out`` (images,
TUM lists, ``camera.json``, ``groundtruth.txt``), checked as an upload is and renamed into place; a bag that
fails leaves nothing."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from storage.errors import InvalidInput
from storage.ingest.bag.decode import MAX_DEPTH_M, decode_camera, decode_colour, decode_depth, gt_poses, stamp_of
from storage.ingest.bag.msgtypes import TF, TF_OLD
from storage.ingest.bag.reader import bag_error, messages, open_reader
from storage.ingest.bag.topics import Topics
from storage.ingest.bag.types import BagImport, BagLimits
from storage.ingest.bag.writer import Writer
from storage.ingest.sequence import validate_sequence


def import_uploaded_bag(upload: Path, kind: str, out: Path, limits: BagLimits) -> BagImport:
    """:func:`import_bag` of an uploaded file (stored without its name) that
    :func:`~storage.ingest.bag.sniff.sniff_bag` called ``kind``; the reader tells ROS 2's storages apart by
    suffix, so the file is renamed to carry one."""
    if kind in ("mcap", "db3"):
        upload = upload.rename(upload.with_name(f"{upload.name}.{kind}"))
    return import_bag(upload, out, limits=limits)


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


@dataclass(slots=True)
class _Gathered:
    """What the pass over the messages collects beside the images the writer holds."""

    tf_pair: tuple[str, str] | None
    """The tf (parent, child) frames ground truth is read from: the caller's, else the first seen."""
    gt_lines: list[str] = field(default_factory=list)
    far: int = 0
    """Depth pixels dropped as beyond the PNG's range."""


def _convert(
    bag: Path, root: Path, *, rgb: str | None, depth: str | None, info: str | None, gt: str | None,
    gt_frames: tuple[str, str] | None, limits: BagLimits,
) -> BagImport:
    reader = open_reader(bag)
    try:
        topics = Topics(reader, bag)
        rgb_topic, depth_topic, info_topic, gt_topic = topics.choose(rgb=rgb, depth=depth, info=info, gt=gt)
        result = BagImport("ros1" if not reader.is2 else "ros2", rgb_topic, depth_topic, info_topic, gt_topic)
        if info_topic is None:
            result.notes.append("no CameraInfo topic: no camera.json written (give the camera when running)")
        writer = Writer(root, limits)
        gathered = _Gathered(gt_frames)
        _read(reader, bag, result, writer, gathered)
        _finish(root, result, writer, gathered)
        return result
    finally:
        try:
            reader.close()
        except Exception:  # a reader that failed half-way may not close cleanly; the error raised wins
            pass


def _read(reader: Any, bag: Path, result: BagImport, writer: Writer, gathered: _Gathered) -> None:
    """One pass over the chosen topics' messages: images to ``writer``, the camera to ``result``, poses to
    ``gathered``."""
    rgb_topic, depth_topic = result.rgb_topic, result.depth_topic
    info_topic, gt_topic = result.info_topic, result.gt_topic
    wanted = {rgb_topic, depth_topic} | {t for t in (info_topic, gt_topic) if t}
    conns = [c for c in reader.connections if c.topic in wanted]
    for conn, t_ns, raw in messages(reader, conns, bag):
        try:
            msg = reader.deserialize(raw, conn.msgtype)
        except Exception as exc:
            raise bag_error(bag, exc) from None
        if conn.topic == rgb_topic:
            payload, suffix, _size = decode_colour(msg, conn.msgtype)
            result.rgb_frames += writer.add("rgb", stamp_of(msg, t_ns), payload, suffix)
        elif conn.topic == depth_topic:
            units, dropped = decode_depth(msg, conn.msgtype)
            gathered.far += dropped
            result.depth_frames += writer.add("depth", stamp_of(msg, t_ns), units, ".png")
        elif info_topic is not None and conn.topic == info_topic:
            if result.camera is None and not any(n.startswith(f"{info_topic}:") for n in result.notes):
                result.camera = decode_camera(msg, info_topic, result.notes)
        elif conn.topic == gt_topic:
            for stamp, pos, quat, pair in gt_poses(msg, conn.msgtype, t_ns):
                if conn.msgtype in (TF, TF_OLD):
                    gathered.tf_pair = gathered.tf_pair or pair
                    if pair != gathered.tf_pair:
                        continue
                gathered.gt_lines.append(f"{stamp:.6f} " + " ".join(f"{v + 0.0:.9g}" for v in (*pos, *quat)))


def _finish(root: Path, result: BagImport, writer: Writer, gathered: _Gathered) -> None:
    """Check what the pass found, then write the lists, ``camera.json`` and ``groundtruth.txt``."""
    if not result.rgb_frames:
        raise InvalidInput(f"colour topic {result.rgb_topic!r} holds no images", {"topic": result.rgb_topic})
    if not result.depth_frames:
        raise InvalidInput(f"depth topic {result.depth_topic!r} holds no images", {"topic": result.depth_topic})
    writer.write_lists()
    for kind, n in writer.skipped.items():
        if n:
            result.notes.append(f"{n} {kind} images skipped: their header stamp repeats or precedes the one "
                                "before (TUM lists strictly increase)")
    if gathered.far:
        result.notes.append(f"{gathered.far} depth pixels beyond {MAX_DEPTH_M:.3f} m were marked invalid (0)")
    if result.camera is not None:
        (root / "camera.json").write_text(json.dumps(result.camera, indent=2) + "\n", encoding="utf-8")
    if result.gt_topic is not None:
        result.gt_poses = _write_gt(root, result.gt_topic, gathered)


def _write_gt(root: Path, gt_topic: str, gathered: _Gathered) -> int:
    """``groundtruth.txt`` sorted by time; the number of poses in it."""
    gt_lines, tf_pair = gathered.gt_lines, gathered.tf_pair
    if not gt_lines:
        wanted_pair = f" {tf_pair[0]} -> {tf_pair[1]}" if tf_pair else ""
        raise InvalidInput(f"ground-truth topic {gt_topic!r} holds no poses{wanted_pair}", {"topic": gt_topic})
    gt_lines.sort(key=lambda line: float(line.split()[0]))
    header = f"# ground truth from {gt_topic}" + (f" ({tf_pair[0]} -> {tf_pair[1]})" if tf_pair else "")
    (root / "groundtruth.txt").write_text("\n".join([header, "# timestamp tx ty tz qx qy qz qw", *gt_lines])
                                          + "\n", encoding="utf-8")
    return len(gt_lines)
