"""Live sessions: a client streams RGB-D frames over a WebSocket; the worker runs them as they arrive.

``POST /live`` creates the session: an empty sequence (``storage.live``: frames are kept as they arrive, TUM
layout) and a queued job the worker runs as a live session (``worker.live``). One client then streams to
``WS /live/{job_id}/stream`` (the token in ``Authorization: Bearer`` when one is set): binary frames (see
:mod:`backend.api.live_frames`), optionally ``{"type": "groundtruth", "text": ...}`` and ``{"type": "ping"}``
(answered ``{"type": "pong", "frames": n kept so far}``), and ``{"type": "end"}``. The server answers
``{"type": "ready"}``, ``{"type": "ended", "frames": n}`` at the end, and before closing on a
problem ``{"type": "error", "error": {"code", "message", "detail"}}`` with close code 4000 + the HTTP status the
same problem gets elsewhere (4401 token, 4404 unknown session, 4409 a second client or an ended session, 4413 an
oversized frame, 4422 a bad frame). However the stream ends (end message, disconnect, refused frame) the frames
received are kept and the job finishes with them. ``GET /jobs/{id}/partial`` is what the page polls while any
job runs (its latest poses and counts, ``worker.snapshots``).
"""
from __future__ import annotations

import asyncio
import json
import logging
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from fastapi import APIRouter, WebSocket, WebSocketDisconnect, status
from pydantic import BaseModel, ConfigDict, Field
from starlette.concurrency import run_in_threadpool

from backend.api.deps import Auth, EnqueueDep, SessionDep, StoreDep, check_token
from backend.api.errors import error_responses
from backend.api.guard import GuardedRoute
from backend.api.jobs import check_config, enqueue_or_fail
from backend.api.live_frames import MAX_FRAME_BYTES, FrameReceiver
from backend.api.schemas import JobId
from formats import artifacts
from storage import live as spool_mod
from storage.errors import Conflict, NotFound, ServiceError, StorageError
from storage.models import new_id
from storage.presets import check_preset, parse_camera_spec
from storage.repositories import jobs, sequences

router = APIRouter(tags=["live"], route_class=GuardedRoute)
log = logging.getLogger("backend.api.live")

DEFAULT_LIVE_PRESET = "no-restoration"
"""The preset that keeps up with a 30 Hz camera on two cores (docs/results/realtime.md)."""


class LiveCreate(BaseModel):
    camera: str | dict[str, Any] = Field(description="Camera preset name or intrinsics (as for uploads).",
                                         examples=["bonn"])
    preset: str = Field(default=DEFAULT_LIVE_PRESET, min_length=1, max_length=64,
                        description=f"Pipeline preset (default {DEFAULT_LIVE_PRESET}).")
    name: str | None = Field(default=None, max_length=255)
    config: dict[str, Any] | None = Field(default=None, description="Config overrides, as for jobs.")

    model_config = ConfigDict(extra="forbid")


class LiveOut(BaseModel):
    job_id: str
    sequence_id: str
    stream_url: str = Field(description="The WebSocket path to stream frames to (one client per session).")
    max_frame_bytes: int


@router.post("/live", status_code=status.HTTP_201_CREATED, response_model=LiveOut, dependencies=[Auth],
             responses=error_responses(400, 401, 413, 422, 503))
def create_session(body: LiveCreate, session: SessionDep, store: StoreDep, enqueue: EnqueueDep) -> LiveOut:
    """Start a live session: an empty sequence that fills as frames arrive, and its job."""
    camera = parse_camera_spec(body.camera)
    preset, config = check_preset(body.preset), check_config(body.config)
    seq_id = new_id()
    folder = store.sequence_dir(seq_id)
    spool_mod.LiveSpool(folder).create()
    try:
        sequences.create(session, id=seq_id, name=body.name or f"live {time.strftime('%Y-%m-%d %H:%M:%S')}",
                         path=store.relative(folder), camera=camera,
                         meta={"source": "live", "live": spool_mod.LIVE_RECEIVING})
        job = jobs.create(session, sequence_id=seq_id, preset=preset, config=config)
        sequences.update_meta(session, seq_id, {spool_mod.LIVE_JOB: job.id})
    except BaseException:
        store.delete_sequence(seq_id)
        raise
    enqueue_or_fail(session, enqueue, [job.id])
    return LiveOut(job_id=job.id, sequence_id=seq_id, stream_url=f"/api/v1/live/{job.id}/stream",
                   max_frame_bytes=MAX_FRAME_BYTES)


