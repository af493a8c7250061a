"""The job task with an injected fake pipeline (and once with the real one): claim once, progress,
cancel, failures, deletion, shutdown, orphans, and the huey round trip api-enqueue -> worker-execute."""
from __future__ import annotations

import json
import threading
from pathlib import Path

import pytest
from huey import SqliteHuey

from formats.artifacts import PIPELINE_OUTPUTS
from formats.frame_stats import FrameStats
from storage.models import JobStatus
from storage.queue import make_enqueue
from storage.repositories import jobs, metrics, sequences
from storage.settings import get_settings
from tests.backend.api.data import write_sequence
from worker.consumer import build_context
from worker.reaping import reap_orphans
from worker.runner import Cancelled, RunOutput
from worker.tasks import WorkerContext, execute_job, register_tasks

METRICS = {"frames": 5, "fps": 12.5, "tracked": 4, "lost": 1, "timings_ms": {"tracking": 3.0},
           "ate": {"rmse": 0.02, "mean": 0.01, "median": 0.01, "std": 0.005, "max": 0.05},
           "rpe": {"trans": {"rmse": 0.01}, "rot": {"rmse": 0.3}}}

pytestmark = pytest.mark.usefixtures("no_vtd_env")  # tests/conftest.py


class FakePipeline:
    """Writes the pipeline's five files after `frames` frames; hooks let a test act mid-run."""

    def __init__(self, frames: int = 5, on_frame=None, error: Exception | None = None) -> None:
        self.frames, self.on_frame, self.error = frames, on_frame, error
        self.calls: list[dict] = []

    def __call__(self, sequence_dir, camera, preset, overrides, out_dir, *, progress, should_cancel):
        self.calls.append({"sequence_dir": sequence_dir, "camera": camera, "preset": preset, "overrides": overrides})
        for i in range(self.frames):
            if should_cancel():
                raise Cancelled(f"cancelled after {i} of {self.frames} frames")
            if self.on_frame:
                self.on_frame(i)
            progress(i + 1, self.frames, "tracking")
        if self.error:
            raise self.error
        for name in PIPELINE_OUTPUTS:
            (out_dir / name).write_text(json.dumps(METRICS) if name == "metrics.json" else f"# {name}\n")
        (out_dir / "trajectory.txt").write_text("".join(f"{100 + i / 30} {i * 0.1} 0 {i * i * 0.01} 0 0 0 1\n"
                                                        for i in range(self.frames)))
        stats = [FrameStats(i, 100 + i / 30, tracked=i != 2) for i in range(self.frames)]
        return RunOutput(metrics=dict(METRICS), config={"name": preset, **overrides}, frame_stats=stats)


@pytest.fixture
def ctx(tmp_path: Path) -> WorkerContext:
    c = build_context(get_settings(data_dir=tmp_path / "data"), name="w1", pipeline=FakePipeline())
    c.progress_interval_s = 0.0
    return c


@pytest.fixture
def job_id(ctx: WorkerContext) -> str:
    with ctx.session_factory() as s:
        seq = sequences.create(s, name="s", path="sequences/s", frames=5, camera={"preset": "tum1"})
        return jobs.create(s, sequence_id=seq.id, preset="orb-only", config={"dense.enabled": False}).id


def _job(ctx: WorkerContext, job_id: str):
    with ctx.session_factory() as s:
        return jobs.get(s, job_id)


