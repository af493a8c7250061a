"""Request dependencies as ``Annotated`` aliases: handlers declare what they need by type.

Everything comes from ``app.state`` (filled by :func:`backend.app.create_app`), so tests build an app
with their own settings, database and queue; nothing is global.
"""

from __future__ import annotations

import hmac
from collections.abc import Callable, Iterator
from typing import Annotated

from fastapi import Depends, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
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


_bearer = HTTPBearer(auto_error=False, description="Needed on mutating endpoints when VTD_API_TOKEN is set.")


def require_token(
    request: Request,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> None:
    """When ``VTD_API_TOKEN`` is set, the request must carry ``Authorization: Bearer <token>``."""
    token = request.app.state.settings.api_token
    if not token:
        return
    if credentials is None or credentials.scheme.lower() != "bearer":
        raise Unauthorized("this endpoint needs 'Authorization: Bearer <token>'")
    if not hmac.compare_digest(credentials.credentials.encode(), token.encode()):
        raise Unauthorized("invalid API token")


SettingsDep = Annotated[Settings, Depends(get_settings)]
SessionDep = Annotated[Session, Depends(get_session)]
StoreDep = Annotated[ArtifactStore, Depends(get_store)]
EnqueueDep = Annotated[Enqueue, Depends(get_enqueue)]
Auth = Depends(require_token)
"""Add to a mutating route: ``@router.post(..., dependencies=[Auth])``."""
