import random
import threading
from collections.abc import Callable

import pytest
from sqlalchemy.orm import Session, sessionmaker

from storage.errors import Conflict, InvalidInput, NotFound
from storage.models import Job, JobStatus, Sequence
from storage.repositories import job_reaping, jobs, metrics


@pytest.fixture
def seq(make_sequence: Callable[..., Sequence]) -> Sequence:
    return make_sequence("s")


@pytest.fixture
def job(session: Session, seq: Sequence) -> Job:
    return jobs.create(session, sequence_id=seq.id, preset="full", config={"seg": {"on": True}})


def test_create_and_get(session: Session, job: Job, seq: Sequence) -> None:
    got = jobs.get(session, job.id)
    expected = (seq.id, "full", JobStatus.QUEUED, {"seg": {"on": True}})
    assert (got.sequence_id, got.preset, got.status, got.config) == expected
    assert (got.progress, got.attempts, got.cancel_requested, got.batch_id, got.metrics) == (0.0, 1, False, None, None)
    assert got.created_at.tzinfo is not None and got.started_at is None


def test_create_needs_existing_sequence_and_batch(session: Session, seq: Sequence) -> None:
    with pytest.raises(NotFound):
        jobs.create(session, sequence_id="missing", preset="full")
    with pytest.raises(NotFound):
        jobs.create(session, sequence_id=seq.id, preset="full", batch_id="missing")
    with pytest.raises(InvalidInput):
        jobs.create(session, sequence_id=seq.id, preset="")
    assert jobs.count(session) == 0


def test_get_missing(session: Session) -> None:
    with pytest.raises(NotFound):
        jobs.get(session, "missing")


def test_list_filters_and_paging(session: Session, make_sequence: Callable[..., Sequence]) -> None:
    a, b = make_sequence("a"), make_sequence("b")
    ja = [jobs.create(session, sequence_id=a.id, preset=p) for p in ("full", "orb-only", "no-restoration")]
    jb = jobs.create(session, sequence_id=b.id, preset="full")
    assert jobs.claim(session, ja[0].id, "w1")
    assert [j.id for j in jobs.list_jobs(session)] == [jb.id, ja[2].id, ja[1].id, ja[0].id]
    assert [j.id for j in jobs.list_jobs(session, sequence_id=a.id, limit=2)] == [ja[2].id, ja[1].id]
    assert [j.id for j in jobs.list_jobs(session, sequence_id=a.id, limit=2, offset=2)] == [ja[0].id]
    assert [j.id for j in jobs.list_jobs(session, status="running")] == [ja[0].id]
    assert jobs.count(session, status=JobStatus.QUEUED) == 3
    assert jobs.count(session, status="queued", sequence_id=b.id) == 1
    assert jobs.list_jobs(session, batch_id="none") == []
    with pytest.raises(InvalidInput):
        jobs.list_jobs(session, status="exploded")


def test_claim_once(session: Session, job: Job) -> None:
    assert jobs.claim(session, job.id, "w1") is True
    assert jobs.claim(session, job.id, "w2") is False
    got = jobs.get(session, job.id)
    assert (got.status, got.worker) == (JobStatus.RUNNING, "w1")
    assert got.started_at is not None


def test_claim_missing_job_is_false(session: Session) -> None:
    assert jobs.claim(session, "missing", "w") is False


def test_claim_exactly_once_under_contention(
    session_factory: sessionmaker[Session], session: Session, seq: Sequence
) -> None:
    """Two workers race over the same jobs; every job is won by exactly one."""
    ids = [jobs.create(session, sequence_id=seq.id, preset="full").id for _ in range(40)]
    won: dict[str, list[str]] = {"w1": [], "w2": []}
    errors: list[BaseException] = []
    barrier = threading.Barrier(2)

    def work(name: str) -> None:
        order = ids[:]
        random.Random(name).shuffle(order)
        try:
            with session_factory() as s:
                barrier.wait()
                for job_id in order:
                    if jobs.claim(s, job_id, name):
                        won[name].append(job_id)
        except BaseException as exc:
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(n,)) for n in won]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert sorted(won["w1"] + won["w2"]) == sorted(ids)  # all claimed, none twice
    assert all(jobs.get(session, i).worker == w for w, got in won.items() for i in got)


