"""Pipeline settings checked against their valid ranges before a job is queued.

The rules are ``formats.settings_check``'s, the same the worker applies when it builds the config, read from
the generated ``formats/settings_ranges.json`` so the api never imports the pipeline; sections the file does
not know (stage sections such as ``segmentation``) are left to the worker.
"""

from __future__ import annotations

from typing import Any

from formats.errors import SpecError
from formats.settings_check import check_config, settings_ranges
from storage.errors import InvalidInput

__all__ = ["check_ranges", "settings_ranges"]


def check_ranges(config: dict[str, Any]) -> None:
    """Every setting in ``config`` (nested or dotted overrides) of a known section exists, has its type
    and, where it declares one, lies in its range; then the ordered pairs (``below``/``at_most``: a minimum
    depth under the maximum), each side the override or else the default. :class:`InvalidInput` naming the
    field(s) and the range otherwise."""
    try:
        check_config(config)
    except SpecError as exc:
        raise InvalidInput(exc.message, exc.detail) from exc
