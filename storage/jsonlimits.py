"""What any JSON a client sends (request bodies, camera specs, a sequence's camera.json) may hold.

Refused at the edge with :class:`InvalidInput` (422), before it reaches a query or a column: nesting
deeper than :data:`MAX_DEPTH` (the listings' encoders and the worker recurse: a config 255 deep once
broke every listing), non-finite numbers (``NaN``/``Infinity``, or ``1e400`` which parses as inf:
PostgreSQL's JSON refuses them and the error handler could not encode them), integers beyond 64 bits,
and NUL characters in strings or keys (PostgreSQL text refuses them).
"""

from __future__ import annotations

import json
import math
from typing import Any

from storage.errors import InvalidInput

MAX_DEPTH = 32
"""Configs are two levels deep (``{"section": {"key": value}}``); 32 leaves room, 255 broke listings."""
MAX_INT = 2**63


class _Refused(ValueError):
    pass


def _no_constants(name: str) -> Any:
    raise _Refused(f"{name} is not a finite number")


def parse_json(text: str | bytes, what: str) -> Any:
    """``text`` parsed and checked (see the module); :class:`InvalidInput` naming ``what`` otherwise."""
    try:
        value = json.loads(text, parse_constant=_no_constants)
    except _Refused as exc:
        raise InvalidInput(f"{what}: {exc}", {"what": what}) from None
    except RecursionError:
        raise InvalidInput(f"{what}: JSON nested deeper than {MAX_DEPTH} levels", {"what": what}) from None
    except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError, an integer of over 4300 digits
        raise InvalidInput(f"{what}: not valid JSON ({str(exc)[:200]})", {"what": what}) from None
    check_json(value, what)
    return value


def check_json(value: Any, what: str) -> None:
    """Check an already parsed value (iteratively: the check itself never recurses)."""
    stack: list[tuple[Any, int]] = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict | list):
            if depth > MAX_DEPTH:
                raise InvalidInput(f"{what}: JSON nested deeper than {MAX_DEPTH} levels", {"what": what})
            if isinstance(item, dict):
                for key, sub in item.items():
                    _check_scalar(key, what)
                    stack.append((sub, depth + 1))
            else:
                stack.extend((sub, depth + 1) for sub in item)
        else:
            _check_scalar(item, what)


def _check_scalar(item: Any, what: str) -> None:
    if isinstance(item, str):
        if "\x00" in item:
            raise InvalidInput(f"{what}: strings must not contain NUL characters", {"what": what})
    elif isinstance(item, float):
        if not math.isfinite(item):
            raise InvalidInput(f"{what}: numbers must be finite (no NaN or Infinity)", {"what": what})
    elif isinstance(item, int) and not isinstance(item, bool) and not -MAX_INT <= item < MAX_INT:
        raise InvalidInput(f"{what}: integers must fit in 64 bits", {"what": what})
