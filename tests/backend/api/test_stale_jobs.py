"""A job whose worker died shows failed from its heartbeat alone: the api's reads reap it with the workers'
own reaper (storage.reaping), so no live worker is needed; a job with a fresh heartbeat is left alone.
On SQLite and PostgreSQL."""
from __future__ import annotations

from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path
from typing import Any, cast

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import update

from backend.app import create_app
from storage.errors import NotFound
from storage.models import Job
from storage.repositories import jobs, metrics, sequences
from storage.settings import Settings, get_settings
from storage.sqltypes import utcnow
from tests.backend.api.conftest import RecordingQueue
from tests.backends import pg_schema_url


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def database_url(request) -> Iterator[str | None]:
    if request.param == "sqlite":
        yield None
    else:
        with pg_schema_url() as url:
            yield url


def _app(tmp_path: Path, url: str | None, queue: RecordingQueue, **settings) -> tuple[TestClient, Settings]:
    s = get_settings(data_dir=tmp_path / "data", database_url=url, heartbeat_timeout_s=60, **settings)
    return TestClient(create_app(s, enqueue=queue)), s


def _running(client: TestClient, worker: str, silent_s: float) -> str:
    """A job claimed by `worker`, whose last heartbeat was `silent_s` ago, with half a result stored."""
    state = cast(Any, client.app).state
    with state.session_factory() as s:
        seq = sequences.create(s, name=worker, path=f"sequences/{worker}", frames=100, camera={"preset": "tum1"})
        job = jobs.create(s, sequence_id=seq.id, preset="orb-only")
        assert jobs.claim(s, job.id, worker)
        jobs.update_progress(s, job.id, progress=0.3, frames_done=30, frames_total=100, stage="tracking")
        metrics.save_run_metrics(s, job.id, {"fps": 1.0})
        s.execute(update(Job).where(Job.id == job.id).values(heartbeat_at=utcnow() - timedelta(seconds=silent_s)))
        s.commit()
    state.store.write_text(job.id, "trajectory.txt", "half\n")
    return job.id


def test_a_dead_workers_job_reads_failed_and_a_live_one_running(tmp_path, database_url):
    queue = RecordingQueue()
    client, settings = _app(tmp_path, database_url, queue)
    with client:
        dead = _running(client, "gone", silent_s=3600)
        alive = _running(client, "busy", silent_s=5)
        got = client.get(f"/api/v1/jobs/{dead}").json()
        assert got["status"] == "failed" and "stopped reporting" in got["error"]
        assert got["eta_s"] is None
        assert not (settings.data_dir / "artifacts" / dead).exists()  # no half of a result
        with client.app.state.session_factory() as s, pytest.raises(NotFound):
            metrics.get_run_metrics(s, dead)
        fresh = client.get(f"/api/v1/jobs/{alive}").json()
        assert fresh["status"] == "running" and fresh["error"] is None and fresh["frames_done"] == 30
        assert (settings.data_dir / "artifacts" / alive / "trajectory.txt").is_file()
        listed = {j["id"]: j["status"] for j in client.get("/api/v1/jobs").json()["items"]}
        assert listed == {dead: "failed", alive: "running"}
        assert queue.ids == []


def test_the_list_and_the_event_stream_reap_too(tmp_path, database_url):
    client, _ = _app(tmp_path, database_url, RecordingQueue())
    with client:
        dead = _running(client, "gone", silent_s=3600)
        assert client.get("/api/v1/jobs?status=running").json()["total"] == 0
        assert client.get("/api/v1/jobs?status=failed").json()["items"][0]["id"] == dead
        other = _running(client, "gone-too", silent_s=3600)
        with client.stream("GET", f"/api/v1/jobs/{other}/events") as r:
            text = r.read().decode()
        assert "event: end" in text and '"status":"failed"' in text


def test_within_the_requeue_budget_the_api_requeues(tmp_path, database_url):
    queue = RecordingQueue()
    client, _ = _app(tmp_path, database_url, queue, requeue_orphans=1)
    with client:
        dead = _running(client, "gone", silent_s=3600)
        got = client.get(f"/api/v1/jobs/{dead}").json()
        assert got["status"] == "queued" and got["attempts"] == 2 and queue.ids == [dead]
