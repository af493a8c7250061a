"""A job's outputs: artifact list and download (with HTTP ranges), and live progress as Server-Sent Events."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import AsyncIterator
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request
from fastapi.responses import FileResponse, StreamingResponse
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from backend.api.deps import Offset, SessionDep, StoreDep
from backend.api.errors import error_responses
from backend.api.files import serve_file
from backend.api.schemas import ArtifactName, ArtifactOut, FrameOut, JobId, JobOut, Page
from backend.api.stale import reap_stale_with
from storage.errors import NotFound
from storage.repositories import jobs, metrics

router = APIRouter(prefix="/jobs", tags=["jobs"])

CONTENT_TYPES = {
    ".txt": "text/plain; charset=utf-8",
    ".log": "text/plain; charset=utf-8",
    ".json": "application/json",
    ".csv": "text/csv; charset=utf-8",
    ".ply": "application/x-ply",
    ".png": "image/png",
    ".jpg": "image/jpeg",
    ".jpeg": "image/jpeg",
}
_MEDIA_TYPES = sorted({t.split(";")[0] for t in CONTENT_TYPES.values()} | {"application/octet-stream"})
"""Every media type an artifact may be served as (documented on the download route)."""


def content_type(name: str) -> str:
    dot = name.rfind(".")
    return CONTENT_TYPES.get(name[dot:].lower() if dot >= 0 else "", "application/octet-stream")


@router.get("/{job_id}/artifacts", response_model=list[ArtifactOut], responses=error_responses(404, 500))
def list_artifacts(job_id: JobId, session: SessionDep, store: StoreDep) -> list[ArtifactOut]:
    """The job's finished outputs (trajectory.txt, keyframes.txt, map.ply, metrics.json, config.json,
    frame_stats.csv, log.txt, preview.png, the figures plot_*.png and the frames' preview images)."""
    jobs.get(session, job_id)
    return [
        ArtifactOut(
            name=a.name,
            size_bytes=a.size_bytes,
            content_type=content_type(a.name),
            url=f"/api/v1/jobs/{job_id}/artifacts/{a.name}",
        )
        for a in store.list(job_id)
    ]


@router.get(
    "/{job_id}/artifacts/{name}",
    response_class=FileResponse,
    responses={
        200: {"description": "the file", "content": {t: {} for t in _MEDIA_TYPES}},
        206: {"description": "the requested byte range (send `Range: bytes=a-b`)"},
        **error_responses(404, 416, 422, 500),
    },
)
def get_artifact(
    job_id: JobId, name: ArtifactName, request: Request, session: SessionDep, store: StoreDep
) -> FileResponse:
    """Download one artifact; ``Range`` requests are honoured (large point clouds resume), ``HEAD`` too."""
    jobs.get(session, job_id)
    path = store.path(job_id, name)
    disposition = "inline" if content_type(name).startswith(("text/", "image/", "application/json")) else "attachment"
    return serve_file(path, request, media_type=content_type(name), what=f"job {job_id}'s artifact {name!r}",
                      filename=name, content_disposition_type=disposition)


@router.get("/{job_id}/frames", response_model=Page[FrameOut], responses=error_responses(404, 422))
def list_frames(
    job_id: JobId,
    session: SessionDep,
    limit: Annotated[int, Query(ge=1, le=100_000)] = 10_000,
    offset: Offset = 0,
) -> Page[FrameOut]:
    """Per-frame statistics of a finished run, in frame order (formats.frame_stats.FrameStats; the pipeline's
    ``frame_stats.csv`` artifact holds the same frames with its own column names)."""
    jobs.get(session, job_id)
    rows = metrics.get_frame_stats(session, job_id, limit=limit, offset=offset)
    items = [FrameOut.model_validate(r, from_attributes=True) for r in rows]
    return Page[FrameOut](items=items, total=None, limit=limit, offset=offset)


def _sse(event: str, data: str, event_id: int) -> str:
    return f"id: {event_id}\nevent: {event}\ndata: {data}\n\n"


@router.get(
    "/{job_id}/events",
    responses={
        200: {
            "description": "`text/event-stream`: `progress` events (a JobOut as JSON) while the job changes, "
            "one `end` event when it reaches a final state, `: keep-alive` comments in between.",
            "content": {"text/event-stream": {}},
        },
        **error_responses(404, 429),
    },
)
async def job_events(
    job_id: JobId,
    request: Request,
    interval: Annotated[float, Query(ge=0.1, le=10.0, description="Polling interval in seconds.")] = 0.5,
) -> StreamingResponse:
    """Live progress as Server-Sent Events; the stream ends after the job's final state.

    Each poll opens and closes its own short session: a waiting stream holds no database connection, so
    open dashboards never starve the pool. A client may hold ``max_streams_per_client`` streams (429 beyond).
    """
    factory = request.app.state.session_factory
    await run_in_threadpool(_snapshot, factory, job_id, request.app.state)  # 404 before the stream starts
    slot = request.app.state.streams.acquire(_client_key(request))

    async def stream() -> AsyncIterator[str]:
        try:
            async for chunk in _events(factory, job_id, request, interval):
                yield chunk
        finally:
            slot.release()

    return StreamingResponse(
        stream(),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"},
    )


def _client_key(request: Request) -> str:
    return request.client.host if request.client else "unknown"


def _snapshot(factory: sessionmaker[Session], job_id: str, state: Any = None) -> JobOut:
    """The job as the client sees it, read in a session that is closed again before returning; with the
    app's ``state``, stale jobs reaped first (``backend.api.stale``)."""
    with factory() as session:
        if state is not None:
            reap_stale_with(state, session)
        return JobOut.of(jobs.get(session, job_id))


async def _events(
    factory: sessionmaker[Session], job_id: str, request: Request, interval: float
) -> AsyncIterator[str]:
    last, n, last_sent = None, 0, time.monotonic()
    yield "retry: 2000\n\n"
    while True:
        try:
            out = await run_in_threadpool(_snapshot, factory, job_id, request.app.state)
        except NotFound:
            n += 1
            yield _sse("deleted", json.dumps({"id": job_id}), n)
            return
        payload = out.model_dump_json(exclude={"eta_s"})
        if payload != last:
            last, last_sent = payload, time.monotonic()
            n += 1
            yield _sse("progress", out.model_dump_json(), n)
        if out.status.is_terminal:
            n += 1
            yield _sse("end", json.dumps({"id": job_id, "status": out.status.value}), n)
            return
        if time.monotonic() - last_sent > 15:
            last_sent = time.monotonic()
            yield ": keep-alive\n\n"
        if await request.is_disconnected():
            return
        await asyncio.sleep(interval)
