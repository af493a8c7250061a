"""Request dependencies as ``Annotated`` aliases: handlers declare what they need by type.

Everything comes from ``app.state`` (filled by :func:`backend.app.create_app`), so tests build an app
with their own settings, database and queue; nothing is global.
"""

from __future__ import annotations

import hmac
from collections.abc import Callable, Iterator
from typing import Annotated, Any

from fastapi import Depends, FastAPI, Query, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from fastapi.security.utils import get_authorization_scheme_param
from sqlalchemy.orm import Session

from storage.artifacts import ArtifactStore
from storage.errors import Unauthorized
from storage.settings import Settings

Enqueue = Callable[[str], None]
"""Puts a job id on the queue (the worker's ``run_job`` task)."""


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


def get_session(request: Request) -> Iterator[Session]:
    with request.app.state.session_factory() as session:
        yield session


def get_store(request: Request) -> ArtifactStore:
    return request.app.state.store


def get_enqueue(request: Request) -> Enqueue:
    return request.app.state.enqueue


_SCHEME = "HTTPBearer"
_bearer = HTTPBearer(
    auto_error=False, scheme_name=_SCHEME, description="Needed on mutating endpoints when VTD_API_TOKEN is set."
)


def check_token(request: Request) -> None:
    """When ``VTD_API_TOKEN`` is set, the request must carry ``Authorization: Bearer <token>``.

    Compared with :func:`hmac.compare_digest` (constant time: no timing oracle on the token's prefix).
    """
    token = request.app.state.settings.api_token
    if not token:
        return
    scheme, credentials = get_authorization_scheme_param(request.headers.get("authorization"))
    if not credentials or scheme.lower() != "bearer":
        raise Unauthorized("this endpoint needs 'Authorization: Bearer <token>'")
    if not hmac.compare_digest(credentials.encode(), token.encode()):
        raise Unauthorized("invalid API token")


def require_token(
    request: Request,
    _credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> None:
    """The ``Auth`` dependency: documents the bearer scheme in OpenAPI and checks the token.

    :class:`backend.api.guard.GuardedRoute` runs the same check before the body is read.
    """
    check_token(request)


MAX_OFFSET = 2**31 - 1
"""Far past any real listing, and inside every database's integer range (SQLite raised OverflowError)."""
Limit = Annotated[int, Query(ge=1, le=1000)]
Offset = Annotated[int, Query(ge=0, le=MAX_OFFSET)]


def document_auth(app: FastAPI, *, required: bool) -> None:
    """Make the OpenAPI ``security`` of token-guarded routes say what this deployment enforces.

    FastAPI always documents ``HTTPBearer`` as required; without ``VTD_API_TOKEN`` the routes also take
    anonymous requests, which OpenAPI writes as the alternative ``{}`` (clients and fuzzers then know).
    """
    if required:
        return
    build = app.openapi

    def openapi() -> dict[str, Any]:
        fresh = app.openapi_schema is None
        spec = build()
        if fresh:
            for ops in spec.get("paths", {}).values():
                for op in ops.values():
                    if op.get("security") == [{_SCHEME: []}]:
                        op["security"] = [{_SCHEME: []}, {}]
        return spec

    app.openapi = openapi  # type: ignore[method-assign]


SettingsDep = Annotated[Settings, Depends(get_settings)]
SessionDep = Annotated[Session, Depends(get_session)]
StoreDep = Annotated[ArtifactStore, Depends(get_store)]
EnqueueDep = Annotated[Enqueue, Depends(get_enqueue)]
Auth = Depends(require_token)
"""Add to a mutating route: ``@router.post(..., dependencies=[Auth])``."""
