"""A same-origin reverse proxy of each run's viser server: ``/viewer/{job_id}/...`` on the api's port.

viser's page opens its WebSocket on the page's own URL (``ws://<api>/viewer/{job_id}``), so proxying the
page (HTTP) and that socket is all it needs; the browser never sees the hub's or the run servers' ports,
and one forwarded port (the api's) is enough. The api asks the hub where the run answers on every page
load and socket, so a run server the hub restarted on another port is found again.

Read-only like every GET of the api (no token needed); a WebSocket from another site's page is refused
(its ``Origin`` must be this api's or one of ``VTD_CORS_ORIGINS``).
"""

from __future__ import annotations

import asyncio
import contextlib
import urllib.error
import urllib.request
from email.message import Message
from urllib.parse import quote, urlsplit

from fastapi import APIRouter, Request, WebSocket
from fastapi.responses import RedirectResponse, Response
from starlette.concurrency import run_in_threadpool
from starlette.websockets import WebSocketDisconnect, WebSocketState
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI
from websockets.typing import Subprotocol

from backend.api.deps import SessionDep, SettingsDep
from backend.api.errors import ApiError
from backend.api.schemas import JobId
from backend.api.viewer import VIEWER_PREFIX, RunAddress, ViewerUnavailable, open_run, viewer_path
from storage.repositories import jobs
from storage.settings import Settings

router = APIRouter(prefix=VIEWER_PREFIX, include_in_schema=False)

FETCH_TIMEOUT_S = 15.0
"""viser's page is one ~0.8 MB file served from memory: seconds only when the machine is very busy."""
PASSED_HEADERS = ("content-type", "content-encoding", "cache-control", "last-modified", "etag")
POLICY_VIOLATION = 1008
UPSTREAM_FAILED = 1011

_opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))


@router.get("/{job_id}")
async def viewer_root(job_id: JobId) -> RedirectResponse:
    """The page lives at the trailing-slash URL (its socket at this one)."""
    return RedirectResponse(viewer_path(job_id), status_code=307)


@router.get("/{job_id}/{path:path}")
async def viewer_page(job_id: JobId, path: str, request: Request, session: SessionDep,
                      settings: SettingsDep) -> Response:
    """viser's page and any asset it asks for, fetched from the run's server."""
    await run_in_threadpool(jobs.get, session, job_id)  # 404 for an unknown job
    run = await run_in_threadpool(open_run, settings, job_id)
    url = f"http://{run.netloc}/{quote(path, safe='/')}"
    if request.url.query:
        url += f"?{request.url.query}"
    accept = request.headers.get("accept-encoding", "")
    return await run_in_threadpool(_fetch, url, accept)


def _fetch(url: str, accept_encoding: str) -> Response:
    request = urllib.request.Request(url, headers={"Accept-Encoding": accept_encoding} if accept_encoding else {})
    try:
        with _opener.open(request, timeout=FETCH_TIMEOUT_S) as resp:
            return _response(resp.status, resp.headers, resp.read())
    except urllib.error.HTTPError as exc:  # viser's own 404 for an unknown asset: pass it on
        with exc:
            return _response(exc.code, exc.headers, exc.read())
    except OSError as exc:
        raise ViewerUnavailable("the run's 3D viewer stopped answering; reload the page",
                                {"reason": str(getattr(exc, "reason", exc))}) from None


def _response(status: int, headers: Message, body: bytes) -> Response:
    passed = {name: value for name in PASSED_HEADERS if (value := headers.get(name)) is not None}
    return Response(body, status_code=status, headers=passed)


def allowed_origin(websocket: WebSocket, settings: Settings) -> bool:
    """A browser's socket must come from a page of this api (or of a configured CORS origin)."""
    origin = websocket.headers.get("origin")
    if origin is None:  # not a browser: nothing to protect from cross-site use
        return True
    if origin in settings.cors_origins or "*" in settings.cors_origins:
        return True
    return urlsplit(origin).netloc.lower() == websocket.headers.get("host", "").lower()


@router.websocket("/{job_id}")
async def viewer_socket(websocket: WebSocket, job_id: JobId) -> None:
    """viser's scene stream, relayed both ways between the browser and the run's server."""
    settings: Settings = websocket.app.state.settings
    if not allowed_origin(websocket, settings):
        await websocket.close(POLICY_VIOLATION, "cross-site viewer sockets are refused")
        return
    try:
        run: RunAddress = await run_in_threadpool(open_run, settings, job_id)
    except ApiError as exc:
        await websocket.close(UPSTREAM_FAILED if exc.http_status >= 500 else POLICY_VIOLATION, exc.message[:120])
        return
    offered = [Subprotocol(p) for p in websocket.scope.get("subprotocols", [])]
    try:
        upstream = await connect(f"ws://{run.netloc}/", subprotocols=offered or None, compression=None,
                                 max_size=None, proxy=None, open_timeout=FETCH_TIMEOUT_S)
    except (OSError, TimeoutError, InvalidHandshake, InvalidURI):
        await websocket.close(UPSTREAM_FAILED, "the run's 3D viewer is not answering")
        return
    async with upstream:
        await websocket.accept(subprotocol=upstream.subprotocol)
        await _relay(websocket, upstream)
    if websocket.client_state == WebSocketState.CONNECTED:
        with contextlib.suppress(RuntimeError, WebSocketDisconnect):
            await websocket.close()


async def _relay(websocket: WebSocket, upstream: ClientConnection) -> None:
    """Copy frames both ways until either side closes (then stop the other direction)."""

    async def to_upstream() -> None:
        while True:
            message = await websocket.receive()
            if message["type"] == "websocket.disconnect":
                return
            data = message.get("bytes")
            await upstream.send(data if data is not None else message.get("text") or "")

    async def to_browser() -> None:
        async for data in upstream:
            if isinstance(data, bytes):
                await websocket.send_bytes(data)
            else:
                await websocket.send_text(data)

    tasks = [asyncio.create_task(to_upstream()), asyncio.create_task(to_browser())]
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in tasks:
            task.cancel()
        results = await asyncio.gather(*tasks, return_exceptions=True)
    for result in results:  # a side hanging up is the normal end of a session; anything else is a bug
        if isinstance(result, BaseException) and not isinstance(
            result, (asyncio.CancelledError, ConnectionClosed, WebSocketDisconnect, RuntimeError, OSError)
        ):
            raise result