def test_success_stores_artifacts_metrics_frame_stats_and_config(ctx, job_id):
    assert execute_job(ctx, job_id) == JobStatus.SUCCEEDED
    job = _job(ctx, job_id)
    assert job.status == JobStatus.SUCCEEDED and job.progress == 1.0 and job.worker == "w1"
    assert job.frames_done == job.frames_total == 5
    assert job.config == {"name": "orb-only", "dense.enabled": False}
    # timings are all milliseconds: the run's steps and run_ms, the whole pipeline call; the stage says it ended
    assert job.timings["tracking"] == 3.0 and job.timings["run_ms"] >= 0 and "run_s" not in job.timings
    assert job.stage == jobs.FINISHED_STAGE == "done"
    call = ctx.pipeline.calls[0]
    assert call["camera"] == {"preset": "tum1"} and call["overrides"] == {"dense.enabled": False}
    assert call["sequence_dir"] == ctx.store.root / "sequences/s"
    names = {a.name for a in ctx.store.list(job_id)}
    assert names == {*PIPELINE_OUTPUTS, "frame_stats.csv", "log.txt", "preview.png"}
    assert ctx.store.path(job_id, "preview.png").read_bytes()[:4] == b"\x89PNG"
    assert ctx.store.path(job_id, "frame_stats.csv").read_text().splitlines()[3].startswith("2,")
    assert "succeeded" in ctx.store.path(job_id, "log.txt").read_text()
    with ctx.session_factory() as s:
        m = metrics.get_run_metrics(s, job_id)
        assert (m.ate_rmse, m.rpe_trans_rmse, m.rpe_rot_rmse, m.fps, m.tracked, m.lost) == (0.02, 0.01, 0.3, 12.5, 4, 1)
        stats = metrics.get_frame_stats(s, job_id)
        assert [f.tracked for f in stats] == [True, True, False, True, True]
    assert not list((ctx.store.root / "staging").iterdir())  # the run's scratch folder is gone


def test_a_job_runs_once_even_if_delivered_twice(ctx, job_id):
    assert execute_job(ctx, job_id) == JobStatus.SUCCEEDED
    assert execute_job(ctx, job_id) is None
    assert len(ctx.pipeline.calls) == 1


def test_cancel_mid_run_stops_the_pipeline(ctx, job_id):
    def cancel(i):
        if i == 1:
            with ctx.session_factory() as s:
                jobs.request_cancel(s, job_id)

    ctx.pipeline = FakePipeline(frames=50, on_frame=cancel)
    assert execute_job(ctx, job_id) == JobStatus.CANCELLED
    job = _job(ctx, job_id)
    assert job.status == JobStatus.CANCELLED and job.frames_done < 5 and job.stage == jobs.FINISHED_STAGE
    assert "cancelled after" in job.error
    assert {a.name for a in ctx.store.list(job_id)} == {"log.txt"}


@pytest.mark.parametrize("error, message", [
    (ValueError("boom"), "ValueError: boom"),
    (None, "colour image must be 8-bit"),
])
def test_failures_become_failed_jobs_with_the_message(ctx, job_id, error, message):
    if error is None:
        from worker.slam.errors import SequenceFormatError

        error = SequenceFormatError("colour image must be 8-bit", path="rgb/1.png")
    ctx.pipeline = FakePipeline(error=error)
    assert execute_job(ctx, job_id) == JobStatus.FAILED
    job = _job(ctx, job_id)
    assert message in job.error and job.stage == "tracking"  # the step it failed in, not "done"
    assert "Traceback" in ctx.store.path(job_id, "log.txt").read_text()
    with ctx.session_factory() as s:
        assert metrics.get_frame_stats(s, job_id) == []


def test_a_job_deleted_while_running_leaves_nothing(ctx, job_id):
    def delete(i):
        if i == 1:
            with ctx.session_factory() as s:
                jobs.delete(s, job_id)

    ctx.pipeline = FakePipeline(frames=20, on_frame=delete)
    assert execute_job(ctx, job_id) is None
    assert ctx.store.list(job_id) == []
    assert not ctx.store.job_dir(job_id).exists()


def test_worker_shutdown_fails_the_running_job_retryably(ctx, job_id):
    ctx.pipeline = FakePipeline(frames=20, on_frame=lambda i: i == 2 and ctx.stopping.set())
    assert execute_job(ctx, job_id) == JobStatus.FAILED
    assert "retry" in _job(ctx, job_id).error
    with ctx.session_factory() as s:
        assert jobs.retry(s, job_id).status == JobStatus.QUEUED


def test_bad_config_fails_the_job_through_the_real_adapter(ctx, job_id, tmp_path):
    from worker.runner import run_slam

    write_sequence(ctx.store.root / "sequences/s", n=3)
    ctx.pipeline = run_slam
    with ctx.session_factory() as s:
        bad = jobs.create(s, sequence_id=jobs.get(s, job_id).sequence_id, preset="orb-only",
                          config={"tracking": {"nonsense": 1}})
    assert execute_job(ctx, bad.id) == JobStatus.FAILED
    assert "unknown config field tracking.nonsense" in _job(ctx, bad.id).error


