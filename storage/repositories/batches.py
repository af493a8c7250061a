"""Batches: every sequence under every preset, and the comparison table of their results."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from formats.run_metrics import RunMetrics as RunMetricsSchema
from formats.run_metrics import finite
from storage.errors import InvalidInput, NotFound
from storage.models import Batch, Job, RunMetrics, Sequence, new_id
from storage.repositories import jobs as job_repo
from storage.repositories._common import check_page, get_or_raise, writing


@dataclass(frozen=True, slots=True)
class ComparisonRow:
    """One cell group of the comparison table: a sequence run under a preset (None: no result)."""

    sequence_id: str
    sequence_name: str | None
    preset: str
    job_id: str | None
    status: str | None
    ate_rmse: float | None
    """Metres."""
    rpe_trans_rmse: float | None
    """Metres per RPE interval."""
    rpe_rot_rmse: float | None
    """Degrees per RPE interval."""
    fps: float | None
    """Frames per second, whole pipeline."""
    relocalisations: int | None = None
    mask_iou: float | None = None
    """The rest: formats.run_metrics (RunMetrics.relocalisations, TruthScores)."""
    feature_precision: float | None = None
    feature_recall: float | None = None
    restoration_psnr: float | None = None
    """dB."""
    groundtruth_frame: str | None = None
    """What the sequence's ground truth is the pose of (``camera``, ``bonn-marker``); None for older runs."""
    ate_against: str | None = None
    """What ``ate_rmse`` was measured against (the raw ground truth: the published convention)."""
    ate_corrected_rmse: float | None = None
    """Metres, against the camera's ground truth (a marker's corrected to the camera)."""
    ate_corrected_against: str | None = None
    rpe_against: str | None = None
    """What the RPE columns were measured against (always the camera's ground truth in current runs)."""
    rpe_frame_trans_rmse: float | None = None
    """Metres per frame (consecutive poses)."""
    rpe_frame_rot_rmse: float | None = None
    """Degrees per frame."""

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


# The comparison table's CSV names its columns with their units (the JSON table keeps the plain keys and says the
# units in its schema). By prefix, so a new ATE/RPE column gets its unit too; first match wins.
def csv_header(column: str) -> str:
    """The CSV header of a comparison-table column: an error figure with its unit (``ate_rmse`` -> ``ate_rmse_m``,
    ``rpe_frame_rot_rmse`` -> ``rpe_frame_rot_rmse_deg``, ``restoration_psnr`` -> ``restoration_psnr_db``);
    labels (``ate_against``), ids, counts, fps and fractions 0..1 as they are."""
    unit = None
    if column.endswith("_rmse"):
        unit = "deg" if "_rot" in column else "m" if column.startswith(("ate_", "rpe_")) else None
    elif column == "restoration_psnr":
        unit = "db"
    return column if unit is None else f"{column}_{unit}"


def _unique(items: list[str], what: str) -> list[str]:
    if not items or not all(isinstance(i, str) and i for i in items):
        raise InvalidInput(f"{what} must be a non-empty list of non-empty strings")
    return list(dict.fromkeys(items))  # de-duplicated, order kept


def create(
    session: Session,
    *,
    sequence_ids: list[str],
    presets: list[str],
    name: str = "",
    config: dict[str, Any] | None = None,
) -> Batch:
    """The batch and its queued jobs (one per sequence × preset), in one transaction.

    ``config`` overrides go to every job. The caller enqueues ``jobs_of(batch.id)`` afterwards.
    """
    sequence_ids = _unique(sequence_ids, "sequence_ids")
    presets = _unique(presets, "presets")
    with writing(session):
        found = set(session.scalars(select(Sequence.id).where(Sequence.id.in_(sequence_ids))))
        missing = [s for s in sequence_ids if s not in found]
        if missing:
            raise NotFound(f"unknown sequences: {', '.join(missing)}", {"missing": missing})
        batch = Batch(id=new_id(), name=name, sequence_ids=sequence_ids, presets=presets)
        session.add(batch)
        session.flush()  # the batch row first: the jobs reference it
        session.add_all(
            job_repo.new_job(sequence_id=s, preset=p, config=config, batch_id=batch.id)
            for s in sequence_ids
            for p in presets
        )
    return batch


