"""Jobs: create, list (filters, paging), get, cancel, retry, delete."""

from __future__ import annotations

import json
import logging
from typing import Annotated, Any

from fastapi import APIRouter, Query, Response, status
from sqlalchemy.orm import Session

from backend.api.deps import Auth, Enqueue, EnqueueDep, Limit, Offset, SessionDep, StoreDep
from backend.api.errors import ApiError, error_responses
from backend.api.guard import GuardedRoute
from backend.api.schemas import JobCreate, JobId, JobOut, Page
from backend.api.stale import ReapStale
from storage.config_ranges import check_ranges
from storage.errors import InvalidInput
from storage.models import JobStatus
from storage.presets import check_preset, check_stages
from storage.repositories import jobs
from storage.repositories.metrics import json_safe

router = APIRouter(prefix="/jobs", tags=["jobs"], route_class=GuardedRoute)
log = logging.getLogger("backend.api")

MAX_CONFIG_CHARS = 64 * 1024


class QueueUnavailable(ApiError):
    code = "queue_unavailable"
    http_status = 503


def enqueue_or_fail(session: Session, enqueue: Enqueue, job_ids: list[str]) -> None:
    """Put jobs on the queue; a job the queue refused is failed at once (it can be retried later)."""
    failed = []
    for job_id in job_ids:
        try:
            enqueue(job_id)
        except Exception as exc:
            log.error("could not enqueue job %s: %s", job_id, exc)
            jobs.finish(session, job_id, JobStatus.FAILED, error=f"could not enqueue the job: {exc}")
            failed.append(job_id)
    if failed:
        raise QueueUnavailable("the job queue is unavailable; retry the jobs later", {"job_ids": failed})


def check_config(config: dict[str, Any] | None) -> dict[str, Any] | None:
    """Size, the core settings' valid ranges (422 naming the field and range) and the order of a given
    ``stages`` list; the worker checks everything again, including stage sections."""
    if config is None:
        return None
    if len(json.dumps(json_safe(config))) > MAX_CONFIG_CHARS:
        raise InvalidInput(f"config overrides are limited to {MAX_CONFIG_CHARS} characters")
    check_ranges(config)
    check_stages(config)
    return config


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    response_model=JobOut,
    dependencies=[Auth],
    responses=error_responses(400, 401, 404, 413, 422, 503, 507),
)
def create_job(body: JobCreate, session: SessionDep, enqueue: EnqueueDep) -> JobOut:
    """Queue a run of a sequence under a preset, with optional config overrides."""
    job = jobs.create(
        session, sequence_id=body.sequence_id, preset=check_preset(body.preset), config=check_config(body.config)
    )
    enqueue_or_fail(session, enqueue, [job.id])
    return JobOut.of(jobs.get(session, job.id))


@router.get("", response_model=Page[JobOut], dependencies=[ReapStale], responses=error_responses(422))
def list_jobs(
    session: SessionDep,
    status_: Annotated[JobStatus | None, Query(alias="status")] = None,
    sequence_id: str | None = None,
    batch_id: str | None = None,
    limit: Limit = 50,
    offset: Offset = 0,
) -> Page[JobOut]:
    """Newest first, optionally filtered by status, sequence or batch."""
    filters = {"status": status_, "sequence_id": sequence_id, "batch_id": batch_id}
    items = jobs.list_jobs(session, **filters, limit=limit, offset=offset)
    return Page[JobOut](
        items=[JobOut.of(j) for j in items], total=jobs.count(session, **filters), limit=limit, offset=offset
    )


@router.get("/{job_id}", response_model=JobOut, dependencies=[ReapStale], responses=error_responses(404))
def get_job(job_id: JobId, session: SessionDep) -> JobOut:
    return JobOut.of(jobs.get(session, job_id))


@router.post(
    "/{job_id}/cancel", response_model=JobOut, dependencies=[Auth], responses=error_responses(401, 404, 409)
)
def cancel_job(job_id: JobId, session: SessionDep) -> JobOut:
    """A queued job is cancelled at once; a running one stops within a few frames (watch its status)."""
    return JobOut.of(jobs.request_cancel(session, job_id))


@router.post(
    "/{job_id}/retry", response_model=JobOut, dependencies=[Auth], responses=error_responses(401, 404, 409, 503)
)
def retry_job(job_id: JobId, session: SessionDep, store: StoreDep, enqueue: EnqueueDep) -> JobOut:
    """Queue a failed or cancelled job again from scratch (its old artifacts and metrics are dropped)."""
    jobs.retry(session, job_id)
    store.delete_job(job_id)
    enqueue_or_fail(session, enqueue, [job_id])
    return JobOut.of(jobs.get(session, job_id))


@router.delete(
    "/{job_id}", status_code=status.HTTP_204_NO_CONTENT, dependencies=[Auth], responses=error_responses(401, 404)
)
def delete_job(job_id: JobId, session: SessionDep, store: StoreDep) -> Response:
    """Delete a job in any state with its metrics and artifacts (a running one stops)."""
    jobs.delete(session, job_id)
    store.delete_job(job_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