def test_progress(session: Session, job: Job) -> None:
    assert jobs.claim(session, job.id, "w")
    stop = jobs.update_progress(
        session, job.id, progress=1.7, stage="tracking", frames_done=5, frames_total=10, timings={"seg": 1.0}
    )
    assert stop is False
    got = jobs.get(session, job.id)
    expected = (1.0, "tracking", 5, 10, {"seg": 1.0})
    assert (got.progress, got.stage, got.frames_done, got.frames_total, got.timings) == expected
    assert jobs.update_progress(session, job.id, progress=-1) is False
    assert jobs.get(session, job.id).progress == 0.0


def test_progress_ignored_unless_running(session: Session, job: Job) -> None:
    assert jobs.update_progress(session, job.id, progress=0.5) is True  # queued: not running, stop
    assert jobs.get(session, job.id).progress == 0.0
    with pytest.raises(NotFound):
        jobs.update_progress(session, "missing", progress=0.1)


def test_cancel_queued_job_then_claim_fails(session: Session, job: Job) -> None:
    got = jobs.request_cancel(session, job.id)
    assert got.status == JobStatus.CANCELLED and got.cancel_requested and got.finished_at is not None
    assert jobs.claim(session, job.id, "w") is False
    assert jobs.request_cancel(session, job.id).status == JobStatus.CANCELLED  # idempotent


def test_cancel_running_job_flags_worker(session: Session, job: Job) -> None:
    assert jobs.claim(session, job.id, "w")
    got = jobs.request_cancel(session, job.id)
    assert got.status == JobStatus.RUNNING and got.cancel_requested
    assert jobs.get(session, job.id).cancel_requested
    assert jobs.update_progress(session, job.id, progress=0.5) is True  # the worker is told to stop
    done = jobs.finish(session, job.id, JobStatus.CANCELLED, error="cancelled by user")
    assert (done.status, done.error) == (JobStatus.CANCELLED, "cancelled by user")


def test_cancel_finished_job_conflicts(session: Session, job: Job) -> None:
    assert jobs.claim(session, job.id, "w")
    jobs.finish(session, job.id, "succeeded")
    with pytest.raises(Conflict):
        jobs.request_cancel(session, job.id)
    with pytest.raises(NotFound):
        jobs.request_cancel(session, "missing")


def test_finish(session: Session, job: Job) -> None:
    assert jobs.claim(session, job.id, "w")
    done = jobs.finish(session, job.id, "succeeded", timings={"total": 2.0})
    assert (done.status, done.progress, done.timings, done.error) == (JobStatus.SUCCEEDED, 1.0, {"total": 2.0}, None)
    assert done.stage == jobs.FINISHED_STAGE  # not the last running step ("saving")
    assert done.started_at is not None and done.finished_at is not None
    assert done.finished_at >= done.started_at
    with pytest.raises(Conflict):
        jobs.finish(session, job.id, "failed", error="late")
    with pytest.raises(InvalidInput):
        jobs.finish(session, job.id, "running")
    with pytest.raises(InvalidInput):
        jobs.finish(session, job.id, "nonsense")
    with pytest.raises(NotFound):
        jobs.finish(session, "missing", "failed")


def test_retry_failed_job(session: Session, job: Job) -> None:
    assert jobs.claim(session, job.id, "w")
    jobs.update_progress(session, job.id, progress=0.4, stage="tracking", frames_done=4)
    metrics.save_run_metrics(session, job.id, {"fps": 3.0})
    metrics.add_frame_stats(session, job.id, [{"frame_index": 0, "timestamp": 0.0}])
    jobs.finish(session, job.id, "failed", error="boom")
    again = jobs.retry(session, job.id)
    expected = (JobStatus.QUEUED, 2, 0.0, "", None)
    assert (again.status, again.attempts, again.progress, again.stage, again.error) == expected
    assert (again.started_at, again.finished_at, again.worker, again.cancel_requested) == (None, None, None, False)
    assert again.config == {"seg": {"on": True}}  # the requested config stays
    assert again.metrics is None and metrics.get_frame_stats(session, job.id) == []
    assert jobs.claim(session, job.id, "w2")


def test_retry_cancelled_job(session: Session, job: Job) -> None:
    jobs.request_cancel(session, job.id)
    assert jobs.retry(session, job.id).status == JobStatus.QUEUED
    assert jobs.claim(session, job.id, "w")  # the old cancel flag does not stick


@pytest.mark.parametrize("state", ["queued", "running", "succeeded"])
def test_retry_other_states_conflict(session: Session, job: Job, state: str) -> None:
    if state != "queued":
        assert jobs.claim(session, job.id, "w")
    if state == "succeeded":
        jobs.finish(session, job.id, "succeeded")
    with pytest.raises(Conflict):
        jobs.retry(session, job.id)
    assert jobs.get(session, job.id).attempts == 1


