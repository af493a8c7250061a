"""Run metrics (one summary row per job) and per-frame statistics, read through the formats schemas
(formats.run_metrics, formats.frame_stats)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

from sqlalchemy import insert, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from formats.errors import FormatError
from formats.frame_stats import FrameStats
from formats.run_metrics import RunMetrics as RunMetricsSchema
from formats.run_metrics import finite
from storage.errors import Conflict, InvalidInput, NotFound
from storage.models import FrameStat, Job, RunMetrics
from storage.repositories._common import get_or_raise, writing


def json_safe(value: Any) -> Any:
    """``value`` made storable as JSON on every backend.

    NaN/inf become None (PostgreSQL's json rejects them; ATE without ground truth is often NaN), numpy
    scalars and arrays become Python numbers and lists (duck-typed: storage does not import numpy).
    """
    if isinstance(value, Mapping):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return json_safe(value.tolist())  # numpy arrays and scalars alike
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def summary_columns(blob: Mapping[str, Any]) -> dict[str, Any]:
    """The indexed columns read from a ``metrics.json`` blob (formats.run_metrics, which also reads the older
    RPE spellings); absent or non-finite values are None.

    ``ate_{rmse,mean,median,std,max}`` (m), ``rpe_trans_rmse`` (m per interval), ``rpe_rot_rmse`` (degrees per
    interval), ``fps`` (frames/s), ``tracked``, ``lost`` (frame counts).
    """
    m = RunMetricsSchema.from_dict(blob)
    ate = m.ate.to_dict() if m.ate is not None else {}
    cols: dict[str, Any] = {f"ate_{k}": finite(ate.get(k)) for k in ("rmse", "mean", "median", "std", "max")}
    cols["rpe_trans_rmse"] = finite(m.rpe.trans.rmse) if m.rpe is not None else None
    cols["rpe_rot_rmse"] = finite(m.rpe.rot_deg.rmse) if m.rpe is not None else None
    cols["fps"] = finite(m.fps)
    cols["tracked"], cols["lost"] = m.tracked, m.lost
    return cols


def save_run_metrics(session: Session, job_id: str, metrics: Mapping[str, Any]) -> RunMetrics:
    """Store (or replace) a job's metrics: the summary columns plus the whole blob."""
    with writing(session):
        get_or_raise(session, Job, job_id, "job")
        row = session.get(RunMetrics, job_id, populate_existing=True) or RunMetrics(job_id=job_id)
        for key, value in summary_columns(metrics).items():
            setattr(row, key, value)
        row.metrics = json_safe(metrics)
        session.add(row)
    return row


def get_run_metrics(session: Session, job_id: str) -> RunMetrics:
    row = session.get(RunMetrics, job_id, populate_existing=True)
    if row is None:
        raise NotFound(f"no metrics for job {job_id}", {"job_id": job_id})
    return row


def _frame_row(job_id: str, row: FrameStats | Mapping[str, Any]) -> dict[str, Any]:
    try:
        stats = row if isinstance(row, FrameStats) else FrameStats.from_row(row)
    except FormatError as exc:
        raw = json_safe(dict(row)) if isinstance(row, Mapping) else None
        raise InvalidInput(f"a malformed frame stat: {exc.message}", {"row": raw}) from exc
    return {"job_id": job_id, **stats.to_stored(), "timings": json_safe(stats.timings)}


def add_frame_stats(session: Session, job_id: str, rows: Iterable[FrameStats | Mapping[str, Any]]) -> int:
    """Bulk-insert per-frame stats (may be called in chunks while running); returns the count.

    Rows are :class:`FrameStats` or mappings it reads (missing optional keys take its defaults); a malformed row
    is :class:`InvalidInput`, a frame index stored twice a :class:`Conflict`.
    """
    values = [_frame_row(job_id, r) for r in rows]
    if not values:
        return 0
    try:
        with writing(session):
            get_or_raise(session, Job, job_id, "job")
            session.execute(insert(FrameStat), values)
    except IntegrityError as exc:
        raise Conflict(f"frame stats of job {job_id} already stored for some frames") from exc
    return len(values)


def get_frame_stats(
    session: Session, job_id: str, *, limit: int | None = None, offset: int = 0
) -> list[FrameStats]:
    """A job's frame stats in frame order (empty if none were stored)."""
    stmt = (
        select(FrameStat)
        .where(FrameStat.job_id == job_id)
        .order_by(FrameStat.frame_index)
        .offset(offset)
        .limit(limit)
        .execution_options(populate_existing=True)
    )
    return [
        FrameStats(r.frame_index, r.timestamp, r.tracked, r.n_features, r.n_dynamic_removed, r.ate_error,
                   dict(r.timings or {}))
        for r in session.scalars(stmt)
    ]
