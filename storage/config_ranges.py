"""Pipeline settings checked against their valid ranges before a job is queued.

The ranges are the pipeline's own (``valid(...)`` fields of ``worker.slam.config``), read from the
generated ``formats/settings_ranges.json`` so the api never imports the pipeline. The worker checks the
same ranges again when it builds the config; sections the file does not know (stage sections such as
``segmentation``) are left to it.
"""

from __future__ import annotations

import json
from functools import cache
from importlib import resources
from typing import Any

from storage.errors import InvalidInput


@cache
def settings_ranges() -> dict[str, dict[str, Any]]:
    """``{"features.n_levels": {"type", "min", "max", "default"}, ...}`` (read once per process)."""
    text = resources.files("formats").joinpath("settings_ranges.json").read_text(encoding="utf-8")
    data: dict[str, dict[str, Any]] = json.loads(text)
    return data


def check_ranges(config: dict[str, Any]) -> None:
    """Every setting in ``config`` (nested or dotted overrides) of a known section exists, and a ranged
    one has the right type and lies in its range; :class:`InvalidInput` naming the field and the range."""
    ranges = settings_ranges()
    sections = {key.split(".", 1)[0] for key in ranges}
    for key, value in _flatten(config):
        if key.split(".", 1)[0] not in sections:
            continue  # not a settings section (name, stages) or one the worker checks itself
        spec = ranges.get(key)
        if spec is None:
            if not any(ranges.get(prefix, {}).get("type") == "dict" for prefix in _prefixes(key)):
                raise InvalidInput(f"unknown config field {key!r}", {"field": key})
            continue
        if "min" not in spec:
            continue
        lo, hi = spec["min"], spec["max"]
        detail = {"field": key, "min": lo, "max": hi, "value": value if _is_number(value) else str(value)[:64]}
        if not _is_number(value) or (spec["type"] == "int" and not float(value).is_integer()):
            raise InvalidInput(f"config {key} must be {'an integer' if spec['type'] == 'int' else 'a number'} "
                               f"within {lo}..{hi}", detail)
        if not lo <= value <= hi:
            raise InvalidInput(f"config {key} must be within {lo}..{hi}, got {value!r}", detail)


def _prefixes(key: str) -> list[str]:
    parts = key.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _flatten(config: dict[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    for key, value in config.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.extend(_flatten(value, name + "."))
        else:
            out.append((name, value))
    return out