def get(session: Session, batch_id: str) -> Batch:
    return get_or_raise(session, Batch, batch_id, "batch")


def list_batches(session: Session, *, limit: int = 50, offset: int = 0) -> list[Batch]:
    """Newest first."""
    check_page(limit, offset)
    stmt = (
        select(Batch)
        .order_by(Batch.created_at.desc(), Batch.id)
        .limit(limit)
        .offset(offset)
        .execution_options(populate_existing=True)
    )
    return list(session.scalars(stmt))


def jobs_of(session: Session, batch_id: str) -> list[Job]:
    """The batch's jobs in table order: by sequence, then preset, as given at creation."""
    batch = get(session, batch_id)
    jobs = session.scalars(
        select(Job)
        .where(Job.batch_id == batch_id)
        .order_by(Job.created_at, Job.id)
        .execution_options(populate_existing=True)
    ).all()
    order = _order(batch)
    return sorted(jobs, key=lambda j: order.get((j.sequence_id, j.preset), (len(order), 0)))


def _order(batch: Batch) -> dict[tuple[str, str], tuple[int, int]]:
    return {
        (s, p): (i, k)
        for i, s in enumerate(batch.sequence_ids)
        for k, p in enumerate(batch.presets)
    }


def comparison(session: Session, batch_id: str) -> list[ComparisonRow]:
    """One row per sequence × preset of the batch, in creation order; metrics None until known.

    If a cell somehow has several jobs, the newest one wins; a deleted sequence's cells stay, empty.
    """
    batch = get(session, batch_id)
    stmt = (
        select(
            Job.id,
            Job.sequence_id,
            Job.preset,
            Job.status,
            RunMetrics.ate_rmse,
            RunMetrics.rpe_trans_rmse,
            RunMetrics.rpe_rot_rmse,
            RunMetrics.fps,
            RunMetrics.metrics,
        )
        .outerjoin(RunMetrics, RunMetrics.job_id == Job.id)
        .where(Job.batch_id == batch_id)
        .order_by(Job.created_at, Job.id)
    )
    cells = {(r.sequence_id, r.preset): r for r in session.execute(stmt)}
    names_stmt = select(Sequence.id, Sequence.name).where(Sequence.id.in_(batch.sequence_ids))
    names = {sid: name for sid, name in session.execute(names_stmt)}
    rows = []
    for seq_id in batch.sequence_ids:
        for preset in batch.presets:
            r = cells.get((seq_id, preset))
            run = RunMetricsSchema.from_dict(r.metrics if r is not None and r.metrics else {})
            rows.append(
                ComparisonRow(
                    sequence_id=seq_id,
                    sequence_name=names.get(seq_id),
                    preset=preset,
                    job_id=r.id if r else None,
                    status=r.status.value if r else None,
                    ate_rmse=r.ate_rmse if r else None,
                    rpe_trans_rmse=r.rpe_trans_rmse if r else None,
                    rpe_rot_rmse=r.rpe_rot_rmse if r else None,
                    fps=r.fps if r else None,
                    relocalisations=run.relocalisations,
                    **dataclasses.asdict(run.truth_scores()),
                    **_groundtruth_columns(run),
                )
            )
    return rows


def _groundtruth_columns(run: RunMetricsSchema) -> dict[str, Any]:
    """The ground-truth frame, the labels and the figures ``metrics.json`` adds next to ``ate`` and ``rpe``."""
    return {
        "groundtruth_frame": run.groundtruth_frame,
        "ate_against": run.ate_against,
        "ate_corrected_rmse": finite(run.ate_corrected.rmse) if run.ate_corrected is not None else None,
        "ate_corrected_against": run.ate_corrected_against,
        "rpe_against": run.rpe_against,
        "rpe_frame_trans_rmse": finite(run.rpe_frame.trans.rmse) if run.rpe_frame is not None else None,
        "rpe_frame_rot_rmse": finite(run.rpe_frame.rot_deg.rmse) if run.rpe_frame is not None else None,
    }
