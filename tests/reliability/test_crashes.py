"""Crashes with real processes: a worker `kill -9`ed mid-job, restarts with jobs in the queue, a full disk.

The api runs in this process (TestClient) on the same data dir as the worker subprocesses (SQLite
database + SQLite queue file, the embedded default), so it keeps answering while workers die.
"""
from __future__ import annotations

import errno
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from storage.models import JobStatus
from storage.repositories import jobs, metrics, sequences
from storage.settings import Settings
from tests.backend.api.data import write_sequence
from tests.reliability.conftest import api_client
from tests.reliability.procs import FINAL, Procs, clean_env, healthy, job, submit, upload, wait_for

pytestmark = pytest.mark.slow

LONG_FRAMES = 300  # ~5-10 s of orb-only at 160x120: long enough to be killed mid-run
SHORT_FRAMES = 20


def _sequences(client, tmp_path: Path) -> tuple[str, str]:
    long = upload(client, write_sequence(tmp_path / "long", n=LONG_FRAMES), tmp_path / "long.tgz")
    short = upload(client, write_sequence(tmp_path / "short", n=SHORT_FRAMES), tmp_path / "short.tgz")
    return long["id"], short["id"]


def _mid_run(client, job_id: str, procs: Procs) -> dict:
    return wait_for("the long job to be mid-run", lambda: (j := job(client, job_id))["status"] == "running"
                    and 0 < j["frames_done"] < LONG_FRAMES and j, timeout=90, context=procs.tails)


def _plant_partial_save(settings: Settings, job_id: str) -> Path:
    """What a worker killed while copying results leaves: some artifacts and a temp file."""
    folder = settings.data_dir / "artifacts" / job_id
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "trajectory.txt").write_text("100.0 0 0 0 0 0 0 1\n")
    (folder / ".tmp-abc123").write_bytes(b"ply\nformat binary")
    return folder


def _health(env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "worker.health"], env=env, capture_output=True, text=True,
                          timeout=60)


def _env(settings: Settings, **extra: str) -> dict[str, str]:
    return clean_env(VTD_DATA_DIR=str(settings.data_dir), **extra)


def test_worker_killed_mid_job_is_reaped_on_restart_and_the_queue_goes_on(settings, procs, tmp_path):
    """Orphan path, default mode: the restarted worker (same name) fails the job with a reason and
    removes its partial files; jobs queued behind it still run; the api answers throughout."""
    env = _env(settings, VTD_HEARTBEAT_TIMEOUT_S="600")  # only the restart may reap here
    with api_client(settings) as client:
        long_seq, short_seq = _sequences(client, tmp_path)
        first = procs.worker(env)
        name = procs.wait_ready(first)
        victim = submit(client, long_seq)
        behind = [submit(client, short_seq) for _ in range(2)]
        running = _mid_run(client, victim, procs)
        assert running["worker"] == name
        staging = list((settings.data_dir / "staging").glob(f"job-{victim}-*"))
        assert staging, "the running job has a scratch folder"
        partial = _plant_partial_save(settings, victim)

        procs.kill9(first)
        assert healthy(client)
        assert job(client, victim)["status"] == "running"  # nobody knows yet
        assert all(job(client, j)["status"] == "queued" for j in behind)

        second = procs.worker(env)
        assert procs.wait_ready(second) == name  # the dead worker's name is free again
        failed = wait_for("the orphan to be failed", lambda: (j := job(client, victim))["status"] in FINAL and j,
                          context=procs.tails)
        assert failed["status"] == "failed", failed
        assert "stopped before the job finished" in failed["error"] and name in failed["error"]
        assert not partial.exists() and not any(p.exists() for p in staging)
        assert client.get(f"/api/v1/jobs/{victim}/artifacts").json() == []
        for j in behind:
            done = wait_for(f"job {j}", lambda j=j: (x := job(client, j))["status"] in FINAL and x,
                            context=procs.tails)
            assert done["status"] == "succeeded", (done, procs.tails())
            names = {a["name"] for a in client.get(f"/api/v1/jobs/{j}/artifacts").json()}
            assert {"trajectory.txt", "map.ply", "metrics.json"} <= names
        assert healthy(client)
        # the failed one is retryable and then runs to the end
        assert client.post(f"/api/v1/jobs/{victim}/retry").status_code == 200
        done = wait_for("the retried job", lambda: (x := job(client, victim))["status"] in FINAL and x,
                        timeout=120, context=procs.tails)
        assert done["status"] == "succeeded" and (done["attempts"], done["requeues"]) == (2, 0), done
        assert procs.stop(second) == 0


