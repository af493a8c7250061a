"""Jobs and their state machine.

queued → running (claim) → succeeded | failed | cancelled (finish); queued → cancelled (request_cancel);
failed | cancelled → queued (retry); running → queued | failed (reaped: its worker died, see
:mod:`storage.repositories.job_reaping`). Transitions are conditional UPDATEs checked by rowcount, so two
workers or a worker and the api racing on one job can never both win.
"""

from __future__ import annotations

from typing import Any, cast

from sqlalchemy import ColumnElement, func, select, update
from sqlalchemy import delete as sql_delete
from sqlalchemy.engine import CursorResult
from sqlalchemy.orm import Session

from storage.errors import Conflict, InvalidInput, NotFound
from storage.models import Batch, FrameStat, Job, JobStatus, RunMetrics, Sequence, new_id
from storage.repositories._common import check_page, get_or_raise, writing
from storage.sqltypes import utcnow

ACTIVE = (JobStatus.QUEUED, JobStatus.RUNNING)
RETRYABLE = (JobStatus.FAILED, JobStatus.CANCELLED)

FINISHED_STAGE = "done"
"""The stage of a job that succeeded or was cancelled: its status says how. A failed job keeps the stage it
failed in (``tracking``, ``saving``...; empty if it failed before its first step), so its page says where."""

RUN_MS = "run_ms"
"""The key of a job's ``timings`` (all milliseconds) holding the whole pipeline call; older jobs stored seconds
under ``run_s``: :func:`run_seconds` reads either."""


def run_seconds(timings: dict[str, Any] | None) -> float | None:
    """The pipeline's wall time of a job in seconds, from its ``timings`` (``run_ms``, or an older ``run_s``)."""
    timings = timings or {}
    ms, s = timings.get(RUN_MS), timings.get("run_s")
    if isinstance(ms, int | float) and not isinstance(ms, bool):
        return round(ms / 1000, 3)
    if isinstance(s, int | float) and not isinstance(s, bool):
        return float(s)
    return None


def timings_ms(timings: dict[str, Any] | None) -> dict[str, Any]:
    """A job's ``timings`` in milliseconds throughout: an older job's ``run_s`` (seconds) becomes ``run_ms``."""
    out = dict(timings or {})
    if "run_s" in out:
        s = out.pop("run_s")
        if RUN_MS not in out and isinstance(s, int | float) and not isinstance(s, bool):
            out[RUN_MS] = round(1000 * s, 1)
    return out


def create(
    session: Session,
    *,
    sequence_id: str,
    preset: str,
    config: dict[str, Any] | None = None,
    batch_id: str | None = None,
) -> Job:
    """A queued job; the caller enqueues it on the queue after this returns (the row must exist first)."""
    with writing(session):
        get_or_raise(session, Sequence, sequence_id, "sequence")
        if batch_id is not None:
            get_or_raise(session, Batch, batch_id, "batch")
        job = new_job(sequence_id=sequence_id, preset=preset, config=config, batch_id=batch_id)
        session.add(job)
    return job


def new_job(
    *, sequence_id: str, preset: str, config: dict[str, Any] | None, batch_id: str | None
) -> Job:
    """An unsaved queued job (batches add several in one transaction)."""
    if not preset:
        raise InvalidInput("preset must not be empty")
    return Job(
        id=new_id(),
        sequence_id=sequence_id,
        batch_id=batch_id,
        preset=preset,
        status=JobStatus.QUEUED,
        config=config or {},
    )


def get(session: Session, job_id: str) -> Job:
    return get_or_raise(session, Job, job_id, "job")


def _filters(
    status: JobStatus | str | None, sequence_id: str | None, batch_id: str | None
) -> list[ColumnElement[bool]]:
    conds: list[ColumnElement[bool]] = []
    if status is not None:
        try:
            conds.append(Job.status == JobStatus(status))
        except ValueError:
            raise InvalidInput(
                f"unknown status {status!r}", {"allowed": [s.value for s in JobStatus]}
            ) from None
    if sequence_id is not None:
        conds.append(Job.sequence_id == sequence_id)
    if batch_id is not None:
        conds.append(Job.batch_id == batch_id)
    return conds


