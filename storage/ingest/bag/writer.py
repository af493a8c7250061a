"""The staging folder an import writes: colour and depth images named by their stamps, and TUM's lists of
them (strictly increasing), within the import's :class:`~storage.ingest.bag.types.BagLimits`."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from storage.errors import PayloadTooLarge, StorageError
from storage.ingest.bag.types import BagLimits

if TYPE_CHECKING:
    import numpy as np


def _write(path: Path, data: bytes) -> None:
    """One image file; an OSError (a full disk) passes through: the upload maps it to a 507."""
    path.write_bytes(data)


class Writer:
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
