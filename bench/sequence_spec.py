"""The benchmarks' `DIR[:CAMERA]` arguments: a sequence folder and, optionally, its camera.

CAMERA is a preset name (`bonn`, `7scenes`, ...) or a JSON object of intrinsics (which holds colons itself);
left out, the folder's own `camera.json` describes it (`vtdslam synth` and `vtdslam augment` write one), as the
sequence reader does whenever a folder has one.
"""
from __future__ import annotations

from worker.slam.camera import Camera, parse_camera


def split_spec(spec: str) -> tuple[str, str | None]:
    """(folder, camera text or None) of `DIR[:CAMERA]`."""
    head, brace, tail = spec.partition(":{")
    if brace:
        return head, "{" + tail
    folder, colon, camera = spec.rpartition(":")
    if not colon:
        return spec, None
    return folder, camera or None


def camera_of(camera: str | None) -> Camera | None:
    """The `Camera` of a spec's camera text; None (the folder's camera.json) when it gave none."""
    return parse_camera(camera) if camera else None
