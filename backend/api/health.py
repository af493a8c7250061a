"""``GET /health``: the api is up and its database answers."""

from __future__ import annotations

from fastapi import APIRouter, Request
from sqlalchemy import text

from backend.api.deps import SessionDep
from backend.api.schemas import Health

router = APIRouter(tags=["health"])


@router.get("/health", response_model=Health)
def health(request: Request, session: SessionDep) -> Health:
    try:
        session.execute(text("SELECT 1"))
        database = "ok"
    except Exception as exc:  # reported, not raised: health answers even when the database is down
        database = f"error: {type(exc).__name__}"
    return Health(status="ok" if database == "ok" else "degraded", version=request.app.version, database=database)
