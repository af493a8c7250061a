"""The dashboard's HTML pages and static assets (templates and JS/CSS live in ``webui/``).

Pages are thin server-rendered shells: each loads ``app.js`` plus its own script, which reads the REST
api under ``/api/v1``. :func:`include_dashboard` adds the pages, the viewer endpoint and ``/static``.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, FastAPI, Request
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles
from fastapi.templating import Jinja2Templates

import webui
from backend.api import viewer, viewer_proxy
from storage.presets import CAMERA_PRESETS, PIPELINE_PRESETS

WEBUI_DIR = Path(webui.__file__).resolve().parent
TEMPLATES_DIR = WEBUI_DIR / "templates"
STATIC_DIR = WEBUI_DIR / "static"
BASELINE_PRESET = "orb-only"
"""The batch table's percentages are relative to this preset (the paper's ORB-SLAM2 column)."""

router = APIRouter(include_in_schema=False)
templates = Jinja2Templates(directory=str(TEMPLATES_DIR))


def _page(request: Request, template: str, active: str, **context: object) -> HTMLResponse:
    base = {
        "active": active,
        "version": request.app.version,
        "camera_presets": CAMERA_PRESETS,
        "pipeline_presets": PIPELINE_PRESETS,
        "baseline_preset": BASELINE_PRESET,
    }
    return templates.TemplateResponse(request, template, {**base, **context})


@router.get("/", response_class=HTMLResponse)
@router.get("/sequences", response_class=HTMLResponse)
def sequences_page(request: Request) -> HTMLResponse:
    return _page(request, "sequences.html", "sequences")


@router.get("/jobs", response_class=HTMLResponse)
def jobs_page(request: Request) -> HTMLResponse:
    return _page(request, "jobs.html", "jobs")


@router.get("/jobs/{job_id}", response_class=HTMLResponse)
def job_page(request: Request, job_id: str) -> HTMLResponse:
    return _page(request, "job.html", "jobs", job_id=job_id)


@router.get("/batches/{batch_id}", response_class=HTMLResponse)
def batch_page(request: Request, batch_id: str) -> HTMLResponse:
    return _page(request, "batch.html", "jobs", batch_id=batch_id)


def include_dashboard(app: FastAPI, api_prefix: str = "/api/v1") -> None:
    """Add the dashboard pages, ``GET {api_prefix}/jobs/{id}/viewer``, the ``/viewer/`` proxy and ``/static``
    (once per app)."""
    if getattr(app.state, "dashboard_included", False):
        return
    app.include_router(viewer.router, prefix=api_prefix)
    app.include_router(viewer_proxy.router)  # each run's scene under /viewer/{job_id}/ on this origin
    app.include_router(router)
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    app.state.dashboard_included = True
