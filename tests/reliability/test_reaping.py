"""Reaping in process (fast, both modes × both paths), zombies, heartbeats and unique worker names."""
from __future__ import annotations

import json
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from formats.artifacts import PIPELINE_OUTPUTS
from formats.frame_stats import FrameStats
from storage.errors import ConfigurationError
from storage.models import JobStatus, RunMetrics
from storage.repositories import job_reaping, jobs, metrics, sequences
from storage.settings import Settings, get_settings
from worker.consumer import build_context
from worker.identity import claim_name
from worker.reaping import reap_orphans, reap_stale, start_reaper
from worker.runner import Cancelled, RunOutput
from worker.tasks import WorkerContext, execute_job

METRICS = {"frames": 3, "fps": 10.0, "tracked": 3, "ate": {"rmse": 0.01}}


class Pipeline:
    """A stand-in pipeline: `frames` frames, a hook per frame, an optional silent pause (a long BA)."""

    def __init__(self, frames: int = 3, on_frame=None, silent_s: float = 0.0, before_return=None) -> None:
        self.frames, self.on_frame, self.silent_s = frames, on_frame, silent_s
        self.before_return = before_return

    def __call__(self, sequence_dir, camera, preset, overrides, out_dir, *, progress, should_cancel):
        for i in range(self.frames):
            if should_cancel():
                raise Cancelled(f"cancelled after {i} frames")
            progress(i + 1, self.frames, "tracking")
            if self.on_frame:
                self.on_frame(i)
        time.sleep(self.silent_s)  # work that reports nothing (a global bundle adjustment)
        for name in PIPELINE_OUTPUTS:
            (out_dir / name).write_text(json.dumps(METRICS) if name == "metrics.json" else f"# {name}\n")
        stats = [FrameStats(i, float(i), tracked=True) for i in range(self.frames)]
        if self.before_return:
            self.before_return()
        return RunOutput(metrics=dict(METRICS), config={"name": preset}, frame_stats=stats)


def _ctx(settings: Settings, name: str, **kw) -> WorkerContext:
    ctx = build_context(settings, name=name, pipeline=Pipeline())
    ctx.progress_interval_s = 0.0
    ctx.enqueue = kw.pop("enqueue", None)
    for key, value in kw.items():
        setattr(ctx, key, value)
    return ctx


def _job(ctx: WorkerContext) -> str:
    with ctx.session_factory() as s:
        seq = sequences.create(s, name="s", path="sequences/s", frames=3, camera={"preset": "tum1"})
        return jobs.create(s, sequence_id=seq.id, preset="orb-only").id


def _get(ctx: WorkerContext, job_id: str):
    with ctx.session_factory() as s:
        return jobs.get(s, job_id)


def _dead_worker_job(ctx: WorkerContext, job_id: str, worker: str) -> Path:
    """A job claimed by `worker` which then died while saving: its row says running, files are half there."""
    with ctx.session_factory() as s:
        assert jobs.claim(s, job_id, worker)
        metrics.save_run_metrics(s, job_id, METRICS)
    ctx.store.write_text(job_id, "trajectory.txt", "half\n")
    ctx.store.new_staging_dir(prefix=f"job-{job_id}-")
    return ctx.store.job_dir(job_id)


@pytest.mark.parametrize("path", ["orphan", "stale"])
@pytest.mark.parametrize("requeue", [0, 1])
def test_dead_workers_job_is_failed_or_requeued_with_its_files_removed(tmp_path: Path, path: str, requeue: int) -> None:
    settings = get_settings(data_dir=tmp_path / "data", requeue_orphans=requeue)
    queue: list[str] = []
    ctx = _ctx(settings, "w1", enqueue=queue.append)
    job_id = _job(ctx)
    folder = _dead_worker_job(ctx, job_id, "w1")
    reaped = reap_orphans(ctx) if path == "orphan" else reap_stale(ctx, timeout_s=-1.0)
    assert reaped.all == [job_id]
    got = _get(ctx, job_id)
    assert not folder.exists() and not list((settings.data_dir / "staging").glob(f"job-{job_id}-*"))
    with ctx.session_factory() as s:
        assert metrics.get_frame_stats(s, job_id) == []
        assert s.get(RunMetrics, job_id) is None  # no half metrics row
    if requeue:
        assert (got.status, got.attempts, got.requeues, got.worker, got.error) == (JobStatus.QUEUED, 2, 1, None, None)
        assert got.stage == job_reaping.REQUEUED_STAGE and got.progress == 0.0 and got.started_at is None
        assert queue == [job_id]
        # the next death of the same job fails it: one requeue only
        _dead_worker_job(ctx, job_id, "w1")
        reaped = reap_orphans(ctx) if path == "orphan" else reap_stale(ctx, timeout_s=-1.0)
        assert reaped.failed == [job_id] and queue == [job_id]
        with ctx.session_factory() as s:  # a manual retry gives the budget back
            assert jobs.retry(s, job_id).requeues == 0
    else:
        assert got.status == JobStatus.FAILED and queue == []
        assert ("stopped before" if path == "orphan" else "stopped reporting") in got.error


def test_only_the_own_names_orphans_and_only_stale_jobs_are_reaped(settings: Settings) -> None:
    ctx = _ctx(settings, "w1")
    mine, other = _job(ctx), _job(ctx)
    with ctx.session_factory() as s:
        assert jobs.claim(s, mine, "w1") and jobs.claim(s, other, "w2")
    assert reap_stale(ctx, timeout_s=60).all == []  # both reported just now
    assert reap_orphans(ctx).all == [mine]
    assert _get(ctx, other).status == JobStatus.RUNNING