@router.get("/jobs/{job_id}/partial", responses=error_responses(404))
def job_partial(job_id: JobId, session: SessionDep, store: StoreDep) -> dict[str, Any]:
    """A running job's latest poses and counts (``partial.json``: null before the first frame and after the
    end), its status, and whether its sequence is a live session still receiving."""
    job = jobs.get(session, job_id)
    seq = sequences.get(session, job.sequence_id)
    try:
        state = json.loads(store.path(job_id, artifacts.PARTIAL_STATE).read_text())
    except (NotFound, FileNotFoundError, ValueError):
        state = None
    return {"job_id": job.id, "status": job.status.value, "live": (seq.meta or {}).get("live"), "state": state}


def _open(app: Any, job_id: str) -> tuple[str, spool_mod.LiveSpool]:
    """The job's session spool, claimed for this client; NotFound / Conflict otherwise."""
    with app.state.session_factory() as session:
        job = jobs.get(session, job_id)
        seq = sequences.get(session, job.sequence_id)
        if (seq.meta or {}).get("source") != "live":
            raise NotFound(f"job {job_id} is not a live session", {"id": job_id})
        spool = spool_mod.LiveSpool(app.state.store.resolve(seq.path))
    spool.claim_client()
    return seq.id, spool


async def _refuse(ws: WebSocket, exc: ServiceError, accepted: bool = False) -> None:
    if not accepted:
        await ws.accept()
    await ws.send_json({"type": "error", "error": exc.to_dict()})
    await ws.close(code=4000 + exc.http_status, reason=exc.message[:120])


@router.websocket("/live/{job_id}/stream")
async def stream_frames(websocket: WebSocket, job_id: str) -> None:
    """One client streams one session's frames (see the module docstring for the protocol)."""
    app = websocket.app
    try:
        check_token(websocket)  # type: ignore[arg-type]  # reads .app and .headers, which a WebSocket has
        seq_id, spool = await run_in_threadpool(_open, app, job_id)
    except ServiceError as exc:
        return await _refuse(websocket, exc)
    await websocket.accept()
    receiver = FrameReceiver(spool, app.state.settings)
    # one thread per session writes its frames in order; the end waits for the frame in flight
    writer = ThreadPoolExecutor(1, thread_name_prefix=f"live-{job_id[:8]}")
    reason = "client disconnected"
    await websocket.send_json({"type": "ready", "job_id": job_id, "sequence_id": seq_id,
                               "max_frame_bytes": MAX_FRAME_BYTES})
    connected = True
    try:
        reason = await _receive(websocket, receiver, spool, writer)
    except WebSocketDisconnect:
        connected = False
    except StorageError as exc:
        reason = f"refused: {exc.message}"
        log.info("live session %s: %s", job_id, exc.message)
        await _refuse(websocket, exc, accepted=True)
        connected = False
    finally:  # synchronous: a handler cancelled by its server's shutdown still records the session
        writer.shutdown(wait=True)
        end = _end(spool, reason, receiver.frames)
        _finalize(app, seq_id)
    if connected and end.reason == reason:
        await websocket.send_json({"type": "ended", "frames": end.frames, "job_id": job_id, "reason": end.reason})
        await websocket.close()


async def _receive(websocket: WebSocket, receiver: FrameReceiver, spool: spool_mod.LiveSpool,
                   writer: ThreadPoolExecutor) -> str:
    """Frames until the client ends the stream; the reason the stream ended."""
    loop = asyncio.get_running_loop()
    while True:
        msg = await websocket.receive()
        arrival = time.time()
        if msg["type"] == "websocket.disconnect":
            raise WebSocketDisconnect(msg.get("code", 1000))
        if msg.get("bytes") is not None:
            await loop.run_in_executor(writer, receiver.add, msg["bytes"], arrival)
        elif msg.get("text") is not None:
            kind = await loop.run_in_executor(writer, receiver.control, msg["text"])  # a ground truth is MBs
            if kind == "end":
                return "client ended the stream"
            if kind == "ping":  # how many frames are kept so far
                await websocket.send_json({"type": "pong", "frames": receiver.frames})
        ended = spool.ended()
        if ended is not None:  # the worker gave up on the session (cancelled, stopped)
            raise Conflict(f"the session ended: {ended.reason}", {"reason": ended.reason})


def _end(spool: spool_mod.LiveSpool, reason: str, frames: int) -> spool_mod.StreamEnd:
    try:
        return spool.end(reason, frames)
    except OSError as exc:  # the sequence was deleted meanwhile: nothing left to end
        log.warning("live session %s: could not mark its end: %s", spool.folder.name, exc)
        return spool_mod.StreamEnd(reason, frames, time.time())


def _finalize(app: Any, seq_id: str) -> None:
    try:
        with app.state.session_factory() as session:
            spool_mod.finalize(session, app.state.store, seq_id)
    except Exception as exc:  # the worker records it again when the job ends
        log.warning("live sequence %s: could not record it: %s", seq_id, exc)
