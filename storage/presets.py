"""Names the api validates against without importing the pipeline.

The pipeline's registries (``worker.slam.config`` presets, ``worker.slam.camera.PRESETS``) are the truth;
``tests/backend/api/test_presets.py`` checks these mirrors equal them, so adding a preset there fails the
suite until it is added here too.
"""

from __future__ import annotations

import json
import math
from typing import Any

from storage.errors import InvalidInput

PIPELINE_PRESETS: tuple[str, ...] = ("full", "no-restoration", "geometry-only", "orb-only")
"""Pipeline presets a job may name (``worker.slam.config.preset_names()``)."""

DEFAULT_PIPELINE_PRESET = "full"
"""What a job runs when it names no preset (``worker.slam.config.default_preset()``)."""

CAMERA_PRESETS: tuple[str, ...] = ("7scenes", "bonn", "tum1", "tum2", "tum3")
"""Camera presets a sequence may name (``worker.slam.camera.PRESETS``)."""

_CAMERA_NUMBERS = ("fx", "fy", "cx", "cy", "depth_scale")
_CAMERA_FIELDS = {*_CAMERA_NUMBERS, "width", "height", "dist", "name"}


def check_preset(name: str) -> str:
    """``name`` if it is a known pipeline preset, else :class:`InvalidInput` listing the known ones."""
    if name not in PIPELINE_PRESETS:
        raise InvalidInput(
            f"unknown preset {name!r}; choose one of {', '.join(PIPELINE_PRESETS)}",
            {"preset": name, "allowed": list(PIPELINE_PRESETS)},
        )
    return name


def parse_camera_spec(spec: str | dict[str, Any]) -> dict[str, Any]:
    """A camera preset name or explicit intrinsics (a JSON object or dict), checked and normalised.

    Returns what ``Sequence.camera`` stores and the worker turns into its camera: ``{"preset": name}``
    or the intrinsics ``{"fx", "fy", "cx", "cy", "depth_scale"?, "width"?, "height"?, "dist"?, "name"?}``.
    """
    if isinstance(spec, str):
        text = spec.strip()
        if not text.startswith("{"):
            if text not in CAMERA_PRESETS:
                raise InvalidInput(
                    f"unknown camera preset {text!r}; choose one of {', '.join(CAMERA_PRESETS)} "
                    "or give intrinsics as JSON",
                    {"camera": text, "allowed": list(CAMERA_PRESETS)},
                )
            return {"preset": text}
        try:
            spec = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InvalidInput(f"camera is not valid JSON: {exc}", {"camera": text[:200]}) from None
    if not isinstance(spec, dict):
        raise InvalidInput("camera must be a preset name or a JSON object of intrinsics")
    return check_intrinsics(spec)


def check_intrinsics(d: dict[str, Any]) -> dict[str, Any]:
    """Explicit intrinsics: fx, fy, cx, cy (and depth_scale) finite and positive, a positive size."""
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
    if "name" in d:
        out["name"] = str(d["name"])[:64]
    return out


def _finite(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InvalidInput(f"camera {key} must be a finite number", {key: value})
    return float(value)


def _positive(value: Any, key: str) -> float:
    f = _finite(value, key)
    if f <= 0:
        raise InvalidInput(f"camera {key} must be positive", {key: value})
    return f
