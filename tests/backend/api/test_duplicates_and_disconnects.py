"""An archive uploaded twice is a 409 naming the first sequence (unless forced); an upload the client
abandons half-way leaves neither files nor a row; two uploads of one archive at once: one 201, one 409;
sequences carry their newest job."""
from __future__ import annotations

import contextlib
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import anyio
import pytest
from fastapi.testclient import TestClient
from starlette.types import Message, Scope

from backend.app import create_app
from storage.settings import Settings, get_settings
from tests.backend.api.conftest import leftovers, upload
from tests.backend.api.data import zip_of
from tests.backends import pg_schema_url

BOUNDARY = "vtd-test-boundary"


def test_second_upload_of_the_same_archive_is_409_naming_the_first(client, settings, seq_tgz):
    first = upload(client, seq_tgz, name="first").json()
    assert first["content_sha256"] and len(first["content_sha256"]) == 64
    before = leftovers(settings)
    r = upload(client, seq_tgz, name="again")
    assert r.status_code == 409, r.text
    err = r.json()["error"]
    assert err["code"] == "conflict" and '"first"' in err["message"] and first["id"] in err["message"]
    assert "allow_duplicate" in err["message"]
    assert err["detail"]["existing_id"] == first["id"] and err["detail"]["sha256"] == first["content_sha256"]
    assert leftovers(settings) == before  # the refused copy left nothing
    assert [s["name"] for s in client.get("/api/v1/sequences").json()["items"]] == ["first"]

    forced = upload(client, seq_tgz, name="again", allow_duplicate=True)
    assert forced.status_code == 201, forced.text
    assert forced.json()["content_sha256"] == first["content_sha256"]
    assert client.get("/api/v1/sequences").json()["total"] == 2


def test_a_different_archive_of_the_same_folder_is_not_a_duplicate(client, seq_tgz, seq_folder, tmp_path):
    assert upload(client, seq_tgz).status_code == 201
    other = zip_of(seq_folder, tmp_path / "s.zip").read_bytes()  # same frames, other bytes
    assert upload(client, other, filename="s.zip").status_code == 201


@pytest.mark.parametrize("value", ["maybe", "2"])
def test_allow_duplicate_must_be_a_boolean(client, settings, seq_tgz, value):
    r = client.post("/api/v1/sequences", files={"file": ("s.tgz", seq_tgz, "application/gzip")},
                    data={"camera": "tum1", "allow_duplicate": value})
    assert r.status_code == 422 and "allow_duplicate" in r.json()["error"]["message"]
    assert leftovers(settings) == []


def _multipart_head(filename: str) -> bytes:
    return (f'--{BOUNDARY}\r\nContent-Disposition: form-data; name="camera"\r\n\r\ntum1\r\n'
            f'--{BOUNDARY}\r\nContent-Disposition: form-data; name="file"; filename="{filename}"\r\n'
            "Content-Type: application/octet-stream\r\n\r\n").encode()