def test_a_reaped_zombie_stores_nothing_and_does_not_touch_the_new_attempt(settings: Settings) -> None:
    """The reaper requeued the job while its (slow, not dead) worker went on: when that worker gets to
    saving, it must notice and store nothing, and its finish must not end the new attempt."""
    ctx = _ctx(settings, "zombie")
    job_id = _job(ctx)

    def reaped_and_reclaimed() -> None:  # its outputs are written: only saving is left
        with ctx.session_factory() as s:  # the reaper's database step (its file cleanup may come later)
            assert job_reaping.reap_stale(s, older_than_s=-1.0, requeue_limit=1).requeued == [job_id]
            assert jobs.claim(s, job_id, "other")

    ctx.pipeline = Pipeline(before_return=reaped_and_reclaimed)
    execute_job(ctx, job_id)
    got = _get(ctx, job_id)
    assert (got.status, got.worker, got.attempts) == (JobStatus.RUNNING, "other", 2)
    assert ctx.store.list(job_id) == []
    with ctx.session_factory() as s:
        assert metrics.get_frame_stats(s, job_id) == []


def test_a_reaped_zombie_leaves_a_failed_job_failed_and_empty(settings: Settings) -> None:
    ctx = _ctx(settings, "zombie")
    job_id = _job(ctx)

    def reaped() -> None:
        with ctx.session_factory() as s:
            assert job_reaping.reap_stale(s, older_than_s=-1.0).failed == [job_id]

    ctx.pipeline = Pipeline(before_return=reaped)
    execute_job(ctx, job_id)
    got = _get(ctx, job_id)
    assert got.status == JobStatus.FAILED and "stopped reporting" in got.error
    assert ctx.store.list(job_id) == []


def test_a_live_job_in_a_silent_stage_is_not_taken_for_dead(tmp_path: Path) -> None:
    """The pipeline reports nothing for 2.5 heartbeat timeouts (a long final BA) while another worker's
    reaper runs: the job's heartbeat keeps it alive and it succeeds."""
    settings = get_settings(data_dir=tmp_path / "data", heartbeat_timeout_s=1.0)
    ctx = _ctx(settings, "busy", pipeline=Pipeline(silent_s=2.5))
    reaper = _ctx(settings, "reaper")
    start_reaper(reaper, settings.heartbeat_timeout_s)
    try:
        job_id = _job(ctx)
        assert execute_job(ctx, job_id) == JobStatus.SUCCEEDED, _get(ctx, job_id).error
    finally:
        reaper.stopping.set()


def test_worker_names_are_unique_among_live_workers(tmp_path: Path) -> None:
    data = tmp_path / "data"
    first = claim_name(data)
    second = claim_name(data)
    assert first.name != second.name and second.name.startswith(first.name)
    with pytest.raises(ConfigurationError, match="already running"):
        claim_name(data, first.name)
    first.release()  # the process holding it died: a restart gets the name (and its orphans) back
    again = claim_name(data)
    assert again.name == first.name
    explicit = claim_name(data, "gpu-box")
    assert explicit.name == "gpu-box"
    for held in (second, again, explicit):
        held.release()


def test_reaper_thread_stops_with_the_worker(settings: Settings) -> None:
    ctx = _ctx(settings, "w1")
    thread = start_reaper(ctx, 0.2)
    ctx.stopping.set()
    thread.join(5)
    assert not thread.is_alive()


def test_two_reapers_racing_requeue_a_job_once(tmp_path: Path) -> None:
    settings = get_settings(data_dir=tmp_path / "data", requeue_orphans=1)
    queue: list[str] = []
    ctxs = [_ctx(settings, f"r{i}", enqueue=queue.append) for i in range(4)]
    job_id = _job(ctxs[0])
    _dead_worker_job(ctxs[0], job_id, "dead")
    barrier = threading.Barrier(len(ctxs))

    def reap(c: WorkerContext) -> None:
        barrier.wait()
        reap_stale(c, timeout_s=-1.0)

    threads = [threading.Thread(target=reap, args=(c,)) for c in ctxs]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert queue == [job_id] and _get(ctxs[0], job_id).attempts == 2


@pytest.mark.parametrize("path", ["orphan", "stale"])
def test_a_job_whose_worker_died_twice_is_a_poison_job(tmp_path: Path, path: str) -> None:
    """However many requeues the deployment allows, the second death fails the job as a poison job (one
    setting that crashes the pipeline would kill every worker); only an explicit retry queues it again."""
    settings = get_settings(data_dir=tmp_path / "data", requeue_orphans=5)
    queue: list[str] = []
    ctx = _ctx(settings, "w1", enqueue=queue.append)
    job_id = _job(ctx)

    def die() -> Any:
        _dead_worker_job(ctx, job_id, "w1")
        return reap_orphans(ctx) if path == "orphan" else reap_stale(ctx, timeout_s=-1.0)

    assert die().requeued == [job_id]
    reaped = die()
    assert reaped.poisoned == reaped.failed == [job_id] and reaped.requeued == []
    got = _get(ctx, job_id)
    assert got.status == JobStatus.FAILED and got.error.startswith("poison job") and queue == [job_id]
    assert reap_stale(ctx, timeout_s=-1.0).all == [] and queue == [job_id]  # never handed on again
    with ctx.session_factory() as s:
        assert jobs.retry(s, job_id).status == JobStatus.QUEUED  # the explicit request
    assert die().requeued == [job_id]  # a fresh budget after the retry
