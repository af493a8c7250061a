"""The per-frame statistics of a run: the pipeline's ``frame_stats.csv`` and the rows the service stores.

The pipeline writes :data:`PIPELINE_COLUMNS` first, then whatever else its stages reported (sorted); the
service stores :data:`STORED_COLUMNS`, two of them renamed (:data:`STORED_NAMES`).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Mapping, Sequence
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


def to_stored(row: Mapping[str, Any]) -> dict[str, Any]:
    """A pipeline row as the service stores it (missing counts are 0, a missing ATE error is None)."""
    return {"frame_index": row["frame_index"], "timestamp": row["timestamp"], "tracked": row["tracked"],
            "n_features": row.get("features", 0), "n_dynamic_removed": row.get("features_removed", 0),
            "ate_error": row.get("ate_error")}


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
