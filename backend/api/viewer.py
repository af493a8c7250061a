"""``GET /jobs/{id}/viewer``: where the browser finds the run's 3D scene.

The viewer hub (``vtdslam viewer``, see :mod:`webui.viewer.hub`) starts one viser server per run and
tells its port; the api only asks it (stdlib urllib, short timeout) and answers with a URL on the host
the browser already used, so a dashboard opened from another machine gets a reachable address.
"""

from __future__ import annotations

import json
import urllib.error
import urllib.request
from urllib.parse import quote

from fastapi import APIRouter, Request
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


class ViewerUnavailable(ApiError):
    code = "viewer_unavailable"
    http_status = 503


class HubRefused(ApiError):
    """The hub answered with an error of its own (e.g. the run has no trajectory yet)."""

    def __init__(self, status: int, error: dict) -> None:
        super().__init__(str(error.get("message") or "the viewer refused the run"), error.get("detail"))
        self.http_status = status
        self.code = str(error.get("code") or "viewer_error")


class ViewerOut(BaseModel):
    url: str = Field(description="The run's viser scene, to open or embed (an iframe works).",
                     examples=["http://127.0.0.1:40123/"])
    port: int


def hub_address(settings: Settings) -> str:
    """The control API's base URL; a wildcard bind address is reached on loopback."""
    host = settings.host
    if host in ("0.0.0.0", "", "::"):
        host = "127.0.0.1"
    if ":" in host:
        host = f"[{host}]"
    return f"http://{host}:{settings.viewer_port}"


def ask_hub(base: str, job_id: str, timeout: float = HUB_TIMEOUT_S) -> int:
    """The port of ``job_id``'s viser server (the hub starts it on first use)."""
    url = f"{base}/runs/{quote(job_id, safe='')}"
    try:
        with urllib.request.urlopen(url, timeout=timeout) as resp:  # noqa: S310 (our own hub, http only)
            body = json.load(resp)
    except urllib.error.HTTPError as exc:
        error = _error_of(exc)
        if 400 <= exc.code < 500 and error:
            raise HubRefused(exc.code, error) from None
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
    return port


def _error_of(exc: urllib.error.HTTPError) -> dict:
    try:
        error = json.loads(exc.read().decode("utf-8", "replace")).get("error")
    except (ValueError, AttributeError, OSError):
        return {}
    return error if isinstance(error, dict) else {}


def browser_host(request: Request) -> str:
    """The host name the browser used for the api (IPv6 in brackets)."""
    host = request.url.hostname or "127.0.0.1"
    return f"[{host}]" if ":" in host else host


@router.get("/{job_id}/viewer", response_model=ViewerOut, responses=error_responses(404, 409, 503))
async def job_viewer(job_id: JobId, request: Request, session: SessionDep, settings: SettingsDep) -> ViewerOut:
    """The URL of the run's 3D scene (map, trajectory vs ground truth, keyframes, frame slider)."""
    await run_in_threadpool(jobs.get, session, job_id)  # 404 for an unknown job
    port = await run_in_threadpool(ask_hub, hub_address(settings), job_id)
    return ViewerOut(url=f"http://{browser_host(request)}:{port}/", port=port)
