"""Two uploads of one archive racing into the database: exactly one lands, the other is the same 409
the api's look-up gives, and leaves no files behind (SQLite and, when reachable, PostgreSQL)."""
from __future__ import annotations

import shutil
import threading
from pathlib import Path

import pytest
from sqlalchemy.orm import Session, sessionmaker

from storage.artifacts import ArtifactStore, make_artifact_store
from storage.errors import Conflict
from storage.ingest import ingest_staged
from storage.models import Sequence
from storage.repositories import sequences
from storage.settings import Settings
from tests.backend.api.data import CAMERA, write_sequence

SHA = "ab" * 32


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_sequence(tmp_path_factory.mktemp("seq") / "rgbd_dataset_test", n=4)


def _staged(store: ArtifactStore, folder: Path) -> Path:
    staging = store.new_staging_dir()
    shutil.copytree(folder, staging / "unpacked" / folder.name)
    return staging


def _files(store: ArtifactStore) -> list[Path]:
    return [p for p in store.root.rglob("*") if p.is_file() and not p.name.startswith("vtdslam.db")]


def _race(session_factory: sessionmaker[Session], store: ArtifactStore, settings: Settings, folder: Path,
          *, unique: bool) -> tuple[list[Sequence], list[BaseException]]:
    """Two threads, each with its own session, install and record the same archive at once."""
    staged = [_staged(store, folder) for _ in range(2)]
    barrier = threading.Barrier(2)
    won: list[Sequence] = []
    lost: list[BaseException] = []

    def upload(staging: Path) -> None:
        with session_factory() as session:
            barrier.wait()
            try:
                won.append(ingest_staged(session, store, settings, staging, name=staging.name,
                                         camera=CAMERA, content_sha256=SHA, unique=unique))
            except BaseException as exc:  # judged below
                lost.append(exc)

    threads = [threading.Thread(target=upload, args=(s,)) for s in staged]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    return won, lost


def test_racing_uploads_of_one_archive_one_wins_the_other_is_409_and_leaves_nothing(
    session_factory: sessionmaker[Session], db_settings: Settings, folder: Path
) -> None:
    store = make_artifact_store(db_settings)
    won, lost = _race(session_factory, store, db_settings, folder, unique=True)
    assert len(won) == 1 and len(lost) == 1, lost
    assert isinstance(lost[0], Conflict) and lost[0].http_status == 409
    assert lost[0].detail == {"existing_id": won[0].id, "existing_name": won[0].name, "sha256": SHA}
    assert "allow_duplicate" in lost[0].message
    with session_factory() as session:
        assert [s.id for s in sequences.list_sequences(session)] == [won[0].id]
    # only the winner's files: no second sequence folder, nothing left in staging
    assert {p.relative_to(store.root).parts[:2] for p in _files(store)} == {("sequences", won[0].id)}
    assert not list(store.staging_dir().iterdir())


def test_copies_allowed_as_duplicates_do_not_race(
    session_factory: sessionmaker[Session], db_settings: Settings, folder: Path
) -> None:
    store = make_artifact_store(db_settings)
    won, lost = _race(session_factory, store, db_settings, folder, unique=False)
    assert lost == [] and len(won) == 2
    assert {s.content_sha256 for s in won} == {SHA} and {s.claimed_sha256 for s in won} == {None}
