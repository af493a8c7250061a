"""FastAPI application factory. The api imports storage only: never torch, OpenCV or the pipeline."""

from __future__ import annotations

import threading
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager

from fastapi import APIRouter, FastAPI
from fastapi.middleware.cors import CORSMiddleware
from sqlalchemy.orm import Session, sessionmaker

from backend.api import batches, health, job_files, jobs, live, presets, sequences
from backend.api.deps import document_auth
from backend.api.docs import include_docs
from backend.api.edge import EdgeMiddleware
from backend.api.errors import install_error_handlers
from backend.api.head import HeadMiddleware
from backend.api.pages import include_dashboard
from backend.api.streams import StreamLimits
from formats.version import package_version
from storage.artifacts import ArtifactStore
from storage.db import init_db, make_engine, make_session_factory
from storage.ingest import sweep_stale_uploads
from storage.settings import Settings, get_settings

API_PREFIX = "/api/v1"
VERSION = package_version()
"""The installed package's (pyproject.toml): /health, OpenAPI and the dashboard's footer."""

DESCRIPTION = """Dynamic-scene RGB-D SLAM service (VTD-SLAM).

Upload a TUM-layout sequence (`POST /sequences`), queue runs (`POST /jobs`, or a whole preset comparison
with `POST /batches`), follow them live (`GET /jobs/{id}/events`, Server-Sent Events) and download the
trajectory, dense map and metrics (`GET /jobs/{id}/artifacts/{name}`). A camera or a recording can also stream
into a live session (`POST /live`, then the WebSocket `/live/{job_id}/stream`): its frames run as they arrive.

Errors always have the shape `{"error": {"code", "message", "detail"}}`. When the server sets
`VTD_API_TOKEN`, mutating endpoints need `Authorization: Bearer <token>`. Every `GET` also answers `HEAD`.
"""


class LazyEnqueue:
    """Builds the huey queue on first use (the api starts without touching Redis or the queue file)."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self._fn: Callable[[str], None] | None = None
        self._lock = threading.Lock()

    def __call__(self, job_id: str) -> None:
        with self._lock:
            if self._fn is None:
                from storage.queue import make_enqueue, make_huey

                self._fn = make_enqueue(make_huey(self.settings))
        self._fn(job_id)


def create_app(
    settings: Settings | None = None,
    *,
    enqueue: Callable[[str], None] | None = None,
    session_factory: sessionmaker[Session] | None = None,
    migrate: bool = True,
) -> FastAPI:
    """The api for ``settings`` (default: from the environment).

    ``enqueue`` (default: the huey queue of the settings) and ``session_factory`` (default: the settings'
    database) let tests inject their own; ``migrate`` upgrades the database schema at startup.
    """
    settings = settings or get_settings()
    engine = None
    if session_factory is None:
        engine = make_engine(settings)
        session_factory = make_session_factory(engine)

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        if migrate:
            init_db(session_factory.kw["bind"])
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        sweep_stale_uploads(app.state.store)
        yield
        if engine is not None:
            engine.dispose()

    app = FastAPI(
        title="VTD-SLAM",
        version=VERSION,
        description=DESCRIPTION,
        lifespan=lifespan,
        docs_url=None,  # /docs and /redoc come from include_docs: assets served here, not from a CDN
        redoc_url=None,
        openapi_tags=[
            {"name": "sequences", "description": "RGB-D sequences in the TUM layout"},
            {"name": "jobs", "description": "pipeline runs, their progress and outputs"},
            {"name": "batches", "description": "sequences x presets comparisons"},
            {"name": "live", "description": "live sessions: frames streamed over a WebSocket, run as they arrive"},
            {"name": "presets", "description": "pipeline and camera preset names"},
            {"name": "health", "description": "liveness"},
        ],
    )
    app.state.settings = settings
    app.state.session_factory = session_factory
    app.state.store = ArtifactStore(settings.data_dir)
    app.state.enqueue = enqueue or LazyEnqueue(settings)
    app.state.streams = StreamLimits(settings.max_streams_per_client)
    install_error_handlers(app)

    api = APIRouter(prefix=API_PREFIX)
    for module in (health, presets, sequences, jobs, job_files, batches, live):
        api.include_router(module.router)
    app.include_router(api)
    include_dashboard(app)  # dashboard pages, /static, the viewer endpoint and its /viewer/ proxy
    include_docs(app)
    document_auth(app, required=bool(settings.api_token))
    if settings.cors_origins:  # off by default: no cross-origin browser access unless configured
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST", "DELETE"],
            allow_headers=["Authorization", "Content-Type", "Range", "Last-Event-ID"],
            allow_credentials=False,  # the api authenticates by bearer token, never by cookie
            expose_headers=["Content-Disposition", "Content-Range", "Accept-Ranges"],
            max_age=600,
        )
    app.add_middleware(HeadMiddleware)  # every GET answers HEAD (headers only)
    app.add_middleware(EdgeMiddleware)  # added last, so outermost: every response gets its request id
    return app
