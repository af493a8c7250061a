"""The pipeline settings' valid ranges as data, for the api (which never imports the pipeline).

``formats/settings_ranges.json`` is generated from the ``valid(...)`` fields of ``worker.slam.config``
and committed; a test regenerates it and fails on any difference. Regenerate after changing a range:

    .venv/bin/python -m worker.slam.ranges
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

from worker.slam.config import PipelineConfig

RANGES_FILE = Path(__file__).resolve().parents[2] / "formats" / "settings_ranges.json"


def settings_ranges() -> dict[str, dict[str, Any]]:
    """``{"features.n_levels": {"type": "int", "min": 1, "max": 16, "default": 8}, ...}`` for every
    ranged field of the core sections, in declaration order."""
    cfg = PipelineConfig()
    out: dict[str, dict[str, Any]] = {}
    for section in dataclasses.fields(cfg):
        value = getattr(cfg, section.name)
        if not dataclasses.is_dataclass(value):
            continue
        for f in dataclasses.fields(value):
            bounds = f.metadata.get("range")
            if bounds is None:
                continue
            default = getattr(value, f.name)
            out[f"{section.name}.{f.name}"] = {
                "type": "int" if isinstance(default, int) else "float",
                "min": bounds[0],
                "max": bounds[1],
                "default": default,
            }
    return out


def render() -> str:
    return json.dumps(settings_ranges(), indent=1) + "\n"


def main() -> None:
    RANGES_FILE.write_text(render(), encoding="utf-8")
    print(f"wrote {RANGES_FILE}")


if __name__ == "__main__":
    main()
