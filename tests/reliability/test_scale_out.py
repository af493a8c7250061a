"""The scaled-out topology as processes: the api (in process) + two `vtdslam worker` processes on
Redis (queue) and PostgreSQL (database), sharing one data dir, run a batch of 10 jobs.

Each job runs exactly once (one claim, one queue delivery, attempts 1), both workers do some of them,
and every job has its results. Skipped with a reason when PostgreSQL or Redis is not reachable.
"""
from __future__ import annotations

import os
import re
import uuid
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import pytest

from storage.settings import Settings, get_settings
from tests.backend.api.data import write_sequence
from tests.reliability.conftest import api_client
from tests.reliability.procs import FINAL, Procs, clean_env, job, submit, upload, wait_for

PG_URL = os.environ.get("VTD_TEST_POSTGRES_URL", "postgresql://postgres@127.0.0.1:5432/test")
REDIS_BASE = os.environ.get("VTD_TEST_REDIS_BASE", "redis://127.0.0.1:6379")
JOBS = 10
FRAMES = 60

pytestmark = [pytest.mark.slow, pytest.mark.postgres, pytest.mark.redis]


@pytest.fixture
def scaled(tmp_path: Path) -> Iterator[Settings]:
    """Settings on a fresh PostgreSQL schema and an empty Redis database, both removed afterwards."""
    psycopg = pytest.importorskip("psycopg")
    redis = pytest.importorskip("redis")
    try:
        psycopg.connect(PG_URL, connect_timeout=3).close()
    except Exception as exc:
        pytest.skip(f"PostgreSQL not reachable at {PG_URL}: {exc}")
    try:
        redis.Redis.from_url(REDIS_BASE, socket_connect_timeout=3).ping()
    except Exception as exc:
        pytest.skip(f"Redis not reachable at {REDIS_BASE}: {exc}")
    # The queue's name is fixed, so a database nobody uses isolates it (claimed with a marker key).
    db_index = None
    for i in range(1, 15):
        r = redis.Redis.from_url(f"{REDIS_BASE}/{i}")
        if r.dbsize() == 0 and r.set("vtd-test-owner", uuid.uuid4().hex, nx=True):
            db_index = i
            break
    if db_index is None:
        pytest.skip("no empty Redis database among 1..14")
    schema = f"vtd_scale_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(PG_URL, autocommit=True) as conn:
        conn.execute(f'CREATE SCHEMA "{schema}"')
    try:
        yield get_settings(data_dir=tmp_path / "data", database_url=f"{PG_URL}?options=-csearch_path%3D{schema}",
                           queue_url=f"{REDIS_BASE}/{db_index}")
    finally:
        redis.Redis.from_url(f"{REDIS_BASE}/{db_index}").flushdb()
        with psycopg.connect(PG_URL, autocommit=True) as conn:
            conn.execute(f'DROP SCHEMA "{schema}" CASCADE')


def test_two_workers_on_redis_and_postgres_run_a_batch_once_each(scaled: Settings, procs: Procs, tmp_path):
    env = clean_env(VTD_DATA_DIR=str(scaled.data_dir), VTD_DATABASE_URL=scaled.database_url,
                    VTD_QUEUE_URL=scaled.queue_url)
    with api_client(scaled) as client:
        seq = upload(client, write_sequence(tmp_path / "seq", n=FRAMES), tmp_path / "seq.tgz")
        # No --name: two workers on one host must still get distinct names (or they would reap each other).
        workers = [procs.worker(env, tag="scale") for _ in range(2)]
        names = [procs.wait_ready(w) for w in workers]
        assert len(set(names)) == 2, names

        ids = [submit(client, seq["id"]) for _ in range(JOBS)]
        done = {j: wait_for(f"job {j}", lambda j=j: (x := job(client, j))["status"] in FINAL and x,
                            timeout=180, context=procs.tails) for j in ids}
        for w in workers:
            assert procs.stop(w) == 0, procs.tails()

        assert {d["status"] for d in done.values()} == {"succeeded"}, [d["error"] for d in done.values()]
        assert {d["attempts"] for d in done.values()} == {1}
        per_worker = Counter(d["worker"] for d in done.values())
        assert set(per_worker) == set(names) and min(per_worker.values()) >= 1, per_worker

        logs = "".join(procs.log_of(w) for w in workers)
        starts = Counter(re.findall(r"job ([0-9a-f]{32}): orb-only on sequence", logs))
        assert starts == Counter({j: 1 for j in ids}), starts  # one claim (one pipeline run) per job
        assert logs.count("Executing storage.jobqueue.run_job") == JOBS  # one queue delivery per job
        for j in ids:
            names_ = {a["name"] for a in client.get(f"/api/v1/jobs/{j}/artifacts").json()}
            assert {"trajectory.txt", "map.ply", "metrics.json", "log.txt"} <= names_, (j, names_)
            assert done[j]["metrics"]["tracked"] == FRAMES and done[j]["frames_done"] == FRAMES
    # the embedded default's files were never created: everything went to PostgreSQL and Redis
    assert not (scaled.data_dir / "vtdslam.db").exists() and not (scaled.data_dir / "queue.db").exists()
    print(f"\njobs per worker: {dict(per_worker)}; attempts per job: "
          f"{sorted(Counter(d['attempts'] for d in done.values()).items())}")