def _abandoned_upload(client: TestClient, filename: str, archive: bytes) -> list[Message]:
    """POST half of ``archive`` straight to the ASGI app, then the client's ``http.disconnect``."""
    head = _multipart_head(filename)
    half = archive[: len(archive) // 2]
    total = len(head) + len(archive) + len(BOUNDARY) + 8  # what a complete body would declare
    messages: list[Message] = [
        {"type": "http.request", "body": head, "more_body": True},
        {"type": "http.request", "body": half, "more_body": True},
        {"type": "http.disconnect"},
    ]
    sent: list[Message] = []

    async def receive() -> Message:
        if messages:
            return messages.pop(0)
        await anyio.sleep_forever()
        raise AssertionError("unreachable")

    async def send(message: Message) -> None:
        sent.append(message)

    scope: Scope = {
        "type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "POST", "scheme": "http",
        "path": "/api/v1/sequences", "raw_path": b"/api/v1/sequences", "root_path": "", "query_string": b"",
        "headers": [(b"host", b"testserver"),
                    (b"content-type", f"multipart/form-data; boundary={BOUNDARY}".encode()),
                    (b"content-length", str(total).encode())],
        "client": ("127.0.0.1", 50000), "server": ("testserver", 80), "state": {},
    }
    assert client.portal is not None
    client.portal.call(client.app, scope, receive, send)
    return sent


@pytest.mark.parametrize("kind", ["tgz", "zip"])  # unpacked while it streams / written, then unpacked
def test_an_upload_abandoned_half_way_leaves_nothing(settings: Settings, seq_tgz, seq_folder, tmp_path: Path,
                                                     kind: str):
    archive = seq_tgz if kind == "tgz" else zip_of(seq_folder, tmp_path / "s.zip").read_bytes()
    with TestClient(create_app(settings, enqueue=lambda job_id: None)) as client:
        sent = _abandoned_upload(client, f"seq.{kind}", archive)
        start = next(m for m in sent if m["type"] == "http.response.start")
        assert start["status"] == 422  # said to nobody, but not a 201 and not a 500
        assert leftovers(settings) == []
        assert not list((settings.data_dir / "staging").iterdir())
        assert client.get("/api/v1/sequences").json()["total"] == 0
        # the same archive sent in full afterwards is not taken for a duplicate of the abandoned one
        assert upload(client, archive, filename=f"seq.{kind}").status_code == 201


def test_sequences_carry_their_newest_job(client, seq_tgz):
    seq = upload(client, seq_tgz).json()
    assert seq["latest_job"] is None
    client.post("/api/v1/jobs", json={"sequence_id": seq["id"], "preset": "orb-only"})
    newest = client.post("/api/v1/jobs", json={"sequence_id": seq["id"], "preset": "geometry-only"}).json()
    listed = client.get("/api/v1/sequences").json()["items"][0]["latest_job"]
    assert listed["id"] == newest["id"] and listed["preset"] == "geometry-only" and listed["status"] == "queued"
    assert client.get(f"/api/v1/sequences/{seq['id']}").json()["latest_job"]["id"] == newest["id"]


@pytest.mark.parametrize("database", ["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def test_two_uploads_of_one_archive_racing_past_the_check_one_is_409(
    settings: Settings, seq_tgz: bytes, monkeypatch: pytest.MonkeyPatch, database: str
) -> None:
    """Both requests pass the look-up before either records its row: the database decides."""
    import backend.api.sequences as routes

    real = routes.ingest_staged
    barrier = threading.Barrier(2)

    def ingest_after_both_checked(*args: Any, **kwargs: Any) -> Any:
        barrier.wait(30)
        return real(*args, **kwargs)

    monkeypatch.setattr(routes, "ingest_staged", ingest_after_both_checked)
    with contextlib.ExitStack() as stack:
        if database == "postgresql":
            url = stack.enter_context(pg_schema_url())
            settings = get_settings(data_dir=settings.data_dir, database_url=url)
        client = stack.enter_context(TestClient(create_app(settings, enqueue=lambda job_id: None)))
        with ThreadPoolExecutor(2) as pool:
            answers = list(pool.map(lambda n: upload(client, seq_tgz, name=n), ["a", "b"]))
        assert sorted(r.status_code for r in answers) == [201, 409], [r.text for r in answers]
        won = next(r for r in answers if r.status_code == 201).json()
        err = next(r for r in answers if r.status_code == 409).json()["error"]
        assert err["code"] == "conflict" and won["id"] in err["message"] and "allow_duplicate" in err["message"]
        assert err["detail"] == {"existing_id": won["id"], "existing_name": won["name"],
                                 "sha256": won["content_sha256"]}
        assert [s["id"] for s in client.get("/api/v1/sequences").json()["items"]] == [won["id"]]
        assert {Path(p).parts[:2] for p in leftovers(settings)} == {("sequences", won["id"])}
        assert not list((settings.data_dir / "staging").iterdir())
