"""TUM RGB-D list files (``rgb.txt``, ``depth.txt``): ``timestamp relative/path`` per line, ``#`` comments."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from formats.errors import FormatError

MAX_LIST_LINES = 100_000
"""Lines a list file may have (about 55 min at 30 Hz, over twice TUM's longest sequence): bounds the memory
and time an upload's listing can cost; more raises FormatError, which the api answers with a 4xx."""


@dataclass(frozen=True, slots=True)
class ListEntry:
    timestamp: float
    """Seconds."""
    path: str
    """POSIX path relative to the sequence folder (never absolute, never ``..``)."""
    line: int
    """1-based line in the list file, for error messages."""


def parse_list(text: str, path: Path | str | None = None) -> list[ListEntry]:
    """Entries of a list file's text, sorted by time; two lines with the same timestamp (as float64) are a
    FormatError naming the later line. ``path`` only names the file in errors."""
    lines = text.splitlines()
    if len(lines) > MAX_LIST_LINES:
        raise FormatError(f"has {len(lines)} lines; at most {MAX_LIST_LINES} are accepted", path=path)
    entries: list[ListEntry] = []
    for lineno, line in enumerate(lines, 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        if len(parts) < 2:
            raise FormatError(f"expected 'timestamp filename', got {s[:80]!r}", path=path, line=lineno)
        try:
            t = float(parts[0])
        except ValueError:
            raise FormatError(f"timestamp {parts[0][:40]!r} is not a number", path=path, line=lineno) from None
        if not math.isfinite(t):
            raise FormatError("timestamp is not finite", path=path, line=lineno)
        rel = PurePosixPath(parts[1])
        if rel.is_absolute() or ".." in rel.parts or "\\" in parts[1] or "\x00" in parts[1]:
            raise FormatError(f"path {parts[1][:80]!r} must be relative and stay inside the sequence",
                              path=path, line=lineno)
        entries.append(ListEntry(t, rel.as_posix(), lineno))
    if not entries:
        raise FormatError("lists no frames", path=path)
    entries.sort(key=lambda e: e.timestamp)
    for before, entry in zip(entries, entries[1:], strict=False):
        if entry.timestamp <= before.timestamp:  # equal once read as float64 (1e17 + t collapses too)
            raise FormatError(
                f"timestamp {entry.timestamp!r} repeats line {before.line}'s: timestamps must strictly increase",
                path=path, line=entry.line,
            )
    return entries


def read_list(path: Path) -> list[ListEntry]:
    """:func:`parse_list` of a UTF-8 file; a missing file is a FormatError too."""
    if not path.is_file():
        raise FormatError("required list file is missing", path=path)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise FormatError(f"not UTF-8 text ({exc.reason})", path=path) from None
    return parse_list(text, path)
