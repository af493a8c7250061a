"""The scaled-out topology as processes: the api (in process) + two `vtdslam worker` processes on
Redis (queue) and PostgreSQL (database), sharing one data dir, run a batch of 10 jobs.

Each job runs exactly once (one claim, one queue delivery, attempts 1), both workers do some of them,
and every job has its results. Skipped with a reason when PostgreSQL or Redis is not reachable.
"""
from __future__ import annotations

import re
from collections import Counter
from collections.abc import Iterator
from functools import partial
from pathlib import Path

import pytest

from storage.settings import Settings, get_settings
from tests.backend.api.data import write_sequence
from tests.backends import scaled_urls
from tests.reliability.conftest import api_client
from tests.reliability.procs import Procs, clean_env, final_job, submit, upload, wait_for

JOBS = 10
FRAMES = 60

pytestmark = [pytest.mark.slow, pytest.mark.postgres, pytest.mark.redis]


@pytest.fixture
def scaled(tmp_path: Path) -> Iterator[Settings]:
    """Settings on a fresh PostgreSQL schema and an empty Redis database, both removed afterwards."""
    with scaled_urls("vtd_scale_") as (database_url, queue_url):
        yield get_settings(data_dir=tmp_path / "data", database_url=database_url, queue_url=queue_url)


def test_two_workers_on_redis_and_postgres_run_a_batch_once_each(scaled: Settings, procs: Procs, tmp_path):
    assert scaled.database_url and scaled.queue_url  # the fixture sets both
    env = clean_env(VTD_DATA_DIR=str(scaled.data_dir), VTD_DATABASE_URL=scaled.database_url,
                    VTD_QUEUE_URL=scaled.queue_url)
    with api_client(scaled) as client:
        seq = upload(client, write_sequence(tmp_path / "seq", n=FRAMES), tmp_path / "seq.tgz")
        # No --name: two workers on one host must still get distinct names (or they would reap each other).
        workers = [procs.worker(env, tag="scale") for _ in range(2)]
        names = [procs.wait_ready(w) for w in workers]
        assert len(set(names)) == 2, names

        ids = [submit(client, seq["id"]) for _ in range(JOBS)]
        done = {j: wait_for(f"job {j}", partial(final_job, client, j), timeout=180, context=procs.tails)
                for j in ids}
        for w in workers:
            assert procs.stop(w) == 0, procs.tails()

        assert {d["status"] for d in done.values()} == {"succeeded"}, [d["error"] for d in done.values()]
        assert {d["attempts"] for d in done.values()} == {1}
        per_worker = Counter(d["worker"] for d in done.values())
        assert set(per_worker) == set(names) and min(per_worker.values()) >= 1, per_worker

        logs = "".join(procs.log_of(w) for w in workers)
        starts = Counter(re.findall(r"job ([0-9a-f]{32}): orb-only on sequence", logs))
        assert starts == Counter({j: 1 for j in ids}), starts  # one claim (one pipeline run) per job
        assert logs.count("Executing storage.queue.run_job") == JOBS  # one queue delivery per job
        for j in ids:
            names_ = {a["name"] for a in client.get(f"/api/v1/jobs/{j}/artifacts").json()}
            assert {"trajectory.txt", "map.ply", "metrics.json", "log.txt"} <= names_, (j, names_)
            assert done[j]["metrics"]["tracked"] == FRAMES and done[j]["frames_done"] == FRAMES
    # the embedded default's files were never created: everything went to PostgreSQL and Redis
    assert not (scaled.data_dir / "vtdslam.db").exists() and not (scaled.data_dir / "queue.db").exists()
    print(f"\njobs per worker: {dict(per_worker)}; attempts per job: "
          f"{sorted(Counter(d['attempts'] for d in done.values()).items())}")
