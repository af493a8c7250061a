"""The rules of explicit camera intrinsics, one checker for the api (an upload's camera) and the worker
(``vtdslam run --camera '{...}'``, a sequence's ``camera.json``).

A spec is a JSON object ``{"fx", "fy", "cx", "cy", "depth_scale"?, "width"?, "height"?, "dist"?, "name"?,
"depth_registered"?, "groundtruth_frame"?}``: focal lengths and principal point in pixels, ``depth_scale``
depth units per metre, ``dist`` OpenCV's k1 k2 p1 p2 [k3], ``groundtruth_frame`` what the sequence's ground
truth is the pose of (a name of ``formats.catalog.GROUNDTRUTH_FRAMES``: ``camera``, the default, or
``bonn-marker``). :func:`check_intrinsics` raises :class:`formats.errors.SpecError`, which the api answers as
422 and the worker as CameraError.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from formats.catalog import CAMERA_PRESETS, DEFAULT_GROUNDTRUTH_FRAME, GROUNDTRUTH_FRAMES
from formats.errors import SpecError

FOCAL_PX = (50.0, 5000.0)
"""Plausible focal lengths in pixels (phones and RGB-D sensors: ~300-1500 at VGA)."""
SIZE_PX = (16, 16384)
DEPTH_SCALE = (1.0, 100_000.0)
"""Depth units per metre (TUM 5000, 7-Scenes 1000)."""
MAX_DIST = 10.0
DEFAULT_SIZE = (640, 480)
"""The image size intrinsics refer to when they give none (every camera preset's)."""
CAMERA_NUMBERS = ("fx", "fy", "cx", "cy", "depth_scale")
CAMERA_FIELDS = frozenset({*CAMERA_NUMBERS, "width", "height", "dist", "name", "depth_registered",
                           "groundtruth_frame"})


def check_intrinsics(d: Mapping[str, Any]) -> dict[str, Any]:
    """Explicit intrinsics, finite and plausible: focal lengths within :data:`FOCAL_PX`, the principal
    point inside the image (``width`` x ``height``, else the presets' 640x480), sizes within
    :data:`SIZE_PX`, ``depth_scale`` within :data:`DEPTH_SCALE`, 4 or 5 distortion coefficients within
    :data:`MAX_DIST`. (A width of 1e15 once gave a "succeeded" job with an ATE of 1e11 m.)

    Returns them normalised: numbers as ``float``, sizes as ``int``, ``dist`` a list of floats as given (4 or
    5), ``name`` at most 64 characters; keys not given stay absent."""
    unknown = sorted(set(d) - CAMERA_FIELDS)
    if unknown:
        raise SpecError(f"unknown camera fields: {unknown}", {"allowed": sorted(CAMERA_FIELDS)})
    missing = [k for k in ("fx", "fy", "cx", "cy") if k not in d]
    if missing:
        raise SpecError(f"camera intrinsics need {', '.join(missing)}", {"missing": missing})
    out: dict[str, Any] = {}
    for key in CAMERA_NUMBERS:
        if key in d:
            out[key] = _positive(d[key], key)
    for key in ("width", "height"):
        if key in d:
            value = _positive(d[key], key)
            if not float(value).is_integer():
                raise SpecError(f"camera {key} must be an integer", {key: d[key]})
            out[key] = int(value)
    if "dist" in d:
        dist = d["dist"]
        if not isinstance(dist, list | tuple) or len(dist) not in (4, 5):
            raise SpecError("camera dist must be a list of 4 or 5 numbers (k1 k2 p1 p2 [k3])")
        out["dist"] = [_finite(v, "dist") for v in dist]
        if any(abs(v) > MAX_DIST for v in out["dist"]):
            raise SpecError(f"camera dist coefficients must be within -{MAX_DIST}..{MAX_DIST}", {"dist": list(dist)})
    if "depth_registered" in d:
        if not isinstance(d["depth_registered"], bool):
            raise SpecError("camera depth_registered must be true or false",
                            {"depth_registered": str(d["depth_registered"])[:64]})
        out["depth_registered"] = d["depth_registered"]
    if "groundtruth_frame" in d:
        frame = d["groundtruth_frame"]
        if frame not in GROUNDTRUTH_FRAMES:
            raise SpecError(f"camera groundtruth_frame must be one of {', '.join(GROUNDTRUTH_FRAMES)}",
                            {"groundtruth_frame": str(frame)[:64], "allowed": list(GROUNDTRUTH_FRAMES)})
        out["groundtruth_frame"] = frame
    _check_plausible(out)
    if "name" in d:
        out["name"] = str(d["name"])[:64]
    return out


def groundtruth_frame_of(spec: Mapping[str, Any] | None) -> str:
    """What a stored camera spec (``{"preset": name}`` or explicit intrinsics) says its sequence's ground truth
    is the pose of; ``camera`` when it says nothing (a sequence's own camera.json wins in the worker)."""
    if not isinstance(spec, Mapping):
        return DEFAULT_GROUNDTRUTH_FRAME
    preset = CAMERA_PRESETS.get(spec["preset"]) if isinstance(spec.get("preset"), str) else None
    frame = preset.groundtruth_frame if preset is not None else spec.get("groundtruth_frame")
    return frame if isinstance(frame, str) and frame in GROUNDTRUTH_FRAMES else DEFAULT_GROUNDTRUTH_FRAME


def _check_plausible(cam: dict[str, Any]) -> None:
    for key, (lo, hi) in (("fx", FOCAL_PX), ("fy", FOCAL_PX), ("width", SIZE_PX), ("height", SIZE_PX),
                          ("depth_scale", DEPTH_SCALE)):
        if key in cam and not lo <= cam[key] <= hi:
            raise SpecError(f"camera {key} must be within {lo:g}..{hi:g}, got {cam[key]:g}",
                            {"field": key, "min": lo, "max": hi, "value": cam[key]})
    width, height = cam.get("width", DEFAULT_SIZE[0]), cam.get("height", DEFAULT_SIZE[1])
    for key, size in (("cx", width), ("cy", height)):
        if not 0 < cam[key] < size:
            raise SpecError(f"camera {key} must lie inside the image (0..{size}), got {cam[key]:g}",
                            {"field": key, "min": 0, "max": size, "value": cam[key]})


def _finite(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise SpecError(f"camera {key} must be a finite number", {key: value})
    return float(value)


def _positive(value: Any, key: str) -> float:
    f = _finite(value, key)
    if f <= 0:
        raise SpecError(f"camera {key} must be positive", {key: value})
    return f
