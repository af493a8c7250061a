from datetime import UTC, datetime, timedelta

import pytest
from sqlalchemy import text
from sqlalchemy.orm import Session

from storage.models import Job, JobStatus, Sequence


def test_defaults_and_aware_timestamps(session: Session) -> None:
    seq = Sequence(name="s", path="sequences/s")
    session.add(seq)
    session.commit()
    session.expunge_all()
    got = session.get(Sequence, seq.id)
    assert got is not None
    assert got.created_at.tzinfo is not None and got.created_at.utcoffset() == timedelta(0)
    assert (got.frames, got.has_groundtruth, got.camera, got.meta, got.size_bytes) == (0, False, {}, {}, 0)


def test_status_stored_as_plain_string(session: Session) -> None:
    seq = Sequence(name="s", path="p")
    job = Job(sequence=seq, preset="full")
    session.add(job)
    session.commit()
    raw = session.execute(text("SELECT status, attempts FROM jobs WHERE id = :i"), {"i": job.id}).one()
    assert tuple(raw) == ("queued", 1)
    assert job.status is JobStatus.QUEUED and not job.status.is_terminal


def test_naive_datetime_rejected(session: Session) -> None:
    session.add(Sequence(name="s", path="p", created_at=datetime(2024, 1, 1)))
    with pytest.raises(Exception, match="naive"):
        session.commit()
    session.rollback()


def test_aware_non_utc_normalised(session: Session) -> None:
    from datetime import timezone

    t = datetime(2024, 1, 1, 12, tzinfo=timezone(timedelta(hours=2)))
    seq = Sequence(name="s", path="p", created_at=t)
    session.add(seq)
    session.commit()
    session.expunge_all()
    got = session.get(Sequence, seq.id)
    assert got is not None and got.created_at == t and got.created_at.tzinfo == UTC
