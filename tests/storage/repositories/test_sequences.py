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
