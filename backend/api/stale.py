"""Reads that show jobs reap the stale ones first (``storage.reaping``, the workers' own reaper): a running
job whose heartbeat is older than ``Settings.heartbeat_timeout_s`` shows failed (or requeued, within
``requeue_orphans``) with the reason, even when no worker is alive to notice. One read when nothing is
stale; a read never fails for it (a locked database: the next read, or a worker's reaper, tries again)."""

from __future__ import annotations

import logging
from typing import Any

from fastapi import Depends, Request
from sqlalchemy.orm import Session

from backend.api.deps import SessionDep
from storage.reaping import reap_stale_jobs

log = logging.getLogger("backend.api")


def reap_stale_with(state: Any, session: Session) -> None:
    """Reap with the app's settings, store and queue (``app.state``) in ``session``."""
    settings = state.settings
    try:
        reap_stale_jobs(session, state.store, timeout_s=settings.heartbeat_timeout_s,
                        requeue_limit=settings.requeue_orphans, enqueue=state.enqueue)
    except Exception as exc:
        session.rollback()
        log.warning("could not check for stale jobs: %s", exc)


def _reap_stale(request: Request, session: SessionDep) -> None:
    reap_stale_with(request.app.state, session)


ReapStale = Depends(_reap_stale)
"""Add to a route that shows job statuses: ``@router.get(..., dependencies=[ReapStale])``."""
