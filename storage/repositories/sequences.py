"""Sequences: the RGB-D recordings jobs run on."""

from __future__ import annotations

from typing import Any

from sqlalchemy import delete as sql_delete
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from storage.errors import Conflict
from storage.models import Job, Sequence, new_id
from storage.repositories._common import check_page, get_or_raise, writing


def create(
    session: Session,
    *,
    name: str,
    path: str,
    frames: int = 0,
    duration_s: float = 0.0,
    has_groundtruth: bool = False,
    camera: dict[str, Any] | None = None,
    size_bytes: int = 0,
    meta: dict[str, Any] | None = None,
    id: str | None = None,
    content_sha256: str | None = None,
    claim: bool = False,
) -> Sequence:
    """Record a sequence already in place; ``id`` may be chosen first to name its directory.

    ``claim``: this sequence holds ``content_sha256`` against duplicates; if another already holds it
    (an upload of the same archive that committed first), nothing is recorded and a :class:`Conflict`
    names that one.
    """
    seq = Sequence(
        id=id or new_id(),
        name=name,
        path=path,
        frames=frames,
        duration_s=duration_s,
        has_groundtruth=has_groundtruth,
        camera=camera or {},
        size_bytes=size_bytes,
        meta=meta or {},
        content_sha256=content_sha256,
        claimed_sha256=content_sha256 if claim else None,
    )
    try:
        with writing(session):
            session.add(seq)
    except IntegrityError:
        holder = _claimant(session, content_sha256) if claim and content_sha256 else None
        if holder is None:  # another constraint refused the row
            raise
        raise duplicate_upload(holder, holder.claimed_sha256 or "") from None
    return seq


def duplicate_upload(existing: Sequence, sha256: str) -> Conflict:
    """The 409 for an archive already uploaded as ``existing``."""
    return Conflict(
        f'this archive was already uploaded as "{existing.name}" (sequence {existing.id}); '
        "send allow_duplicate=true to add it again",
        {"existing_id": existing.id, "existing_name": existing.name, "sha256": sha256},
    )


def _claimant(session: Session, sha256: str) -> Sequence | None:
    return session.scalars(select(Sequence).where(Sequence.claimed_sha256 == sha256)).first()


def get(session: Session, sequence_id: str) -> Sequence:
    return get_or_raise(session, Sequence, sequence_id, "sequence")


def find_by_content(session: Session, content_sha256: str) -> Sequence | None:
    """The oldest sequence uploaded from an archive with this SHA-256 (hex), if any."""
    stmt = (
        select(Sequence)
        .where(Sequence.content_sha256 == content_sha256)
        .order_by(Sequence.created_at, Sequence.id)
        .limit(1)
    )
    return session.scalars(stmt).first()


def latest_jobs(session: Session, sequence_ids: list[str]) -> dict[str, Job]:
    """Each listed sequence's newest job (by creation), for those that have one."""
    if not sequence_ids:
        return {}
    newest = (
        select(Job.sequence_id, func.max(Job.created_at).label("created_at"))
        .where(Job.sequence_id.in_(sequence_ids))
        .group_by(Job.sequence_id)
        .subquery()
    )
    stmt = (
        select(Job)
        .join(newest, (Job.sequence_id == newest.c.sequence_id) & (Job.created_at == newest.c.created_at))
        .order_by(Job.id)
        .execution_options(populate_existing=True)
    )
    # Two jobs created in the same instant: the larger id wins, the same choice on every call.
    return {job.sequence_id: job for job in session.scalars(stmt)}


def list_sequences(session: Session, *, limit: int = 50, offset: int = 0) -> list[Sequence]:
    """Newest first."""
    check_page(limit, offset)
    stmt = (
        select(Sequence)
        .order_by(Sequence.created_at.desc(), Sequence.id)
        .limit(limit)
        .offset(offset)
        .execution_options(populate_existing=True)
    )
    return list(session.scalars(stmt))


def count(session: Session) -> int:
    return session.scalar(select(func.count()).select_from(Sequence)) or 0


def delete(session: Session, sequence_id: str) -> list[str]:
    """Delete the sequence and (by cascade) its jobs, metrics and frame stats.

    Returns the deleted jobs' ids so the caller can remove their artifacts and files.
    """
    with writing(session):
        get(session, sequence_id)
        job_ids = list(session.scalars(select(Job.id).where(Job.sequence_id == sequence_id)))
        session.execute(sql_delete(Sequence).where(Sequence.id == sequence_id))
    return job_ids


def set_recorded(session: Session, sequence_id: str, *, frames: int, duration_s: float, size_bytes: int,
                 has_groundtruth: bool, meta: dict[str, Any]) -> Sequence:
    """What a live session's sequence holds once its stream ended (its row was created empty)."""
    with writing(session):
        seq = get(session, sequence_id)
        seq.frames, seq.duration_s, seq.size_bytes = frames, duration_s, size_bytes
        seq.has_groundtruth = has_groundtruth
        seq.meta = {**(seq.meta or {}), **meta}
    return seq


def update_meta(session: Session, sequence_id: str, meta: dict[str, Any]) -> Sequence:
    """Merge ``meta`` into the sequence's ``meta`` (a live session names its job there)."""
    with writing(session):
        seq = get(session, sequence_id)
        seq.meta = {**(seq.meta or {}), **meta}
    return seq
