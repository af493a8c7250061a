"""Names the api validates against without importing the pipeline.

They come from ``formats.catalog``, the list the pipeline builds its presets and cameras from, so the api and
the worker cannot disagree.
"""

from __future__ import annotations

from typing import Any

from formats import camera_spec, catalog
from formats.errors import SpecError
from storage.errors import InvalidInput
from storage.jsonlimits import check_json, parse_json

PIPELINE_PRESETS: tuple[str, ...] = tuple(p.name for p in catalog.PIPELINE_PRESETS)
"""Pipeline presets a job may name, most complete first."""

DEFAULT_PIPELINE_PRESET = catalog.DEFAULT_PIPELINE_PRESET
"""What a job runs when it names no preset."""

CAMERA_PRESETS: tuple[str, ...] = tuple(sorted(catalog.CAMERA_PRESETS))
"""Camera presets a sequence may name."""

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
    "depth_registered"?, "groundtruth_frame"?}`` (``camera`` or ``bonn-marker``: what the ground truth is the pose
    of; the ``bonn`` preset says ``bonn-marker`` itself).
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
    """Explicit intrinsics, finite and plausible (``formats.camera_spec``'s rules, the worker's too),
    normalised; :class:`InvalidInput` naming the field otherwise."""
    try:
        return camera_spec.check_intrinsics(d)
    except SpecError as exc:
        raise InvalidInput(exc.message, exc.detail) from exc
