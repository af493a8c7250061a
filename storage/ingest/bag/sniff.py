"""Telling a bag from an archive: by a file's magic bytes, or a ROS 2 bag folder by its ``metadata.yaml``."""

from __future__ import annotations

from pathlib import Path

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


def is_ros1_bag(path: Path) -> bool:
    """Whether ``path`` starts with ROS 1's ``#ROSBAG V2.0`` magic."""
    return sniff_bag(path) == "ros1"
