"""Opening a bag with ``rosbags``' AnyReader and reading its messages; the reader's errors become
InvalidInput naming the bag (never the server's folders)."""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from storage.errors import InvalidInput, StorageError
from storage.ingest.bag.sniff import is_ros1_bag


def bag_error(bag: Path, exc: BaseException) -> InvalidInput:
    # the reader's messages name files by absolute path: keep their names, never the server's folders
    text = re.sub(r"(?<![\w.])/(?:[^\s'\"/]+/)+", "", str(exc)).strip() or type(exc).__name__
    return InvalidInput(f"{bag.name} is not a readable ROS bag (truncated or corrupt?): {text[:300]}",
                        {"file": bag.name, "reason": type(exc).__name__})


def open_reader(bag: Path) -> Any:
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
        raise bag_error(bag, exc) from None
    finally:
        if path is not bag:
            shutil.rmtree(path.parent, ignore_errors=True)
    return reader


def messages(reader: Any, conns: list[Any], bag: Path) -> Iterator[tuple[Any, int, bytes]]:
    it = iter(reader.messages(connections=conns))
    while True:
        try:
            item = next(it)
        except StopIteration:
            return
        except StorageError:
            raise
        except Exception as exc:  # a chunk cut off or corrupt mid-file
            raise bag_error(bag, exc) from None
        yield item
