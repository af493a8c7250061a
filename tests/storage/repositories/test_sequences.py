from collections.abc import Callable

import pytest
from sqlalchemy.orm import Session

from storage.errors import InvalidInput, NotFound
from storage.models import Sequence
from storage.repositories import jobs, sequences


def test_create_and_get(session: Session) -> None:
    seq = sequences.create(
        session,
        name="fr3_walking",
        path="sequences/x",
        frames=10,
        duration_s=1.5,
        has_groundtruth=True,
        camera={"fx": 1.0},
        size_bytes=123,
        meta={"source": "upload"},
    )
    got = sequences.get(session, seq.id)
    assert (got.name, got.frames, got.duration_s, got.has_groundtruth) == ("fr3_walking", 10, 1.5, True)
    assert (got.camera, got.size_bytes, got.meta) == ({"fx": 1.0}, 123, {"source": "upload"})


def test_create_with_chosen_id(session: Session) -> None:
    assert sequences.create(session, name="a", path="p", id="abc123").id == "abc123"


def test_get_missing(session: Session) -> None:
    with pytest.raises(NotFound) as ei:
        sequences.get(session, "nope")
    assert ei.value.detail == {"id": "nope"}


def test_list_pages_newest_first(session: Session, make_sequence: Callable[..., Sequence]) -> None:
    made = [make_sequence(f"s{i}") for i in range(5)]
    assert sequences.count(session) == 5
    first = sequences.list_sequences(session, limit=2)
    rest = sequences.list_sequences(session, limit=10, offset=2)
    assert [s.id for s in first + rest] == [s.id for s in reversed(made)]


@pytest.mark.parametrize(("limit", "offset"), [(0, 0), (1001, 0), (10, -1)])
def test_list_rejects_bad_paging(session: Session, limit: int, offset: int) -> None:
    with pytest.raises(InvalidInput):
        sequences.list_sequences(session, limit=limit, offset=offset)


def test_delete_cascades_to_jobs(session: Session, make_sequence: Callable[..., Sequence]) -> None:
    seq, other = make_sequence("a"), make_sequence("b")
    j1 = jobs.create(session, sequence_id=seq.id, preset="full")
    j2 = jobs.create(session, sequence_id=seq.id, preset="orb-only")
    keep = jobs.create(session, sequence_id=other.id, preset="full")
    assert sorted(sequences.delete(session, seq.id)) == sorted([j1.id, j2.id])
    with pytest.raises(NotFound):
        sequences.get(session, seq.id)
    with pytest.raises(NotFound):
        jobs.get(session, j1.id)
    assert jobs.get(session, keep.id).id == keep.id
    with pytest.raises(NotFound):
        sequences.delete(session, seq.id)


def test_latest_jobs_are_each_sequences_newest(session: Session, make_sequence: Callable[..., Sequence]) -> None:
    a, b, idle = make_sequence("a"), make_sequence("b"), make_sequence("idle")
    jobs.create(session, sequence_id=a.id, preset="full")
    newest_a = jobs.create(session, sequence_id=a.id, preset="orb-only")
    only_b = jobs.create(session, sequence_id=b.id, preset="full")
    latest = sequences.latest_jobs(session, [a.id, b.id, idle.id])
    assert {k: v.id for k, v in latest.items()} == {a.id: newest_a.id, b.id: only_b.id}
    assert sequences.latest_jobs(session, []) == {}


def test_find_by_content_returns_the_first_upload(session: Session) -> None:
    first = sequences.create(session, name="first", path="p1", content_sha256="ab" * 32)
    sequences.create(session, name="again", path="p2", content_sha256="ab" * 32)
    sequences.create(session, name="registered", path="p3")
    found = sequences.find_by_content(session, "ab" * 32)
    assert found is not None and found.id == first.id
    assert sequences.find_by_content(session, "cd" * 32) is None
