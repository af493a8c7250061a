"""Run metrics (one summary row per job) and per-frame statistics."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

from sqlalchemy import insert, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

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


def _num(value: Any) -> float | None:
    try:
        f = float(value)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _int(value: Any) -> int | None:
    f = _num(value)
    return None if f is None else int(f)


def _dig(blob: Mapping[str, Any], *path: str) -> Any:
    cur: Any = blob
    for key in path:
        if not isinstance(cur, Mapping):
            return None
        cur = cur.get(key)
    return cur


def summary_columns(blob: Mapping[str, Any]) -> dict[str, Any]:
    """The indexed columns read from a ``metrics.json`` blob; absent or non-finite values are None.

    Keys: ``ate.{rmse,mean,median,std,max}``, ``rpe.trans.rmse`` and ``rpe.rot_deg.rmse`` (the pipeline's
    metrics.json; ``rpe.trans_rmse``/``rpe.rot_rmse`` and ``rpe.rot.rmse`` are read too), ``fps``,
    ``tracked``, ``lost`` (frame counts).
    """
    cols: dict[str, Any] = {
        f"ate_{k}": _num(_dig(blob, "ate", k)) for k in ("rmse", "mean", "median", "std", "max")
    }
    for part, nested in (("trans", ("trans",)), ("rot", ("rot_deg", "rot"))):
        value = _dig(blob, "rpe", f"{part}_rmse")
        for key in nested:
            value = value if value is not None else _dig(blob, "rpe", key, "rmse")
        cols[f"rpe_{part}_rmse"] = _num(value)
    cols["fps"] = _num(blob.get("fps"))
    cols["tracked"] = _int(blob.get("tracked"))
    cols["lost"] = _int(blob.get("lost"))
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


def _frame_row(job_id: str, row: Mapping[str, Any]) -> dict[str, Any]:
    try:
        index, timestamp = int(row["frame_index"]), float(row["timestamp"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InvalidInput(
            "a frame stat needs numeric frame_index and timestamp", {"row": json_safe(dict(row))}
        ) from exc
    return {
        "job_id": job_id,
        "frame_index": index,
        "timestamp": timestamp,
        "tracked": bool(row.get("tracked", True)),
        "n_features": int(row.get("n_features", 0)),
        "n_dynamic_removed": int(row.get("n_dynamic_removed", 0)),
        "ate_error": _num(row.get("ate_error")),
        "timings": json_safe(row.get("timings") or {}),
    }


def add_frame_stats(session: Session, job_id: str, rows: Iterable[Mapping[str, Any]]) -> int:
    """Bulk-insert per-frame stats (may be called in chunks while running); returns the count.

    Missing optional keys take defaults; a frame index stored twice is a :class:`Conflict`.
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
) -> list[FrameStat]:
    """A job's frame stats in frame order (empty if none were stored)."""
    stmt = (
        select(FrameStat)
        .where(FrameStat.job_id == job_id)
        .order_by(FrameStat.frame_index)
        .offset(offset)
        .limit(limit)
        .execution_options(populate_existing=True)
    )
    return list(session.scalars(stmt))
