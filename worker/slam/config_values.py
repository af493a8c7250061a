"""Setting values from a (partial, possibly dotted) dict on the config dataclasses, with the checks the api
applies too (`formats.settings_check`): types kept, ranges and ordered pairs enforced, unknown keys refused."""
from __future__ import annotations

import dataclasses
from typing import Any

from formats.errors import SpecError
from formats.settings_check import PAIR_RULES, check_pair, check_setting, kind_of
from worker.slam.errors import ConfigError


def expand_dotted(d: dict) -> dict:
    """`{"a.b.c": 1, "a.b.d": 2}` -> `{"a": {"b": {"c": 1, "d": 2}}}` (merged deeply, not overwritten)."""
    out: dict[str, Any] = {}
    for key, val in d.items():
        if "." in key:
            head, _, rest = key.partition(".")
            key, val = head, expand_dotted({rest: val})
        elif isinstance(val, dict):
            val = expand_dotted(val)
        if isinstance(val, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], val)
        elif key in out and (isinstance(val, dict) or isinstance(out[key], dict)):
            raise ConfigError(f"config key {key!r} is given both as a value and as a section")
        else:
            out[key] = val
    return out


def _merge(a: dict, b: dict) -> dict:
    out = dict(a)
    for k, v in b.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def apply_values(obj: Any, values: dict, where: str) -> Any:
    """Set `values` on the dataclass `obj`; returns it (or, for a frozen dataclass, an updated copy)."""
    fields = {f.name: f for f in dataclasses.fields(obj)}
    changes: dict[str, Any] = {}
    for key, val in values.items():
        if key not in fields:
            raise ConfigError(f"unknown config field {where}.{key}", detail={"field": f"{where}.{key}"})
        cur = getattr(obj, key)
        if dataclasses.is_dataclass(cur) and isinstance(val, dict):
            changes[key] = apply_values(cur, val, f"{where}.{key}")
        elif isinstance(cur, tuple) and isinstance(val, (list, tuple)):
            changes[key] = tuple(val)
        else:
            changes[key] = _coerce(cur, val, f"{where}.{key}", fields[key].metadata.get("range"))
    if type(obj).__dataclass_params__.frozen:
        try:
            obj = dataclasses.replace(obj, **changes)  # runs the section's own checks (__post_init__)
        except ValueError as exc:
            raise ConfigError(f"invalid value in {where}: {exc}", detail={"field": where}) from exc
    else:
        for key, val in changes.items():
            setattr(obj, key, val)
        check = getattr(obj, "__post_init__", None)
        if check is not None and changes:
            try:
                check()
            except ValueError as exc:
                raise ConfigError(f"invalid value in {where}: {exc}", detail={"field": where}) from exc
    _check_pairs(obj, where)
    return obj


def _check_pairs(obj: Any, where: str) -> None:
    """Each ``below``/``at_most`` pair of ``obj`` (see :func:`valid`) in order, else a :class:`ConfigError`
    naming both fields (``formats.settings_check``'s rule, which the api applies to the published ranges)."""
    for f in dataclasses.fields(obj):
        for rule in PAIR_RULES:
            other = f.metadata.get(rule)
            if other is None:
                continue
            try:
                check_pair(rule, f"{where}.{f.name}", getattr(obj, f.name), f"{where}.{other}", getattr(obj, other))
            except SpecError as exc:
                raise ConfigError(exc.message, detail=exc.detail) from exc


def _coerce(current: Any, val: Any, where: str, bounds: tuple[float, float] | None = None) -> Any:
    """``val`` with the field's type (bools stay bools, ints stay ints) and within its ``bounds``, so a bad
    snapshot fails early and clearly: ``formats.settings_check``'s rules, the api's too."""
    try:
        return check_setting(where, val, kind_of(current), bounds)
    except SpecError as exc:
        raise ConfigError(exc.message, detail=exc.detail) from exc