def list_jobs(
    session: Session,
    *,
    status: JobStatus | str | None = None,
    sequence_id: str | None = None,
    batch_id: str | None = None,
    limit: int = 50,
    offset: int = 0,
) -> list[Job]:
    """Newest first, optionally filtered."""
    check_page(limit, offset)
    stmt = (
        select(Job)
        .where(*_filters(status, sequence_id, batch_id))
        .order_by(Job.created_at.desc(), Job.id)
        .limit(limit)
        .offset(offset)
        .execution_options(populate_existing=True)
    )
    return list(session.scalars(stmt))


def count(
    session: Session,
    *,
    status: JobStatus | str | None = None,
    sequence_id: str | None = None,
    batch_id: str | None = None,
) -> int:
    stmt = select(func.count()).select_from(Job).where(*_filters(status, sequence_id, batch_id))
    return session.scalar(stmt) or 0


def _transition(session: Session, job_id: str, *where: ColumnElement[bool], **values: Any) -> bool:
    """One conditional UPDATE in the caller's transaction; True if it changed the row."""
    stmt = (
        update(Job)
        .where(Job.id == job_id, *where)
        .values(**values)
        .execution_options(synchronize_session=False)  # get() re-reads; no in-memory sync needed
    )
    result = cast(CursorResult[Any], session.execute(stmt))
    return result.rowcount == 1


def claim(session: Session, job_id: str, worker: str) -> bool:
    """Atomically move a queued job to running for ``worker``.

    False when the job is gone, cancelled or already claimed: the caller must then skip it. This is
    what makes a job run once even if the queue delivers it twice or two workers race.
    """
    with writing(session):
        return _transition(
            session,
            job_id,
            Job.status == JobStatus.QUEUED,
            Job.cancel_requested.is_(False),
            status=JobStatus.RUNNING,
            started_at=utcnow(),
            heartbeat_at=utcnow(),
            worker=worker,
        )


def _ours(attempt: int | None) -> list[ColumnElement[bool]]:
    """The condition that a running job is still the claim ``attempt`` of its worker.

    A worker whose job was reaped (and maybe requeued and claimed by another worker) keeps running until
    it notices; matching the attempt keeps that zombie from touching the new attempt's row.
    """
    return [] if attempt is None else [Job.attempts == attempt]


def set_config(session: Session, job_id: str, config: dict[str, Any]) -> None:
    """Store the full config snapshot the run actually uses."""
    with writing(session):
        if not _transition(session, job_id, config=config):
            raise NotFound(f"job {job_id} not found", {"id": job_id})


def update_progress(
    session: Session,
    job_id: str,
    *,
    progress: float | None = None,
    stage: str | None = None,
    frames_done: int | None = None,
    frames_total: int | None = None,
    timings: dict[str, Any] | None = None,
    attempt: int | None = None,
) -> bool:
    """Report progress of a running job (``progress`` clamped to 0..1).

    Returns True when the worker should stop: a cancel was requested, the job is no longer running or
    (with ``attempt``) it is no longer the attempt this worker claimed. Raises :class:`NotFound` if the
    job was deleted meanwhile.
    """
    values: dict[str, Any] = {"heartbeat_at": utcnow()}  # every report is also a heartbeat
    if progress is not None:
        values["progress"] = min(1.0, max(0.0, float(progress)))
    if stage is not None:
        values["stage"] = stage
    if frames_done is not None:
        values["frames_done"] = frames_done
    if frames_total is not None:
        values["frames_total"] = frames_total
    if timings is not None:
        values["timings"] = timings
    with writing(session):
        if values:
            _transition(session, job_id, Job.status == JobStatus.RUNNING, *_ours(attempt), **values)
        row = session.execute(
            select(Job.status, Job.cancel_requested, Job.attempts).where(Job.id == job_id)
        ).one_or_none()
    if row is None:
        raise NotFound(f"job {job_id} not found", {"id": job_id})
    lost = attempt is not None and row.attempts != attempt
    return bool(row.cancel_requested) or row.status != JobStatus.RUNNING or lost


def heartbeat(session: Session, job_id: str, attempt: int | None = None) -> bool:
    """Mark a running job alive (its worker is busy in a long stage); False if it is not ours any more."""
    with writing(session):
        return _transition(
            session, job_id, Job.status == JobStatus.RUNNING, *_ours(attempt), heartbeat_at=utcnow()
        )


