"""The pipeline settings' rules, one checker for both sides of the api/worker wall.

A setting's spec is what ``formats/settings_ranges.json`` publishes (generated from the config dataclasses by
``worker.slam.ranges``): its ``type`` (``bool``, ``int``, ``float``, ``str``; others are not checked here),
or for a list of names the ``choices`` its items may take, optionally a valid range ``min..max`` (inclusive)
and a ``below``/``at_most`` partner that bounds it from above.
The api checks a job's config against the published specs with :func:`check_config`; the worker checks each
override of its dataclasses with :func:`check_setting` and :func:`check_pair`. Both raise
:class:`formats.errors.SpecError` naming the field, which each side turns into its own error class.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from functools import cache
from importlib import resources
from typing import Any

from formats.errors import SpecError

SettingsSpecs = Mapping[str, Mapping[str, Any]]
"""``{"features.n_levels": {"type": "int", "default": 8, "min": 1, "max": 16}, ...}``, dotted keys."""

PAIR_RULES: dict[str, tuple[str, Callable[[Any, Any], bool]]] = {
    "below": ("below", lambda lo, hi: lo < hi),
    "at_most": ("at most", lambda lo, hi: lo <= hi),
}
"""The cross-field rules a spec may name: the lower end of a pair whose ranges each hold but could contradict
each other (a minimum depth above the maximum)."""

_TRUE, _FALSE = ("true", "1", "yes"), ("false", "0", "no")
_KIND_WORDS = {"int": "an integer", "float": "a finite number", "bool": "true or false", "str": "a string"}


@cache
def settings_ranges() -> dict[str, dict[str, Any]]:
    """The published specs of every setting (read once per process), in declaration order."""
    text = resources.files("formats").joinpath("settings_ranges.json").read_text(encoding="utf-8")
    data: dict[str, dict[str, Any]] = json.loads(text)
    return data


def kind_of(default: Any) -> str:
    """The spec type of a setting whose default is ``default`` (bools before ints: a bool is an int):
    ``bool``, ``int``, ``float``, ``str`` (checked), ``list`` (a tuple too), ``dict``, ``null`` or the
    Python type's name (published, not checked)."""
    for kind, name in ((bool, "bool"), (int, "int"), (float, "float"), (str, "str"), (list | tuple, "list"),
                       (dict, "dict")):
        if isinstance(default, kind):
            return name
    return "null" if default is None else type(default).__name__


def check_setting(key: str, value: Any, kind: str, bounds: tuple[float, float] | None = None) -> Any:
    """``value`` of setting ``key`` as its ``kind``, within ``bounds`` (``lo, hi``, inclusive) when given.

    Returns it normalised: ints as ``int`` (an integral float too), floats as ``float``, bools as ``bool``
    (also from the strings true/false, 1/0, yes/no). Any other kind passes unchecked. A wrong type or a value
    out of range is a :class:`SpecError` naming the field and the range."""
    ok, normal = _normalise(value, kind)
    if not ok:
        within = "" if bounds is None else f" within {bounds[0]}..{bounds[1]}"
        raise SpecError(f"config {key} must be {_KIND_WORDS[kind]}{within}, got {_shown(value)}",
                        _detail(key, value, bounds))
    if bounds is not None and not bounds[0] <= normal <= bounds[1]:
        raise SpecError(f"config {key} must be within {bounds[0]}..{bounds[1]}, got {value!r}",
                        _detail(key, value, bounds))
    return normal


def check_choices(key: str, value: Any, choices: list[str]) -> None:
    """``value`` of the list setting ``key`` is None, a list of names or a comma-separated string of names, each
    one of ``choices``; else a :class:`SpecError` naming the field and the first unknown name."""
    if value is None:
        return
    names = [n.strip() for n in value.split(",") if n.strip()] if isinstance(value, str) else value
    if not isinstance(names, list | tuple) or not all(isinstance(n, str) for n in names):
        raise SpecError(f"config {key} must be a list of names, got {_shown(value)}", {"field": key})
    unknown = [n for n in names if n not in choices]
    if unknown:
        raise SpecError(f"config {key}: unknown name {unknown[0]!r}", {"field": key, "value": unknown[0][:64],
                                                                       "allowed": list(choices)})


def check_pair(rule: str, lo_key: str, lo: Any, hi_key: str, hi: Any) -> None:
    """``lo`` (of ``lo_key``) is ``below``/``at_most`` (the ``rule``) ``hi`` (of ``hi_key``), else a
    :class:`SpecError` naming both fields."""
    words, ok = PAIR_RULES[rule]
    if not ok(lo, hi):
        raise SpecError(f"config {lo_key} ({lo!r}) must be {words} {hi_key} ({hi!r})",
                        {"field": lo_key, "fields": [lo_key, hi_key], "values": [lo, hi]})


def check_config(config: Mapping[str, Any], specs: SettingsSpecs | None = None) -> None:
    """Every setting in ``config`` (nested or dotted overrides) of a section ``specs`` knows exists, and has
    its type and range; then every pair, each side the override or else the default (presets differ only in
    their stages). Sections it does not know (name, stages, a stage's own section) are left to the worker."""
    specs = settings_ranges() if specs is None else specs
    sections = {key.split(".", 1)[0] for key in specs}
    flat = _flatten(config)
    for key, value in flat:
        if key.split(".", 1)[0] not in sections:
            continue
        spec = specs.get(key)
        if spec is None:
            if not any(specs.get(prefix, {}).get("type") == "dict" for prefix in _prefixes(key)):
                raise SpecError(f"unknown config field {key!r}", {"field": key})
            continue
        if "choices" in spec:
            check_choices(key, value, spec["choices"])
        else:
            check_setting(key, value, spec["type"], (spec["min"], spec["max"]) if "min" in spec else None)
    given = dict(flat)
    for lo_key, spec in specs.items():
        for rule in PAIR_RULES:
            hi_key = spec.get(rule)
            if hi_key is not None and (lo_key in given or hi_key in given):
                check_pair(rule, lo_key, given.get(lo_key, spec["default"]), hi_key,
                           given.get(hi_key, specs[hi_key]["default"]))


def _normalise(value: Any, kind: str) -> tuple[bool, Any]:
    """(whether ``value`` is a ``kind``, its normal form)."""
    if kind == "bool":
        if isinstance(value, bool):
            return True, value
        text = value.lower() if isinstance(value, str) else None
        return text in _TRUE + _FALSE, text in _TRUE
    if kind in ("int", "float"):
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            return False, value
        if kind == "int":
            return float(value).is_integer(), int(value)
        return True, float(value)
    if kind == "str":
        return isinstance(value, str), value
    return True, value


def _detail(key: str, value: Any, bounds: tuple[float, float] | None) -> dict[str, Any]:
    shown = value if isinstance(value, int | float) and not isinstance(value, bool) else str(value)[:64]
    out: dict[str, Any] = {"field": key, "value": shown}
    if bounds is not None:
        out["min"], out["max"] = bounds
    return out


def _shown(value: Any) -> str:
    return repr(value) if not isinstance(value, str) else repr(value[:64])


def _prefixes(key: str) -> list[str]:
    parts = key.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def _flatten(config: Mapping[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    for key, value in config.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.extend(_flatten(value, name + "."))
        else:
            out.append((name, value))
    return out
