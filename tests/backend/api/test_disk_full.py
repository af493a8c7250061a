"""Issue 60.4: a full disk or database is a 507 in the error shape with nothing left behind (no files, no
row, nothing queued), on upload and on job creation; on SQLite and PostgreSQL. Faults injected: the
upload's writer and the unpacker raise OSError(ENOSPC), the database commit SQLite's "database or disk is
full" or PostgreSQL's disk_full (SQLSTATE 53100)."""
from __future__ import annotations

import errno
import sqlite3
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session

from backend.app import create_app
from storage.ingest import archive as archive_module
from storage.ingest import stream as stream_module
from storage.settings import Settings, get_settings
from tests.backend.api.conftest import RecordingQueue, leftovers, upload
from tests.backend.api.data import zip_of
from tests.backends import pg_schema_url


@pytest.fixture(params=["sqlite", "postgresql"])
def env(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[tuple[TestClient, Settings, RecordingQueue]]:
    with ExitStack() as stack:
        url = stack.enter_context(pg_schema_url()) if request.param == "postgresql" else None
        settings = get_settings(data_dir=tmp_path / "data", **({"database_url": url} if url else {}))
        queue = RecordingQueue()
        client = stack.enter_context(TestClient(create_app(settings, enqueue=queue)))
        client.database = request.param
        yield client, settings, queue


def _db_full(database: str) -> OperationalError:
    if database == "postgresql":
        import psycopg.errors

        orig: Exception = psycopg.errors.DiskFull('could not extend file "base/1/2": No space left on device')
    else:
        orig = sqlite3.OperationalError("database or disk is full")
    return OperationalError("INSERT INTO ...", {}, orig)


def _full_disk_error(r, what: str) -> None:  # noqa: ANN001
    assert r.status_code == 507, r.text
    assert r.headers["content-type"] == "application/json"
    error = r.json()["error"]
    assert error["code"] == "insufficient_storage" and "out of storage space" in error["message"], error
    assert what in error["message"] and "detail" in error


def _nothing_stored(client: TestClient, settings: Settings) -> None:
    assert leftovers(settings) == []
    assert client.get("/api/v1/sequences").json()["items"] == []


def test_enospc_while_receiving_a_zip_is_507(env, seq_folder, tmp_path, monkeypatch) -> None:
    client, settings, _ = env

    class FullFile:
        def __init__(self, path, mode) -> None:  # noqa: ANN001
            self.raw = open(path, mode)  # noqa: SIM115

        def write(self, block: bytes) -> int:
            raise OSError(errno.ENOSPC, "No space left on device")

        def close(self) -> None:
            self.raw.close()

    monkeypatch.setattr(stream_module, "open", FullFile, raising=False)
    r = upload(client, zip_of(seq_folder, tmp_path / "s.zip").read_bytes(), filename="s.zip")
    _full_disk_error(r, "receiving the upload")
    _nothing_stored(client, settings)


def test_enospc_while_unpacking_a_tgz_is_507(env, seq_tgz, monkeypatch) -> None:
    client, settings, _ = env

    def full(*_args, **_kwargs) -> None:  # noqa: ANN002, ANN003
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(archive_module, "_write", full)
    _full_disk_error(upload(client, seq_tgz), "unpacking the upload")
    _nothing_stored(client, settings)


def test_a_full_database_on_upload_is_507(env, seq_tgz, monkeypatch) -> None:
    client, settings, _ = env
    with monkeypatch.context() as m:
        m.setattr(Session, "commit", lambda self: (_ for _ in ()).throw(_db_full(client.database)))
        r = upload(client, seq_tgz)
    _full_disk_error(r, "database")
    _nothing_stored(client, settings)
    assert upload(client, seq_tgz).status_code == 201  # space again: the same archive goes in


def test_a_full_database_on_job_creation_is_507(env, seq_tgz, monkeypatch) -> None:
    client, settings, queue = env
    seq_id = upload(client, seq_tgz).json()["id"]
    with monkeypatch.context() as m:
        m.setattr(Session, "commit", lambda self: (_ for _ in ()).throw(_db_full(client.database)))
        r = client.post("/api/v1/jobs", json={"sequence_id": seq_id, "preset": "orb-only"})
    _full_disk_error(r, "database")
    assert client.get("/api/v1/jobs").json()["items"] == [] and queue.ids == []
