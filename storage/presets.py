"""Names the api validates against without importing the pipeline.

They come from ``formats.catalog``, the list the pipeline builds its presets and cameras from, so the api and
the worker cannot disagree.
"""

from __future__ import annotations

import math
from typing import Any

from formats import catalog
from storage.errors import InvalidInput
from storage.jsonlimits import check_json, parse_json

PIPELINE_PRESETS: tuple[str, ...] = tuple(p.name for p in catalog.PIPELINE_PRESETS)
"""Pipeline presets a job may name, most complete first."""

DEFAULT_PIPELINE_PRESET = catalog.DEFAULT_PIPELINE_PRESET
"""What a job runs when it names no preset."""

CAMERA_PRESETS: tuple[str, ...] = tuple(sorted(catalog.CAMERA_PRESETS))
"""Camera presets a sequence may name."""

FOCAL_PX = (50.0, 5000.0)
"""Plausible focal lengths in pixels (phones and RGB-D sensors: ~300-1500 at VGA)."""
SIZE_PX = (16, 16384)
DEPTH_SCALE = (1.0, 100_000.0)
"""Depth units per metre (TUM 5000, 7-Scenes 1000)."""
MAX_DIST = 10.0
DEFAULT_SIZE = (640, 480)
"""The image size intrinsics refer to when they give none (every camera preset's)."""
_CAMERA_NUMBERS = ("fx", "fy", "cx", "cy", "depth_scale")
_CAMERA_FIELDS = {*_CAMERA_NUMBERS, "width", "height", "dist", "name", "depth_registered"}


def check_preset(name: str) -> str:
    """``name`` if it is a known pipeline preset, else :class:`InvalidInput` listing the known ones."""
    if name not in PIPELINE_PRESETS:
        raise InvalidInput(
            f"unknown preset {name!r}; choose one of {', '.join(PIPELINE_PRESETS)}",
            {"preset": name, "allowed": list(PIPELINE_PRESETS)},
        )
    return name


def check_stages(config: dict[str, Any]) -> None:
    """A config's own ``stages`` list (when it gives one) must be one the pipeline can run: known stages, each
    once, each after the stages that provide what it needs (:func:`formats.catalog.check_stage_order`)."""
    if "stages" not in config:
        return
    stages = config["stages"]
    if not isinstance(stages, list) or not all(isinstance(s, str) for s in stages):
        raise InvalidInput("config stages must be a list of stage names", {"allowed": list(catalog.STAGE_CONTRACTS)})
    try:
        catalog.check_stage_order(stages)
    except catalog.StageOrderError as exc:
        raise InvalidInput(exc.message, exc.detail) from exc


def parse_camera_spec(spec: str | dict[str, Any]) -> dict[str, Any]:
    """A camera preset name or explicit intrinsics (a JSON object or dict), checked and normalised.

    Returns what ``Sequence.camera`` stores and the worker turns into its camera: ``{"preset": name}``
    or the intrinsics ``{"fx", "fy", "cx", "cy", "depth_scale"?, "width"?, "height"?, "dist"?, "name"?,
    "depth_registered"?}``.
    """
    if isinstance(spec, str):
        text = spec.strip()
        if not text.startswith("{"):
            if text not in CAMERA_PRESETS:
                raise InvalidInput(
                    f"unknown camera preset {text[:64]!r}; choose one of {', '.join(CAMERA_PRESETS)} "
                    "or give intrinsics as JSON",
                    {"camera": text[:64], "allowed": list(CAMERA_PRESETS)},
                )
            return {"preset": text}
        spec = parse_json(text, "camera")
    if not isinstance(spec, dict):
        raise InvalidInput("camera must be a preset name or a JSON object of intrinsics")
    check_json(spec, "camera")
    return check_intrinsics(spec)


def check_intrinsics(d: dict[str, Any]) -> dict[str, Any]:
    """Explicit intrinsics, finite and plausible: focal lengths within :data:`FOCAL_PX`, the principal
    point inside the image (``width`` x ``height``, else the presets' 640x480), sizes within
    :data:`SIZE_PX`, ``depth_scale`` within :data:`DEPTH_SCALE`, distortion within :data:`MAX_DIST`.
    (A width of 1e15 once gave a "succeeded" job with an ATE of 1e11 m.)"""
    unknown = sorted(set(d) - _CAMERA_FIELDS)
    if unknown:
        raise InvalidInput(f"unknown camera fields: {unknown}", {"allowed": sorted(_CAMERA_FIELDS)})
    missing = [k for k in ("fx", "fy", "cx", "cy") if k not in d]
    if missing:
        raise InvalidInput(f"camera intrinsics need {', '.join(missing)}", {"missing": missing})
    out: dict[str, Any] = {}
    for key in _CAMERA_NUMBERS:
        if key in d:
            out[key] = _positive(d[key], key)
    for key in ("width", "height"):
        if key in d:
            value = _positive(d[key], key)
            if not float(value).is_integer():
                raise InvalidInput(f"camera {key} must be an integer", {key: d[key]})
            out[key] = int(value)
    if "dist" in d:
        dist = d["dist"]
        if not isinstance(dist, list) or len(dist) not in (4, 5):
            raise InvalidInput("camera dist must be a list of 4 or 5 numbers (k1 k2 p1 p2 [k3])")
        out["dist"] = [_finite(v, "dist") for v in dist]
        if any(abs(v) > MAX_DIST for v in out["dist"]):
            raise InvalidInput(f"camera dist coefficients must be within -{MAX_DIST}..{MAX_DIST}", {"dist": dist})
    if "depth_registered" in d:
        if not isinstance(d["depth_registered"], bool):
            raise InvalidInput("camera depth_registered must be true or false",
                               {"depth_registered": str(d["depth_registered"])[:64]})
        out["depth_registered"] = d["depth_registered"]
    _check_plausible(out)
    if "name" in d:
        out["name"] = str(d["name"])[:64]
    return out


def _check_plausible(cam: dict[str, Any]) -> None:
    for key, (lo, hi) in (("fx", FOCAL_PX), ("fy", FOCAL_PX), ("width", SIZE_PX), ("height", SIZE_PX),
                          ("depth_scale", DEPTH_SCALE)):
        if key in cam and not lo <= cam[key] <= hi:
            raise InvalidInput(f"camera {key} must be within {lo:g}..{hi:g}, got {cam[key]:g}",
                               {"field": key, "min": lo, "max": hi, "value": cam[key]})
    width, height = cam.get("width", DEFAULT_SIZE[0]), cam.get("height", DEFAULT_SIZE[1])
    for key, size in (("cx", width), ("cy", height)):
        if not 0 < cam[key] < size:
            raise InvalidInput(f"camera {key} must lie inside the image (0..{size}), got {cam[key]:g}",
                               {"field": key, "min": 0, "max": size, "value": cam[key]})


def _finite(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InvalidInput(f"camera {key} must be a finite number", {key: value})
    return float(value)


def _positive(value: Any, key: str) -> float:
    f = _finite(value, key)
    if f <= 0:
        raise InvalidInput(f"camera {key} must be positive", {key: value})
    return f
