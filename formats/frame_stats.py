"""The per-frame statistics of a run: the pipeline's ``frame_stats.csv`` and the typed row (:class:`FrameStats`)
the service stores, the api serves (``/jobs/{id}/frames``) and the viewer reads.

The pipeline writes :data:`PIPELINE_COLUMNS` first, then whatever else its stages reported (sorted); the
service stores :data:`STORED_COLUMNS`, two of them named differently (:data:`STORED_NAMES`).
:meth:`FrameStats.from_row` is the one reader of a row in either naming (a pipeline row, a stored row, or a CSV
row of strings).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from formats.errors import FormatError

PIPELINE_COLUMNS = ("frame_index", "timestamp", "tracked", "ate_error", "features", "matched_points")
STORED_COLUMNS = ("frame_index", "timestamp", "tracked", "n_features", "n_dynamic_removed", "ate_error")
STORED_NAMES = {"features": "n_features", "features_removed": "n_dynamic_removed"}
"""Pipeline column -> stored column, where they differ."""


def pipeline_columns(rows: Iterable[Mapping[str, Any]]) -> list[str]:
    """:data:`PIPELINE_COLUMNS`, then every other key of ``rows``, sorted."""
    return [*PIPELINE_COLUMNS, *sorted({k for r in rows for k in r} - set(PIPELINE_COLUMNS))]


def _number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise FormatError(f"{what} is not a number: {value!r}")
    try:
        return float(value)
    except ValueError:
        raise FormatError(f"{what} is not a number: {value!r}") from None


def _count(value: Any, what: str) -> int:
    """An int (None or an empty cell is 0; a float is truncated, as int() does)."""
    if value is None or value == "":
        return 0
    f = _number(value, what)
    if not math.isfinite(f):
        raise FormatError(f"{what} is not a finite number: {value!r}")
    return int(f)


def _flag(value: Any) -> bool:
    """A bool; a CSV cell ``True``/``False`` (also 1/0, yes/no); None or empty is True (tracked by default)."""
    if isinstance(value, str):
        return value.strip().lower() not in ("false", "0", "no") if value.strip() else True
    return True if value is None else bool(value)


def _error(value: Any) -> float | None:
    """A finite float, else None (empty cell, NaN, garbage)."""
    try:
        f = _number(value, "ate_error")
    except FormatError:
        return None
    return f if math.isfinite(f) else None


@dataclass(frozen=True)
class FrameStats:
    """One frame's statistics as the service stores and serves them."""

    frame_index: int
    """Index of the frame in its sequence."""
    timestamp: float
    """Seconds, the sequence's clock (TUM timestamps)."""
    tracked: bool = True
    """Whether tracking found a pose for the frame."""
    n_features: int = 0
    """ORB keypoints of the frame the tracker saw (the pipeline's ``features`` column)."""
    n_dynamic_removed: int = 0
    """Keypoints culled as dynamic (the pipeline's ``features_removed`` column; 0 without culling)."""
    ate_error: float | None = None
    """Metres: the frame's translation error after SE(3) alignment; None without a matched ground-truth pose."""
    timings: dict[str, Any] = field(default_factory=dict)
    """Milliseconds by step, where a producer reports them (the pipeline reports run means only)."""

    @classmethod
    def from_row(cls, row: Mapping[str, Any]) -> FrameStats:
        """A row in the pipeline's or the stored naming (stored names win), values typed or CSV strings; missing
        counts are 0, ``tracked`` True, ``ate_error`` None. FormatError without a numeric frame_index and
        timestamp, or with a non-numeric count."""
        if row.get("frame_index") is None or row.get("timestamp") is None:
            raise FormatError("a frame stat needs numeric frame_index and timestamp")
        index = _number(row["frame_index"], "frame_index")
        if not index.is_integer():
            raise FormatError(f"frame_index is not an integer: {row['frame_index']!r}")
        features = row.get("n_features", row.get("features"))
        removed = row.get("n_dynamic_removed", row.get("features_removed"))
        timings = row.get("timings")
        return cls(int(index), _number(row["timestamp"], "timestamp"), _flag(row.get("tracked")),
                   _count(features, "n_features"), _count(removed, "n_dynamic_removed"), _error(row.get("ate_error")),
                   dict(timings) if isinstance(timings, Mapping) else {})

    def to_stored(self) -> dict[str, Any]:
        """The :data:`STORED_COLUMNS` of the row (``timings`` left out)."""
        return {"frame_index": self.frame_index, "timestamp": self.timestamp, "tracked": self.tracked,
                "n_features": self.n_features, "n_dynamic_removed": self.n_dynamic_removed,
                "ate_error": self.ate_error}


def to_stored(row: Mapping[str, Any]) -> dict[str, Any]:
    """A pipeline row as the service stores it (missing counts are 0, a missing ATE error is None)."""
    return FrameStats.from_row(row).to_stored()


def format_frame_stats(rows: Sequence[Mapping[str, Any]], columns: Sequence[str] | None = None) -> str:
    """CSV text of ``rows`` (``columns`` defaults to :func:`pipeline_columns`); None and missing are empty
    cells, other keys are left out. Lines end in CRLF (the csv module's default, RFC 4180)."""
    columns = list(columns) if columns is not None else pipeline_columns(rows)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore")
    writer.writeheader()
    for r in rows:
        writer.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in columns})
    return buf.getvalue()


def write_frame_stats(path: Path, rows: Sequence[Mapping[str, Any]], columns: Sequence[str] | None = None) -> None:
    """:func:`format_frame_stats` into ``path``."""
    with path.open("w", newline="") as fh:
        fh.write(format_frame_stats(rows, columns))


def read_frame_stats(path: Path) -> list[dict[str, str]]:
    """The rows of a frame-stats CSV as strings by column (empty cells are ``""``); needs ``frame_index`` and
    ``timestamp`` columns."""
    with path.open(newline="", encoding="utf-8", errors="replace") as fh:
        reader = csv.DictReader(fh)
        if not {"frame_index", "timestamp"} <= set(reader.fieldnames or ()):
            raise FormatError("needs frame_index and timestamp columns", path=path)
        return [dict(r) for r in reader]


def load_frame_stats(path: Path) -> list[FrameStats]:
    """:func:`read_frame_stats` as typed rows (either naming); FormatError on a malformed row."""
    return [FrameStats.from_row(r) for r in read_frame_stats(path)]