def test_stale_job_is_requeued_once_then_failed(settings, procs, tmp_path):
    """Stale-heartbeat path with `requeue_orphans=1`: workers of other names reap the dead one's job
    after `heartbeat_timeout_s`; the first death requeues it (attempt 2, run by another worker), the
    second fails it as a poison job. Jobs queued behind it still complete."""
    env = _env(settings, VTD_HEARTBEAT_TIMEOUT_S="2", VTD_REQUEUE_ORPHANS="1")
    with api_client(settings) as client:
        long_seq, short_seq = _sequences(client, tmp_path)
        first = procs.worker(env, "--name", "crash-a")
        procs.wait_ready(first)
        victim = submit(client, long_seq)
        behind = submit(client, short_seq)
        _mid_run(client, victim, procs)
        procs.kill9(first)

        second = procs.worker(env, "--name", "crash-b")
        procs.wait_ready(second)
        again = wait_for("the requeued job to run on crash-b",
                         lambda: (j := job(client, victim))["worker"] == "crash-b" and j["frames_done"] > 0 and j,
                         timeout=90, context=procs.tails)
        assert (again["attempts"], again["requeues"], again["status"]) == (2, 1, "running"), again
        assert healthy(client)
        procs.kill9(second)

        third = procs.worker(env, "--name", "crash-c")
        procs.wait_ready(third)
        failed = wait_for("the job to fail after its second death",
                          lambda: (j := job(client, victim))["status"] in FINAL and j, context=procs.tails)
        # the second death makes it a poison job: failed with that reason, never handed on again
        assert failed["status"] == "failed" and "poison job" in failed["error"], failed
        assert (failed["attempts"], failed["requeues"]) == (2, 1)  # requeued once, not twice
        assert not (settings.data_dir / "artifacts" / victim).exists()
        assert not list((settings.data_dir / "staging").glob(f"job-{victim}-*"))
        done = wait_for("the job behind it", lambda: (x := job(client, behind))["status"] in FINAL and x,
                        context=procs.tails)
        assert done["status"] == "succeeded", (done, procs.tails())
        assert procs.stop(third) == 0


def test_jobs_queued_while_no_worker_runs_are_all_processed_across_restarts(settings, procs, tmp_path):
    """Nothing is lost: jobs queued with no worker, then with the worker stopped (SIGTERM) or killed
    (`kill -9`, idle) between jobs, and with the api restarted, all run once a worker is back."""
    env = _env(settings)
    with api_client(settings) as client:
        _, short_seq = _sequences(client, tmp_path)
        early = [submit(client, short_seq) for _ in range(3)]
    with api_client(settings) as client:  # a restarted api sees the same jobs
        assert all(job(client, j)["status"] == "queued" for j in early)
        worker = procs.worker(env)
        procs.wait_ready(worker)
        for j in early:
            wait_for(f"job {j}", lambda j=j: job(client, j)["status"] == "succeeded", context=procs.tails)
        assert procs.stop(worker) == 0
        between = [submit(client, short_seq) for _ in range(2)]
        worker = procs.worker(env)
        procs.wait_ready(worker)
        for j in between:
            wait_for(f"job {j}", lambda j=j: job(client, j)["status"] == "succeeded", context=procs.tails)
        assert _health(env).returncode == 0, _health(env).stderr  # the container healthcheck
        procs.kill9(worker)  # idle: nothing running to lose
        dead = _health(env)
        assert dead.returncode == 1 and "not running" in dead.stderr, dead
        late = [submit(client, short_seq) for _ in range(2)]
        worker = procs.worker(env)
        procs.wait_ready(worker)
        for j in late:
            wait_for(f"job {j}", lambda j=j: job(client, j)["status"] == "succeeded", context=procs.tails)
        every = client.get("/api/v1/jobs", params={"limit": 100}).json()
        assert every["total"] == 7 and {j["status"] for j in every["items"]} == {"succeeded"}
        assert {j["attempts"] for j in every["items"]} == {1}
        assert procs.stop(worker) == 0


def test_disk_full_while_saving_fails_cleanly(settings, monkeypatch):
    """ENOSPC half-way through copying the results: a failed job saying so, no artifact of the run
    (nor a temp file), no metrics; once there is space again a retry succeeds."""
    import storage.artifacts as artifacts
    from worker.consumer import build_context
    from worker.tasks import execute_job

    ctx = build_context(settings, name="w-disk")
    write_sequence(ctx.store.root / "sequences/s", n=SHORT_FRAMES)
    with ctx.session_factory() as s:
        seq = sequences.create(s, name="s", path="sequences/s", frames=SHORT_FRAMES, camera={"preset": "tum1"})
        job_id = jobs.create(s, sequence_id=seq.id, preset="orb-only").id

    real_copy = shutil.copyfileobj
    copies = []

    def filling_up(src, dst, length=0):
        copies.append(dst)
        if len(copies) == 3:  # two artifacts are in place already, the third is half written
            dst.write(src.read(16))
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_copy(src, dst, length)

    monkeypatch.setattr(artifacts.shutil, "copyfileobj", filling_up)
    assert execute_job(ctx, job_id) == JobStatus.FAILED
    with ctx.session_factory() as s:
        failed = jobs.get(s, job_id)
        assert "disk full" in failed.error and "retry" in failed.error
        assert metrics.get_frame_stats(s, job_id) == []
    assert len(copies) == 3
    folder = ctx.store.job_dir(job_id)
    left = sorted(p.name for p in folder.iterdir()) if folder.exists() else []
    assert left in ([], ["log.txt"]), left  # the log says why; nothing of the half-saved run
    assert not list((settings.data_dir / "staging").iterdir())

    monkeypatch.setattr(artifacts.shutil, "copyfileobj", real_copy)
    with ctx.session_factory() as s:
        jobs.retry(s, job_id)
    ctx.store.delete_job(job_id)
    assert execute_job(ctx, job_id) == JobStatus.SUCCEEDED
    assert {"trajectory.txt", "map.ply", "metrics.json"} <= {a.name for a in ctx.store.list(job_id)}
