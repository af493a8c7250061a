"""Issue 60.7, the HTTP contract at its edges: HEAD on every GET route, range errors in the error shape,
and a total-time cap on uploads (a body that trickles forever, just fast enough for the idle timeout)."""
from __future__ import annotations

import http.client
import socket
import time

import pytest

from backend.app import create_app
from backend.http_limits import MAX_HEADER_BYTES, LimitedH11Protocol
from storage.settings import get_settings
from tests.backend.api.conftest import RecordingQueue, leftovers, upload
from tests.backend.api.live import serve
from tests.backend.api.test_jobs import complete, new_job


@pytest.fixture
def job_id(client, db, settings, seq_tgz) -> str:
    seq = upload(client, seq_tgz).json()["id"]
    job = new_job(client, seq)["id"]
    complete(db, settings, job)
    return job


@pytest.fixture
def db(settings):
    from storage.db import make_engine, make_session_factory

    engine = make_engine(settings)
    yield make_session_factory(engine)
    engine.dispose()


def _plain_get_paths(client, job_id: str) -> list[str]:
    """Every GET of the api's OpenAPI document, path parameters filled with this test's ids."""
    spec = client.get("/openapi.json").json()
    seq_id = client.get(f"/api/v1/jobs/{job_id}").json()["sequence_id"]
    fill = {"{job_id}": job_id, "{sequence_id}": seq_id, "{name}": "map.ply", "{batch_id}": "nope"}
    paths = []
    for path, ops in spec["paths"].items():
        if "get" in ops:
            for key, value in fill.items():
                path = path.replace(key, value)
            paths.append(path)
    return paths


def test_every_get_route_answers_head(client, job_id) -> None:
    """HEAD was a 405 everywhere: FastAPI's routes do not add it as Starlette's do."""
    paths = _plain_get_paths(client, job_id) + ["/", f"/jobs/{job_id}", "/openapi.json"]
    assert len(paths) > 15
    for path in paths:
        if path.endswith("/events") or path.endswith("/viewer"):
            continue  # an endless stream, the hub: covered on a real server below / in the viewer tests
        got, head = client.get(path), client.head(path)
        assert head.status_code == got.status_code != 405, (path, head.status_code, got.status_code)
        assert head.content == b"", path
        assert head.headers["content-type"] == got.headers["content-type"], path


def test_head_of_an_artifact_has_its_size_and_ranges(client, job_id) -> None:
    base = f"/api/v1/jobs/{job_id}/artifacts/map.ply"
    full = client.get(base).content
    head = client.head(base)
    assert head.status_code == 200 and head.content == b""
    assert int(head.headers["content-length"]) == len(full) and head.headers["accept-ranges"] == "bytes"
    part = client.head(base, headers={"Range": "bytes=4-19"})
    assert part.status_code == 206 and part.headers["content-range"] == f"bytes 4-19/{len(full)}"
    assert client.head(f"/api/v1/jobs/{job_id}/artifacts/nope.txt").status_code == 404
    assert client.head("/api/v1/jobs/nope").status_code == 404


@pytest.mark.parametrize("spec", ["bytes=5-2", "bytes=999999-", "bytes=-0", "items=0-1", "bytes=abc"])
def test_ranges_that_cannot_be_served_are_416_in_the_error_shape(client, job_id, spec: str) -> None:
    """Starlette answered these in text/plain (and 400 for some, undocumented on the route)."""
    base = f"/api/v1/jobs/{job_id}/artifacts/map.ply"
    size = len(client.get(base).content)
    r = client.get(base, headers={"Range": spec})
    assert r.status_code == 416, (spec, r.status_code, r.text)
    assert r.headers["content-type"] == "application/json" and r.headers["content-range"] == f"bytes */{size}"
    error = r.json()["error"]
    assert error["code"] == "range_not_satisfiable" and "cannot be served" in error["message"]
    assert set(error) >= {"code", "message", "detail"}


def test_a_range_on_a_changed_file_serves_the_whole_file(client, job_id) -> None:
    """If-Range that no longer matches: the range is ignored (whole file), even a range that is bad."""
    base = f"/api/v1/jobs/{job_id}/artifacts/map.ply"
    r = client.get(base, headers={"Range": "bytes=5-2", "If-Range": '"an-old-etag"'})
    assert r.status_code == 200 and r.content == client.get(base).content


def test_head_on_a_real_server_sends_headers_only(settings, job_id) -> None:
    """Through uvicorn: the file is not sent, an event stream is not held open."""
    app = create_app(settings, enqueue=RecordingQueue())
    with serve(app) as base:
        host, port = base.removeprefix("http://").split(":")
        for path in (f"/api/v1/jobs/{job_id}/artifacts/map.ply", f"/api/v1/jobs/{job_id}/events",
                     "/api/v1/health"):
            conn = http.client.HTTPConnection(host, int(port), timeout=5)
            t0 = time.monotonic()
            conn.request("HEAD", path)
            r = conn.getresponse()
            assert r.status == 200 and r.read() == b"", path
            assert time.monotonic() - t0 < 3, path
            conn.close()


def test_an_upload_that_trickles_past_the_cap_is_408_and_leaves_nothing(tmp_path, seq_tgz) -> None:
    """Each chunk comes well within the idle timeout; the whole body never comes within the cap."""
    settings = get_settings(data_dir=tmp_path / "data", upload_max_seconds=1.0)
    boundary = "trickle"
    head = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"camera\"\r\n\r\ntum1\r\n"
            f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"s.tgz\"\r\n\r\n").encode()
    app = create_app(settings, enqueue=RecordingQueue())
    with serve(app, http=LimitedH11Protocol, h11_max_incomplete_event_size=MAX_HEADER_BYTES) as base:
        port = int(base.rsplit(":", 1)[1])
        with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
            s.sendall(b"POST /api/v1/sequences HTTP/1.1\r\nHost: t\r\nTransfer-Encoding: chunked\r\n"
                      + f"Content-Type: multipart/form-data; boundary={boundary}\r\n\r\n".encode())
            body = head + seq_tgz
            t0, out = time.monotonic(), b""
            s.settimeout(0.2)
            for i in range(0, len(body), 64):
                piece = body[i:i + 64]
                try:
                    s.sendall(f"{len(piece):x}\r\n".encode() + piece + b"\r\n")
                    out += s.recv(65536)
                except TimeoutError:
                    continue
                except (BrokenPipeError, ConnectionResetError):
                    break
                if out or time.monotonic() - t0 > 8:
                    break
            elapsed = time.monotonic() - t0
            s.settimeout(5)
            while out and not out.endswith(b"}}"):  # the rest of the JSON body
                more = s.recv(65536)
                if not more:
                    break
                out += more
        assert out.startswith(b"HTTP/1.1 408"), out[:300]
        assert b'"code":"request_timeout"' in out and b"within 1 s" in out
        assert 1.0 <= elapsed < 5
        assert leftovers(settings) == []
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
        conn.request("GET", "/api/v1/sequences")
        assert b'"items":[]' in conn.getresponse().read()
        conn.close()
