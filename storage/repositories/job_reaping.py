"""Reaping: the running jobs of workers that died are requeued (a few times) or failed.

A worker starting reaps the jobs left running under its name (:func:`reap_orphaned`); every worker's reaper
and the api's reads reap jobs with no sign of life for a while (:func:`reap_stale`). A job whose worker died
:data:`POISON_DEATHS` times is failed as a poison job. The files of reaped jobs are the caller's
(``storage.reaping``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import timedelta

from sqlalchemy import ColumnElement, func, select, update
from sqlalchemy.orm import Session

from storage.models import Job, JobStatus
from storage.repositories._common import writing
from storage.repositories.jobs import FRESH, drop_results
from storage.sqltypes import utcnow

REQUEUED_STAGE = "requeued: its worker died"
"""The stage a requeued job shows until a worker starts it again."""

POISON_DEATHS = 2
"""A job whose worker process died this many times in a row (automatic requeues) is a poison job: it is
failed and never handed to another worker (one setting could kill every worker); only a manual retry
queues it again."""
POISON_ERROR = (
    "poison job: its worker process died {deaths} times while running it (a setting or input that crashes "
    "the pipeline?); it is not handed to another worker, retry it explicitly after a fix"
)


@dataclass
class Reaped:
    """What reaping did to the running jobs of dead workers."""

    failed: list[str] = field(default_factory=list)
    """Includes the ``poisoned`` ones."""
    poisoned: list[str] = field(default_factory=list)
    requeued: list[str] = field(default_factory=list)
    """Back to queued (attempts + 1): the caller must put them on the queue again."""

    @property
    def all(self) -> list[str]:
        return [*self.requeued, *self.failed]


def _reap(session: Session, conds: list[ColumnElement[bool]], error: str, requeue_limit: int) -> Reaped:
    """Requeue (up to ``requeue_limit`` times per job, and never a poison job) or fail the running jobs
    matching ``conds``.

    Both are conditional UPDATEs on ``status = running`` in one transaction, so two reapers racing
    (every worker runs one) requeue or fail each job once.
    """
    running = [Job.status == JobStatus.RUNNING, *conds]
    reaped = Reaped()
    requeue_limit = min(requeue_limit, POISON_DEATHS - 1)
    with writing(session):
        if requeue_limit > 0:
            stmt = (
                update(Job)
                .where(*running, Job.requeues < requeue_limit, Job.cancel_requested.is_(False))
                .values(status=JobStatus.QUEUED, attempts=Job.attempts + 1, requeues=Job.requeues + 1,
                        **{**FRESH, "stage": REQUEUED_STAGE})
                .returning(Job.id)
                .execution_options(synchronize_session=False)
            )
            reaped.requeued = list(session.scalars(stmt))
            if reaped.requeued:  # a worker killed while saving may have stored some
                drop_results(session, reaped.requeued)
        stmt = (  # this death follows automatic requeues after earlier ones: a poison job
            update(Job)
            .where(*running, Job.requeues >= POISON_DEATHS - 1, Job.cancel_requested.is_(False))
            .values(status=JobStatus.FAILED, finished_at=utcnow(),  # stage: the step it died in
                    error=POISON_ERROR.format(deaths=POISON_DEATHS))
            .returning(Job.id)
            .execution_options(synchronize_session=False)
        )
        reaped.poisoned = list(session.scalars(stmt))
        stmt = (
            update(Job)
            .where(*running)
            .values(status=JobStatus.FAILED, finished_at=utcnow(), error=error)  # stage: the step it died in
            .returning(Job.id)
            .execution_options(synchronize_session=False)
        )
        reaped.failed = [*reaped.poisoned, *session.scalars(stmt)]
        if reaped.failed:  # a failed job never shows the half of a result
            drop_results(session, reaped.failed)
    return reaped


def reap_orphaned(
    session: Session,
    *,
    worker: str | None = None,
    error: str = "the worker stopped before the job finished",
    requeue_limit: int = 0,
) -> Reaped:
    """Requeue or fail jobs left running by a worker that died; call it when a worker starts.

    ``worker`` limits it to jobs claimed under that name; None takes every running job (right for the
    single-machine default, where one worker runs).
    """
    conds = [] if worker is None else [Job.worker == worker]
    return _reap(session, conds, error, requeue_limit)


def reap_stale(
    session: Session,
    *,
    older_than_s: float,
    error: str = "the worker stopped reporting (died or lost its connection); retry the job",
    requeue_limit: int = 0,
) -> Reaped:
    """Requeue or fail running jobs whose worker has not reported for ``older_than_s`` seconds."""
    return _reap(session, [_silent_for(older_than_s)], error, requeue_limit)


def any_stale(session: Session, *, older_than_s: float) -> bool:
    """Whether :func:`reap_stale` would take a job: one read, so readers (the api) check before writing."""
    stmt = select(Job.id).where(Job.status == JobStatus.RUNNING, _silent_for(older_than_s)).limit(1)
    return session.scalar(stmt) is not None


def _silent_for(seconds: float) -> ColumnElement[bool]:
    """The job's last sign of life (heartbeat, else its start) is older than ``seconds``."""
    return func.coalesce(Job.heartbeat_at, Job.started_at) < utcnow() - timedelta(seconds=seconds)