def test_reap_orphaned_without_requeues_fails(session: Session, seq: Sequence) -> None:
    a, b, c, queued = (jobs.create(session, sequence_id=seq.id, preset="full") for _ in range(4))
    assert jobs.claim(session, a.id, "host1-1") and jobs.claim(session, b.id, "host2-1")
    assert jobs.claim(session, c.id, "host1-1")
    jobs.finish(session, c.id, "succeeded")
    assert job_reaping.reap_orphaned(session, worker="host1-1").failed == [a.id]
    got = jobs.get(session, a.id)
    assert (got.status, got.error) == (JobStatus.FAILED, "the worker stopped before the job finished")
    assert got.stage == ""  # it died before its first step: no step to name
    jobs.update_progress(session, b.id, stage="dense")
    assert job_reaping.reap_orphaned(session).failed == [b.id]
    assert jobs.get(session, b.id).stage == "dense"  # the step its worker died in
    assert job_reaping.reap_orphaned(session).failed == []
    assert jobs.get(session, c.id).status == JobStatus.SUCCEEDED
    assert jobs.get(session, queued.id).status == JobStatus.QUEUED
    assert (jobs.retry(session, a.id).status, jobs.get(session, a.id).stage) == (JobStatus.QUEUED, "")


def test_set_config(session: Session, job: Job) -> None:
    jobs.set_config(session, job.id, {"full": 1})
    assert jobs.get(session, job.id).config == {"full": 1}
    with pytest.raises(NotFound):
        jobs.set_config(session, "missing", {})


def test_delete(session: Session, job: Job) -> None:
    metrics.save_run_metrics(session, job.id, {"fps": 1.0})
    metrics.add_frame_stats(session, job.id, [{"frame_index": 0, "timestamp": 0.0}])
    jobs.delete(session, job.id)
    with pytest.raises(NotFound):
        jobs.get(session, job.id)
    with pytest.raises(NotFound):
        metrics.get_run_metrics(session, job.id)
    assert metrics.get_frame_stats(session, job.id) == []
    with pytest.raises(NotFound):
        jobs.delete(session, job.id)
    with pytest.raises(NotFound):  # a worker still running it learns it is gone
        jobs.update_progress(session, job.id, progress=0.5)


def test_other_session_sees_fresh_progress(
    session_factory: sessionmaker[Session], session: Session, job: Job
) -> None:
    """The api polls with a long-lived session while the worker writes through its own."""
    seen = jobs.get(session, job.id)
    with session_factory() as worker:
        jobs.claim(worker, job.id, "w")
        jobs.update_progress(worker, job.id, progress=0.5)
    assert jobs.get(session, job.id).progress == 0.5
    assert seen.progress == 0.5  # same identity, refreshed
    assert jobs.list_jobs(session)[0].status == JobStatus.RUNNING


def test_reap_stale_uses_the_heartbeat(session: Session, seq: Sequence) -> None:
    import time

    alive, dead = (jobs.create(session, sequence_id=seq.id, preset="full") for _ in range(2))
    assert jobs.claim(session, alive.id, "w1") and jobs.claim(session, dead.id, "w2")
    assert jobs.get(session, dead.id).heartbeat_at is not None
    time.sleep(1.2)
    jobs.update_progress(session, alive.id, frames_done=3)  # w1 reports, w2 has gone silent
    assert job_reaping.reap_stale(session, older_than_s=1.0).failed == [dead.id]
    got = jobs.get(session, dead.id)
    assert got.status == JobStatus.FAILED and "stopped reporting" in (got.error or "")
    assert jobs.get(session, alive.id).status == JobStatus.RUNNING
    assert job_reaping.reap_stale(session, older_than_s=1.0).failed == []


def test_any_stale_reads_what_reap_stale_would_take(session: Session, seq: Sequence) -> None:
    job = jobs.create(session, sequence_id=seq.id, preset="full")
    assert not job_reaping.any_stale(session, older_than_s=-1.0)  # queued: never stale
    assert jobs.claim(session, job.id, "w1")
    assert not job_reaping.any_stale(session, older_than_s=60.0)  # a fresh heartbeat
    assert job_reaping.any_stale(session, older_than_s=-1.0)
    assert job_reaping.reap_stale(session, older_than_s=-1.0).failed == [job.id]
    assert not job_reaping.any_stale(session, older_than_s=-1.0)