def test_orphans_of_this_worker_name_are_failed_on_start(ctx, job_id):
    with ctx.session_factory() as s:
        assert jobs.claim(s, job_id, "w1")
        other = jobs.create(s, sequence_id=jobs.get(s, job_id).sequence_id, preset="orb-only")
        assert jobs.claim(s, other.id, "w2")
    assert reap_orphans(ctx).all == [job_id]
    assert _job(ctx, job_id).status == JobStatus.FAILED and "stopped" in _job(ctx, job_id).error
    assert _job(ctx, other.id).status == JobStatus.RUNNING


def test_api_enqueue_reaches_the_worker_task_through_huey(ctx, job_id, tmp_path):
    """The api registers run_job without a body, the worker with one: the names must agree."""
    path = str(tmp_path / "q.db")
    make_enqueue(SqliteHuey(name="vtdslam", filename=path))(job_id)
    worker_huey = SqliteHuey(name="vtdslam", filename=path)
    register_tasks(worker_huey, ctx)
    message = worker_huey.dequeue()
    worker_huey.execute(message)
    assert _job(ctx, job_id).status == JobStatus.SUCCEEDED


def test_progress_writes_are_throttled(ctx, job_id, monkeypatch):
    writes = []
    real = jobs.update_progress

    def counting(*a, **kw):
        writes.append(kw)
        return real(*a, **kw)

    monkeypatch.setattr(jobs, "update_progress", counting)
    ctx.progress_interval_s = 3600.0
    ctx.pipeline = FakePipeline(frames=200)
    assert execute_job(ctx, job_id) == JobStatus.SUCCEEDED
    assert len(writes) <= 4  # starting, tracking (stage change), saving -- not one per frame


def test_real_pipeline_runs_a_generated_sequence(ctx, job_id):
    pytest.importorskip("cv2")
    from worker.runner import run_slam

    write_sequence(ctx.store.root / "sequences/s", n=45)  # 1.5 s: RPE needs pose pairs 1 s apart
    ctx.pipeline = run_slam
    with ctx.session_factory() as s:
        job = jobs.create(s, sequence_id=jobs.get(s, job_id).sequence_id, preset="orb-only")
    assert execute_job(ctx, job.id) == JobStatus.SUCCEEDED, _job(ctx, job.id).error
    with ctx.session_factory() as s:
        m = metrics.get_run_metrics(s, job.id)
        assert m.ate_rmse is not None and m.ate_rmse < 0.05
        assert m.rpe_rot_rmse is not None and m.tracked == 45
        assert len(metrics.get_frame_stats(s, job.id)) == 45
    assert {a.name for a in ctx.store.list(job.id)} >= set(PIPELINE_OUTPUTS)
    assert _job(ctx, job.id).config["name"] == "orb-only"


def test_a_run_that_tracked_nothing_fails_with_the_reason(ctx, job_id):
    """All-zero depth: no map can start. The job fails saying why, and stores no half result."""
    cv2 = pytest.importorskip("cv2")
    import numpy as np

    from worker.runner import run_slam

    seq = write_sequence(ctx.store.root / "sequences/s", n=5)
    for depth in (seq / "depth").iterdir():
        cv2.imwrite(str(depth), np.zeros((120, 160), np.uint16))
    ctx.pipeline = run_slam
    with ctx.session_factory() as s:
        job = jobs.create(s, sequence_id=jobs.get(s, job_id).sequence_id, preset="orb-only")
    assert execute_job(ctx, job.id) == JobStatus.FAILED
    error = _job(ctx, job.id).error
    assert error.startswith("no frame was tracked: 5 frames of 160x120") and "valid depth" in error
    assert {a.name for a in ctx.store.list(job.id)} <= {"log.txt"}
    with ctx.session_factory() as s:
        assert metrics.get_frame_stats(s, job.id) == []


def test_execute_job_is_thread_safe_for_two_workers(ctx, job_id):
    results = []
    threads = [threading.Thread(target=lambda: results.append(execute_job(ctx, job_id))) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(results, key=str) == [None, JobStatus.SUCCEEDED]
    assert len(ctx.pipeline.calls) == 1
