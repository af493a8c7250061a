"""The pipeline settings' valid ranges as data, for the api (which never imports the pipeline).

``formats/settings_ranges.json`` lists every setting (type, default) with the valid range its
``valid(...)`` field declares, and is generated from the config dataclasses and committed; a test
regenerates it and fails on any difference. Regenerate after changing a config dataclass:

    .venv/bin/python -m worker.slam.ranges
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

from formats.settings_check import kind_of
from worker.slam.catalog import shipped_catalog

RANGES_FILE = Path(__file__).resolve().parents[2] / "formats" / "settings_ranges.json"


def settings_ranges() -> dict[str, dict[str, Any]]:
    """Every setting of every section (core and the shipped stages'), nested ones dotted, in declaration
    order: ``{"features.n_levels": {"type": "int", "default": 8, "min": 1, "max": 16}, "dense.enabled":
    {"type": "bool", "default": true}, ...}``; ``min``/``max`` where the field declares a range."""
    cfg = shipped_catalog().base_config()
    out: dict[str, dict[str, Any]] = {}
    for name in cfg.to_dict():
        value = getattr(cfg, name, None) if name in ("name", "stages") else cfg.section(name)
        if dataclasses.is_dataclass(value):
            _walk(value, name, out)
    return out


def _walk(obj: Any, prefix: str, out: dict[str, dict[str, Any]]) -> None:
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        key = f"{prefix}.{f.name}"
        if dataclasses.is_dataclass(value):
            _walk(value, key, out)
            continue
        entry: dict[str, Any] = {"type": kind_of(value), "default": _json_value(value)}
        bounds = f.metadata.get("range")
        if bounds is not None:
            entry["min"], entry["max"] = bounds
        if "choices" in f.metadata:  # the names a list setting's items may take
            entry["choices"] = list(f.metadata["choices"])
        for rel in ("below", "at_most"):  # the field that bounds this one (storage.config_ranges checks it)
            if rel in f.metadata:
                entry[rel] = f"{prefix}.{f.metadata[rel]}"
        out[key] = entry


def _json_value(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_json_value(v) for v in value]
    if value is None or isinstance(value, bool | int | float | str | list | dict):
        return value
    return str(value)


def render() -> str:
    return json.dumps(settings_ranges(), indent=1) + "\n"


def main() -> None:
    RANGES_FILE.write_text(render(), encoding="utf-8")
    print(f"wrote {RANGES_FILE}")


if __name__ == "__main__":
    main()