def request_cancel(session: Session, job_id: str) -> Job:
    """Cancel a job: a queued one at once, a running one by flag (its worker stops and finishes it).

    Idempotent on a cancelled job; :class:`Conflict` on a succeeded or failed one.
    """
    with writing(session):
        now = utcnow()
        done = _transition(
            session,
            job_id,
            Job.status == JobStatus.QUEUED,
            status=JobStatus.CANCELLED,
            cancel_requested=True,
            finished_at=now,
            stage=FINISHED_STAGE,
        ) or _transition(session, job_id, Job.status == JobStatus.RUNNING, cancel_requested=True)
    job = get(session, job_id)
    if not done and job.status != JobStatus.CANCELLED:
        raise Conflict(f"job {job_id} is already {job.status.value}", {"status": job.status.value})
    return job


def finish(
    session: Session,
    job_id: str,
    status: JobStatus | str,
    *,
    error: str | None = None,
    timings: dict[str, Any] | None = None,
    attempt: int | None = None,
) -> Job:
    """End a queued or running job as succeeded, failed or cancelled (with ``error`` text).

    With ``attempt`` only that claim of the job may end it (:class:`Conflict` otherwise).
    """
    try:
        status = JobStatus(status)
    except ValueError:
        raise InvalidInput(f"unknown status {status!r}") from None
    if not status.is_terminal:
        raise InvalidInput(f"finish needs a final status, not {status.value}")
    values: dict[str, Any] = {"status": status, "finished_at": utcnow(), "error": error}
    if status != JobStatus.FAILED:  # a failed job keeps the step it failed in
        values["stage"] = FINISHED_STAGE
    if status == JobStatus.SUCCEEDED:
        values["progress"] = 1.0
    if timings is not None:
        values["timings"] = timings
    with writing(session):
        done = _transition(session, job_id, Job.status.in_(ACTIVE), *_ours(attempt), **values)
    job = get(session, job_id)
    if not done:
        if attempt is not None and job.attempts != attempt:
            raise Conflict(f"job {job_id} was requeued (attempt {job.attempts}); attempt {attempt} ended",
                           {"status": job.status.value, "attempts": job.attempts})
        raise Conflict(f"job {job_id} is already {job.status.value}", {"status": job.status.value})
    return job


FRESH: dict[str, Any] = {
    "progress": 0.0,
    "stage": "",
    "frames_done": 0,
    "frames_total": 0,
    "error": None,
    "timings": {},
    "started_at": None,
    "heartbeat_at": None,
    "finished_at": None,
    "worker": None,
}
"""The values that make a job back in the queue look like a new one (attempts aside): a retry's and a requeue's."""


def retry(session: Session, job_id: str) -> Job:
    """Requeue a failed or cancelled job from scratch (attempts + 1; old metrics dropped).

    The caller clears the job's artifacts and enqueues it again.
    """
    with writing(session):
        done = _transition(
            session,
            job_id,
            Job.status.in_(RETRYABLE),
            status=JobStatus.QUEUED,
            attempts=Job.attempts + 1,
            requeues=0,  # a manual retry is a fresh start with a fresh budget of automatic requeues
            **FRESH,
            cancel_requested=False,
        )
        if done:
            drop_results(session, [job_id])
    job = get(session, job_id)
    if not done:
        raise Conflict(
            f"only failed or cancelled jobs can be retried; job {job_id} is {job.status.value}",
            {"status": job.status.value},
        )
    return job


def discard_results(session: Session, job_id: str) -> None:
    """Drop a job's stored metrics and frame stats (a save that failed half-way)."""
    with writing(session):
        drop_results(session, [job_id])


def drop_results(session: Session, job_ids: list[str]) -> None:
    """Delete the metrics and frame stats of ``job_ids`` inside the caller's transaction."""
    session.execute(sql_delete(RunMetrics).where(RunMetrics.job_id.in_(job_ids)))
    session.execute(sql_delete(FrameStat).where(FrameStat.job_id.in_(job_ids)))


def delete(session: Session, job_id: str) -> None:
    """Delete a job in any state (with its metrics); a worker running it sees NotFound and stops."""
    with writing(session):
        result = cast(CursorResult[Any], session.execute(sql_delete(Job).where(Job.id == job_id)))
        if result.rowcount != 1:
            raise NotFound(f"job {job_id} not found", {"id": job_id})
