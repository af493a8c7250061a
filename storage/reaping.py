"""Jobs of dead workers, settled: found stale by their heartbeat (or left running by a worker name that
restarted, see ``worker.reaping``), then their partial files removed and the requeued ones put on the queue
again (failed when the queue refuses). Shared by every worker's reaper and the api's reads, so a job whose
worker died shows failed (or requeued) after ``Settings.heartbeat_timeout_s`` even when no worker is alive.

The queries (``storage.repositories.job_reaping.reap_stale``, ``reap_orphaned``) decide which jobs; this module only
does what follows, once per reaped job (the conditional UPDATEs hand each job to one reaper).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from sqlalchemy.orm import Session

from storage.artifacts import ArtifactStore
from storage.models import JobStatus
from storage.repositories import job_reaping, jobs
from storage.repositories.job_reaping import Reaped

log = logging.getLogger("storage.reaping")

Enqueue = Callable[[str], None]


def reap_stale_jobs(session: Session, store: ArtifactStore, *, timeout_s: float, requeue_limit: int,
                    enqueue: Enqueue | None) -> Reaped:
    """Requeue or fail the running jobs whose worker has not reported for ``timeout_s``, and settle them.
    A read first: nothing is written while every running job is alive."""
    if not job_reaping.any_stale(session, older_than_s=timeout_s):
        return Reaped()
    reaped = job_reaping.reap_stale(session, older_than_s=timeout_s, requeue_limit=requeue_limit)
    settle(session, store, reaped, f"had no sign of its worker for {timeout_s:g} s", enqueue)
    return reaped


def settle(session: Session, store: ArtifactStore, reaped: Reaped, why: str, enqueue: Enqueue | None) -> None:
    """Remove the reaped jobs' partial files (artifacts, the run's staging folder); put the requeued ones on
    the queue, failing any the queue refuses. ``why`` completes "job ID ..." in the log."""
    for job_id in reaped.all:
        store.delete_job(job_id)
        store.delete_staging(f"job-{job_id}-")
    for job_id in reaped.failed:
        if job_id in reaped.poisoned:
            log.error("job %s %s again: a poison job (its worker died on it twice), marked failed", job_id, why)
        else:
            log.warning("job %s %s: marked failed", job_id, why)
    for job_id in reaped.requeued:  # the row is queued again; now the queue message (order matters)
        log.warning("job %s %s: requeued", job_id, why)
        try:
            if enqueue is None:
                raise RuntimeError("no queue to requeue it on")
            enqueue(job_id)
        except Exception as exc:
            log.error("job %s could not be requeued: %s", job_id, exc)
            try:
                jobs.finish(session, job_id, JobStatus.FAILED,
                            error=f"its worker died and requeueing it failed ({exc}); retry it")
            except Exception as again:  # left queued without a message: a manual retry is needed
                log.error("job %s: could not mark it failed either: %s", job_id, again)
