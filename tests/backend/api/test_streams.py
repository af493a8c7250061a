"""Event streams hold no database connection while they wait, and each client may hold only so many."""
from __future__ import annotations

import contextlib
import time
from collections.abc import Generator

import httpx
import pytest

from backend.app import create_app
from storage.db import make_engine, make_session_factory
from storage.repositories import jobs
from storage.settings import get_settings
from tests.backend.api.conftest import RecordingQueue
from tests.backend.api.live import serve

STREAMS = 6


@pytest.fixture
def tiny_pool(tmp_path):
    """Two connections and no overflow: a stream holding one would starve the api after two."""
    return get_settings(data_dir=tmp_path / "data", db_pool_size=2, db_max_overflow=0,
                        max_streams_per_client=STREAMS)


def _running_job(base: str, seq_tgz: bytes, settings) -> str:
    with httpx.Client(base_url=base) as c:
        files = {"file": ("seq.tgz", seq_tgz, "application/gzip")}
        seq = c.post("/api/v1/sequences", files=files, data={"camera": "tum1"}).json()
        job = c.post("/api/v1/jobs", json={"sequence_id": seq["id"], "preset": "orb-only"}).json()
    engine = make_engine(settings)
    with make_session_factory(engine)() as s:
        assert jobs.claim(s, job["id"], "test-worker")
    engine.dispose()
    return job["id"]


def _open_stream(stack: contextlib.ExitStack, client: httpx.Client, job_id: str) -> int:
    r = stack.enter_context(client.stream("GET", f"/api/v1/jobs/{job_id}/events?interval=0.1"))
    if r.status_code == 200:
        chunks = r.iter_raw()
        assert isinstance(chunks, Generator)  # httpx's is one; only a generator can be closed before its end
        next(chunks)  # the stream is live (its first event arrived)
        stack.callback(chunks.close)  # a dropped iterator would close the connection at once
    return r.status_code


def test_open_streams_leave_the_pool_to_other_requests(tiny_pool, seq_tgz):
    app = create_app(tiny_pool, enqueue=RecordingQueue())
    with serve(app) as base, contextlib.ExitStack() as stack:
        job_id = _running_job(base, seq_tgz, tiny_pool)
        client = stack.enter_context(httpx.Client(base_url=base, timeout=60))
        streams = [_open_stream(stack, client, job_id) for _ in range(STREAMS)]
        assert streams == [200] * STREAMS
        with httpx.Client(base_url=base, timeout=60) as other:
            answers = [other.get("/api/v1/jobs").status_code for _ in range(5)]
            answers.append(other.get(f"/api/v1/jobs/{job_id}").status_code)
        assert answers == [200] * 6  # with a connection per stream: pool timeout, then 500


def test_streams_per_client_are_capped_and_freed(tiny_pool, seq_tgz):
    app = create_app(tiny_pool, enqueue=RecordingQueue())
    with serve(app) as base:
        job_id = _running_job(base, seq_tgz, tiny_pool)
        with contextlib.ExitStack() as stack:
            client = stack.enter_context(httpx.Client(base_url=base, timeout=60))
            for _ in range(STREAMS):
                _open_stream(stack, client, job_id)
            with httpx.Client(base_url=base, timeout=60) as c:
                refused = c.get(f"/api/v1/jobs/{job_id}/events")
            assert refused.status_code == 429
            assert refused.json()["error"]["code"] == "too_many_streams"
        deadline = time.monotonic() + 30  # the server notices the closed streams at their next poll
        while app.state.streams.open_count("127.0.0.1") and time.monotonic() < deadline:
            time.sleep(0.05)
        assert app.state.streams.open_count("127.0.0.1") == 0
        with httpx.Client(base_url=base, timeout=60) as c, c.stream("GET", f"/api/v1/jobs/{job_id}/events") as r:
            assert r.status_code == 200
