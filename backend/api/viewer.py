"""``GET /jobs/{id}/viewer``: where the browser finds the run's 3D scene, and the hub client behind it.

The viewer hub (``vtdslam viewer``, see :mod:`webui.viewer.hub`) starts one viser server per run; the api
asks it (stdlib urllib, short timeout) where that server answers and serves it on its own origin under
``/viewer/{job_id}/`` (:mod:`backend.api.viewer_proxy`), so a browser needs the api's port only.
"""

from __future__ import annotations

import json
import urllib.error
import urllib.request
from dataclasses import dataclass
from typing import Any
from urllib.parse import quote, urlsplit

from fastapi import APIRouter
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool

from backend.api.deps import SessionDep, SettingsDep
from backend.api.errors import ApiError, error_responses
from backend.api.schemas import JobId
from storage.repositories import jobs
from storage.settings import Settings

router = APIRouter(prefix="/jobs", tags=["jobs"])

HUB_TIMEOUT_S = 15.0
"""Opening a run loads its map and starts a viser server: a few seconds for a large map at most."""
HUB_KEY_HEADER = "X-VTD-Hub-Key"
"""The header the hub reads its key from (``webui.viewer.hub.KEY_HEADER``; the api never imports webui)."""
VIEWER_PREFIX = "/viewer"
"""Where the api serves each run's scene: ``/viewer/{job_id}/`` (page) and ``/viewer/{job_id}`` (WebSocket)."""

# Our own hub and run servers are local: never send these calls through an HTTP(S)_PROXY of the environment.
_opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))


class ViewerUnavailable(ApiError):
    code = "viewer_unavailable"
    http_status = 503


class HubRefused(ApiError):
    """The hub answered with an error of its own (e.g. the run has no trajectory yet)."""

    def __init__(self, status: int, error: dict[str, Any]) -> None:
        super().__init__(str(error.get("message") or "the viewer refused the run"), error.get("detail"))
        self.http_status = status
        self.code = str(error.get("code") or "viewer_error")


@dataclass(frozen=True)
class RunAddress:
    """Where a run's viser server answers, as the api dials it (never shown to browsers)."""

    host: str
    port: int

    @property
    def netloc(self) -> str:
        return f"[{self.host}]:{self.port}" if ":" in self.host else f"{self.host}:{self.port}"


class ViewerOut(BaseModel):
    url: str = Field(description="The run's viser scene on this api's origin, to open or embed (an iframe works).",
                     examples=["/viewer/3f2a9c0d4b1e4f7a8c6d5e4f3a2b1c0d/"])


def hub_address(settings: Settings) -> str:
    """The control API's base URL; a wildcard bind address is reached on loopback."""
    host = settings.host
    if host in ("0.0.0.0", "", "::"):
        host = "127.0.0.1" if host != "::" else "::1"
    if ":" in host:
        host = f"[{host}]"
    return f"http://{host}:{settings.viewer_port}"


def ask_hub(base: str, job_id: str, key: str | None = None, timeout: float = HUB_TIMEOUT_S) -> RunAddress:
    """Where ``job_id``'s viser server answers (the hub starts it on first use).

    ``key`` is the hub key (``Settings.viewer_hub_key``), sent when the api has a token. A hub that names
    no host serves its runs on its own address.
    """
    headers = {HUB_KEY_HEADER: key} if key else {}
    request = urllib.request.Request(f"{base}/runs/{quote(job_id, safe='')}", headers=headers)
    try:
        with _opener.open(request, timeout=timeout) as resp:
            body = json.load(resp)
    except urllib.error.HTTPError as exc:
        error = _error_of(exc)
        if exc.code == 403:
            raise ViewerUnavailable("the 3D viewer refused the api's key: start the api and 'vtdslam viewer' "
                                    "with the same VTD_API_TOKEN", {"hub": base}) from None
        if (400 <= exc.code < 500 or error.get("code") == "artifact_unreadable") and error:
            raise HubRefused(exc.code, error) from None  # the hub's own words (a file it cannot read, …)
        raise ViewerUnavailable(f"the 3D viewer failed to open the run (HTTP {exc.code})", error) from None
    except (OSError, ValueError) as exc:  # refused, unreachable, timed out, not JSON
        reason = getattr(exc, "reason", exc)
        if isinstance(reason, TimeoutError):
            raise ViewerUnavailable(
                f"the 3D viewer did not answer within {timeout:g} s (a very large map loads slowly); try again",
                {"hub": base},
            ) from None
        raise ViewerUnavailable(
            "the 3D viewer is not running or not answering; start it with 'vtdslam viewer' "
            "(it starts with 'vtdslam serve')",
            {"hub": base, "reason": str(reason)},
        ) from None
    port = body.get("port") if isinstance(body, dict) else None
    if not isinstance(port, int) or not 0 < port < 65536:
        raise ViewerUnavailable("the 3D viewer gave no port for the run", {"hub": base})
    host = body.get("host") or urlsplit(base).hostname
    if not isinstance(host, str) or not host:
        raise ViewerUnavailable("the 3D viewer gave no usable host for the run", {"hub": base})
    return RunAddress(host, port)


def open_run(settings: Settings, job_id: str) -> RunAddress:
    """``ask_hub`` with this api's hub address and key."""
    return ask_hub(hub_address(settings), job_id, settings.viewer_hub_key)


def _error_of(exc: urllib.error.HTTPError) -> dict[str, Any]:
    try:
        error = json.loads(exc.read().decode("utf-8", "replace")).get("error")
    except (ValueError, AttributeError, OSError):
        return {}
    return error if isinstance(error, dict) else {}


def viewer_path(job_id: str) -> str:
    return f"{VIEWER_PREFIX}/{quote(job_id, safe='')}/"


@router.get("/{job_id}/viewer", response_model=ViewerOut, responses=error_responses(404, 409, 503))
async def job_viewer(job_id: JobId, session: SessionDep, settings: SettingsDep) -> ViewerOut:
    """Where the run's 3D scene is (map, trajectory vs ground truth, keyframes, frame slider): a path on
    this api's origin, so whoever reaches the api reaches the viewer."""
    await run_in_threadpool(jobs.get, session, job_id)  # 404 for an unknown job
    await run_in_threadpool(open_run, settings, job_id)  # the hub's answer now, not a broken page later
    return ViewerOut(url=viewer_path(job_id))