def test_reap_requeues_up_to_the_limit_then_fails(session: Session, seq: Sequence) -> None:
    dead, cancelling = (jobs.create(session, sequence_id=seq.id, preset="full") for _ in range(2))
    assert jobs.claim(session, dead.id, "w1") and jobs.claim(session, cancelling.id, "w1")
    jobs.update_progress(session, dead.id, progress=0.5, frames_done=5, stage="tracking")
    metrics.save_run_metrics(session, dead.id, {"fps": 1.0})  # killed while saving
    jobs.request_cancel(session, cancelling.id)
    reaped = job_reaping.reap_orphaned(session, worker="w1", requeue_limit=1)
    assert reaped.requeued == [dead.id] and reaped.failed == [cancelling.id]  # a cancel is never requeued
    got = jobs.get(session, dead.id)
    assert (got.status, got.attempts, got.requeues, got.progress, got.frames_done, got.worker) == (
        JobStatus.QUEUED, 2, 1, 0.0, 0, None)
    assert got.stage == job_reaping.REQUEUED_STAGE and got.heartbeat_at is None and got.started_at is None
    with pytest.raises(NotFound):
        metrics.get_run_metrics(session, dead.id)
    assert jobs.claim(session, dead.id, "w2")
    assert job_reaping.reap_stale(session, older_than_s=-1.0, requeue_limit=1).failed == [dead.id]  # budget spent
    assert jobs.retry(session, dead.id).requeues == 0


def test_attempt_guard_keeps_a_reaped_worker_off_the_new_attempt(session: Session, job: Job) -> None:
    assert jobs.claim(session, job.id, "old")
    assert jobs.heartbeat(session, job.id, attempt=1)
    assert job_reaping.reap_orphaned(session, worker="old", requeue_limit=1).requeued == [job.id]
    assert jobs.claim(session, job.id, "new")
    assert not jobs.heartbeat(session, job.id, attempt=1)
    assert jobs.update_progress(session, job.id, frames_done=99, attempt=1)  # "stop"
    assert jobs.get(session, job.id).frames_done == 0
    with pytest.raises(Conflict, match="requeued"):
        jobs.finish(session, job.id, "succeeded", attempt=1)
    assert not jobs.update_progress(session, job.id, frames_done=3, attempt=2)
    assert jobs.finish(session, job.id, "succeeded", attempt=2).status == JobStatus.SUCCEEDED
    assert not jobs.heartbeat(session, job.id, attempt=2)  # ended: no more heartbeats


def test_discard_results(session: Session, job: Job) -> None:
    metrics.save_run_metrics(session, job.id, {"fps": 1.0})
    metrics.add_frame_stats(session, job.id, [{"frame_index": 0, "timestamp": 0.0}])
    jobs.discard_results(session, job.id)
    with pytest.raises(NotFound):
        metrics.get_run_metrics(session, job.id)
    assert metrics.get_frame_stats(session, job.id) == []


def test_ending_sets_the_final_stage_but_a_failure_keeps_the_step_it_failed_in(session: Session, job: Job) -> None:
    jobs.claim(session, job.id, "w")
    jobs.update_progress(session, job.id, stage="saving", frames_done=5, frames_total=5)
    assert jobs.finish(session, job.id, "failed", error="disk full").stage == "saving"
    queued = jobs.create(session, sequence_id=job.sequence_id, preset="orb-only")
    assert jobs.request_cancel(session, queued.id).stage == jobs.FINISHED_STAGE
    running = jobs.create(session, sequence_id=job.sequence_id, preset="orb-only")
    jobs.claim(session, running.id, "w")
    jobs.update_progress(session, running.id, stage="tracking")
    assert jobs.finish(session, running.id, "cancelled").stage == jobs.FINISHED_STAGE


def test_timings_in_milliseconds_and_run_seconds_read_old_and_new_jobs() -> None:
    assert jobs.timings_ms({"tracking": 3.0, "run_s": 1.5}) == {"tracking": 3.0, "run_ms": 1500.0}
    assert jobs.timings_ms({"tracking": 3.0, "run_ms": 1500.0}) == {"tracking": 3.0, "run_ms": 1500.0}
    assert jobs.timings_ms(None) == {}
    assert jobs.run_seconds({"run_ms": 1500.0}) == 1.5 and jobs.run_seconds({"run_s": 2.25}) == 2.25
    assert jobs.run_seconds({}) is None and jobs.run_seconds({"run_ms": "x"}) is None
