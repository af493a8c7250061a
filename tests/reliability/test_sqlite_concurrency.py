"""SQLite (WAL) under concurrent api and worker writes: 50 HTTP clients against a uvicorn api create,
list and poll jobs while, in another process (this one), a worker-like thread takes the jobs off the
SQLite queue file, claims them and writes progress every few milliseconds.

Zero "database is locked", zero 5xx, zero transport errors, and every accepted job is stored and run.
"""
from __future__ import annotations

import random
import threading
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from storage.db import init_db, make_engine, make_session_factory
from storage.models import JobStatus
from storage.queue import make_huey
from storage.repositories import jobs
from storage.settings import Settings
from tests.backend.api.data import write_sequence
from tests.reliability.procs import ApiProc, clean_env, upload

pytestmark = pytest.mark.slow

CLIENTS = 50
DURATION_S = 8.0


@pytest.fixture
def api(settings: Settings, tmp_path: Path) -> Iterator[ApiProc]:
    init_db(settings)
    proc = ApiProc(clean_env(VTD_DATA_DIR=str(settings.data_dir)), tmp_path / "api.log")
    try:
        proc.wait_ready()
        yield proc
    finally:
        proc.close()


class WorkerLike(threading.Thread):
    """Dequeue, claim, report progress in a tight loop (a worker at 100x its write rate), finish."""

    def __init__(self, settings: Settings, stop: threading.Event) -> None:
        super().__init__(name="worker-like", daemon=True)
        from storage.queue import register_run_job

        self.huey = make_huey(settings)
        register_run_job(self.huey)  # so dequeued messages deserialise to the task
        self.engine = make_engine(settings)
        self.sessions = make_session_factory(self.engine)
        self.stop, self.writes = stop, 0
        self.errors: list[str] = []  # repr of what stopped the loop
        self.done: set[str] = set()  # job ids finished

    def run(self) -> None:
        try:
            with self.sessions() as session:
                while not (self.stop.is_set() and self.huey.pending_count() == 0):
                    message = self.huey.dequeue()
                    if message is None:
                        time.sleep(0.01)
                        continue
                    (job_id,) = message.args
                    if not jobs.claim(session, job_id, "worker-like"):
                        continue
                    for i in range(5):
                        jobs.update_progress(session, job_id, frames_done=i, frames_total=5, stage="tracking")
                        self.writes += 1
                        time.sleep(0.005)
                    jobs.finish(session, job_id, JobStatus.SUCCEEDED)
                    self.done.add(job_id)
        except Exception as exc:  # reported by the test
            self.errors.append(repr(exc))
        finally:
            self.engine.dispose()


def _client_loop(url: str, seq_id: str, deadline: float, results: list, created: list) -> None:
    rng = random.Random()
    with httpx.Client(base_url=url, timeout=60) as client:
        mine: list[str] = []
        while time.monotonic() < deadline:
            calls = [("POST /jobs", lambda: client.post("/jobs", json={"sequence_id": seq_id, "preset": "orb-only"})),
                     ("GET /jobs", lambda: client.get("/jobs", params={"limit": 20})),
                     ("GET /jobs?status", lambda: client.get("/jobs", params={"status": "running"}))]
            if mine:
                calls.append(("GET /jobs/{id}", lambda: client.get(f"/jobs/{rng.choice(mine)}")))
            for name, call in calls:
                try:
                    r = call()
                except httpx.HTTPError as exc:
                    results.append((name, None, repr(exc)))
                    continue
                results.append((name, r.status_code, r.text if r.status_code >= 400 else ""))
                if name == "POST /jobs" and r.status_code == 201:
                    mine.append(r.json()["id"])
        created.extend(mine)


def test_fifty_clients_and_a_worker_writing_at_once(settings: Settings, api: ApiProc, tmp_path: Path):
    with httpx.Client(base_url=api.url.rsplit("/api/v1", 1)[0], timeout=60) as client:
        seq = upload(client, write_sequence(tmp_path / "seq", n=3), tmp_path / "seq.tgz")

    stop = threading.Event()
    worker = WorkerLike(settings, stop)
    worker.start()
    results: list = []
    created: list[str] = []
    deadline = time.monotonic() + DURATION_S
    clients = [threading.Thread(target=_client_loop, args=(api.url, seq["id"], deadline, results, created))
               for _ in range(CLIENTS)]
    for t in clients:
        t.start()
    for t in clients:
        t.join(120)
    stop.set()
    worker.join(120)

    by_status = Counter((name, code) for name, code, _ in results)
    bad = [(n, c, body[:200]) for n, c, body in results if c is None or c >= 400]
    assert not bad, (bad[:10], by_status)
    assert not worker.errors, worker.errors
    log = api.output()
    assert "database is locked" not in log and "Traceback" not in log, log[-3000:]
    assert len(created) >= CLIENTS and worker.writes >= len(created)  # everyone got work done
    engine = make_engine(settings)
    try:
        with make_session_factory(engine)() as session:
            assert jobs.count(session) == len(created)  # no accepted write lost
            assert jobs.count(session, status=JobStatus.SUCCEEDED) == len(created)  # all dequeued and run
    finally:
        engine.dispose()
    assert worker.done == set(created)
