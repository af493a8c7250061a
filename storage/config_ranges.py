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
    one has the right type and lies in its range; :class:`InvalidInput` naming the field and the range.
    Then the ordered pairs (``below``/``at_most``: a minimum depth under the maximum), each side the
    override or else the default (presets differ only in their stages), naming both fields."""
    ranges = settings_ranges()
    sections = {key.split(".", 1)[0] for key in ranges}
    flat = _flatten(config)
    for key, value in flat:
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
    _check_pairs(ranges, dict(flat))


_PAIRS = (("below", "below", lambda lo, hi: lo < hi), ("at_most", "at most", lambda lo, hi: lo <= hi))


def _check_pairs(ranges: dict[str, dict[str, Any]], given: dict[str, Any]) -> None:
    for lo_key, spec in ranges.items():
        for rel, words, ok in _PAIRS:
            hi_key = spec.get(rel)
            if hi_key is None or (lo_key not in given and hi_key not in given):
                continue
            lo, hi = given.get(lo_key, spec["default"]), given.get(hi_key, ranges[hi_key]["default"])
            if not ok(lo, hi):
                raise InvalidInput(f"config {lo_key} ({lo!r}) must be {words} {hi_key} ({hi!r})",
                                   {"field": lo_key, "fields": [lo_key, hi_key], "values": [lo, hi]})


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
