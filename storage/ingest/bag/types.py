"""What a bag import returns, and the bounds it works within."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


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
