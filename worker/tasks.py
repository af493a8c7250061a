"""The job task: claim a queued job once, run the pipeline, report progress, store results.

While a job runs, a heartbeat thread marks it alive (so a silent stage is never taken for a dead worker),
and every write is tied to the claimed attempt: a worker whose job was reaped meanwhile (requeued, maybe
running elsewhere) stores nothing and leaves the new attempt alone.

:func:`execute_job` holds the whole flow and takes a :class:`WorkerContext` (settings, sessions, store,
the pipeline function), so tests run it directly with a fake pipeline; :func:`register_tasks` puts it on
a huey instance under the queue contract's name (``storage.queue``).
"""

from __future__ import annotations

import errno
import logging
import shutil
import socket
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from huey import Huey
from sqlalchemy.orm import Session, sessionmaker

from formats import artifacts
from formats.frame_stats import STORED_COLUMNS, format_frame_stats
from formats.run_metrics import RunMetrics, write_run_metrics
from storage import live as live_spool
from storage.artifacts import ArtifactStore
from storage.errors import Conflict, NotFound, StorageError
from storage.models import JobStatus
from storage.queue import register_run_job
from storage.redact import redact_paths
from storage.repositories import jobs, metrics, sequences
from storage.settings import Settings
from worker.live import run_live_slam
from worker.preview import write_trajectory_preview
from worker.runner import Cancelled, PipelineFn, RunOutput, run_slam
from worker.snapshots import PartialWriter, SnapshotConfig

log = logging.getLogger("worker.tasks")

FRAME_STATS_CHUNK = 2000
RUN_MS = jobs.RUN_MS


@dataclass
class WorkerContext:
    """What a worker process needs to run jobs; built once per process."""

    settings: Settings
    session_factory: sessionmaker[Session]
    store: ArtifactStore
    name: str = field(default_factory=socket.gethostname)
    """Stored on the jobs it claims; a restarted worker of the same name fails its orphans."""
    pipeline: PipelineFn = run_slam
    live_pipeline: Callable[..., RunOutput] = run_live_slam
    """Runs a job whose sequence is a live session still receiving (``storage.live``); takes ``snapshot``."""
    snapshots: SnapshotConfig | None = None
    """Partial results of running jobs for the page and the viewer (``worker.snapshots``); None: only live
    sessions write them (``pipeline`` is then called without ``snapshot``: test doubles need not take it)."""
    progress_interval_s: float = 0.5
    """Progress is written (and cancellation checked) at most this often."""
    stopping: threading.Event = field(default_factory=threading.Event)
    """Set when the process shuts down: running jobs stop and fail with a retryable reason."""
    enqueue: Callable[[str], None] | None = None
    """Puts a job id on the queue (set by the consumer; reaping requeues orphans through it)."""
    heartbeat_interval_s: float | None = None
    """A running job is marked alive this often even when the pipeline is silent (a long global BA);
    None: a quarter of ``settings.heartbeat_timeout_s``, so a live job is never taken for a dead one."""


class _Reporter:
    """Throttled progress writes; the answer of each write says whether to stop."""

    def __init__(self, ctx: WorkerContext, session: Session, job_id: str, attempt: int,
                 lost: threading.Event) -> None:
        self.ctx, self.session, self.job_id, self.attempt = ctx, session, job_id, attempt
        self.lost = lost  # set by the heartbeat when the job stopped being ours
        self.done = self.total = 0
        self.stage = ""
        self.last = 0.0
        self.stop_reason: str | None = None  # "cancelled" | "stopping" | "deleted" | "ended"

    def progress(self, done: int, total: int, stage: str) -> None:
        changed = stage != self.stage
        self.done, self.total, self.stage = done, total, stage
        if changed or time.monotonic() - self.last >= self.ctx.progress_interval_s:
            self.flush()

    def should_cancel(self) -> bool:
        if self.ctx.stopping.is_set() and self.stop_reason is None:
            self.stop_reason = "stopping"
        due = time.monotonic() - self.last >= self.ctx.progress_interval_s
        if self.stop_reason is None and (due or self.lost.is_set()):
            self.flush()
        return self.stop_reason is not None

    def flush(self, **extra: Any) -> None:
        self.last = time.monotonic()
        values: dict[str, Any] = {"stage": self.stage, "frames_done": self.done, "frames_total": self.total}
        if self.total > 0:
            values["progress"] = 0.98 * self.done / self.total  # the rest is saving the results
        values.update(extra)
        try:
            stop = jobs.update_progress(self.session, self.job_id, attempt=self.attempt, **values)
        except NotFound:
            self.stop_reason = "deleted"
            return
        if stop and self.stop_reason is None:
            job = jobs.get(self.session, self.job_id)
            mine = job.status == JobStatus.RUNNING and job.attempts == self.attempt
            self.stop_reason = "cancelled" if job.cancel_requested and mine else "ended"


class _Heartbeat:
    """Marks the running job alive from its own thread (and session) while the pipeline may be silent."""

    def __init__(self, ctx: WorkerContext, job_id: str, attempt: int) -> None:
        self.ctx, self.job_id, self.attempt = ctx, job_id, attempt
        self.interval = ctx.heartbeat_interval_s or ctx.settings.heartbeat_timeout_s / 4
        self.lost = threading.Event()
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._loop, name=f"heartbeat-{job_id}", daemon=True)

    def __enter__(self) -> _Heartbeat:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._done.set()
        self._thread.join()

    def _loop(self) -> None:
        with self.ctx.session_factory() as session:
            while not self._done.wait(self.interval):
                try:
                    if not jobs.heartbeat(session, self.job_id, self.attempt):
                        self.lost.set()  # reaped, deleted or ended: the reporter finds out which
                        return
                except Exception as exc:  # a database hiccup: the next beat retries
                    log.warning("job %s: heartbeat failed: %s", self.job_id, exc)


class _JobLog(logging.Handler):
    """Collects this thread's log records during one job (written as the job's ``log.txt``)."""

    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.thread = threading.get_ident()
        self.lines: list[str] = []
        self.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))

    def emit(self, record: logging.LogRecord) -> None:
        if record.thread == self.thread and len(self.lines) < 10_000:
            self.lines.append(self.format(record))


def execute_job(ctx: WorkerContext, job_id: str) -> JobStatus | None:
    """Run one job end to end; returns its final status, or None if it was not ours to run."""
    with ctx.session_factory() as session:
        if not jobs.claim(session, job_id, ctx.name):
            log.info("job %s skipped: not queued any more (cancelled, deleted or claimed elsewhere)", job_id)
            return None
        joblog = _JobLog()
        ours = logging.getLogger("worker")  # the task's and the pipeline's loggers
        if ours.getEffectiveLevel() > logging.INFO:
            ours.setLevel(logging.INFO)
        ours.addHandler(joblog)
        try:
            # Nothing but reaping changes attempts of a running job, and not within milliseconds.
            attempt = jobs.get(session, job_id).attempts
            with _Heartbeat(ctx, job_id, attempt) as beat:
                return _run_claimed(ctx, session, job_id, attempt, beat.lost, joblog)
        finally:
            ours.removeHandler(joblog)


def _run_claimed(
    ctx: WorkerContext, session: Session, job_id: str, attempt: int, lost: threading.Event, joblog: _JobLog
) -> JobStatus | None:
    reporter = _Reporter(ctx, session, job_id, attempt, lost)
    out_dir = ctx.store.new_staging_dir(prefix=f"job-{job_id}-")
    status, error = JobStatus.FAILED, None
    timings: dict[str, Any] | None = None
    saving = False
    partial: PartialWriter | None = None
    live = own_session = False
    try:
        job = jobs.get(session, job_id)
        seq = sequences.get(session, job.sequence_id)
        log.info("job %s: %s on sequence %s (%s, %d frames), worker %s",
                 job_id, job.preset, seq.name, seq.id, seq.frames, ctx.name)
        reporter.progress(0, seq.frames, "starting")
        live = (seq.meta or {}).get("live") == live_spool.LIVE_RECEIVING
        own_session = live and (seq.meta or {}).get(live_spool.LIVE_JOB) == job_id
        if live or ctx.snapshots is not None:
            partial = PartialWriter(ctx.store, job_id, ctx.snapshots or SnapshotConfig())
        t0 = time.monotonic()
        output = (ctx.live_pipeline if live else ctx.pipeline)(
            ctx.store.resolve(seq.path),
            dict(seq.camera),
            job.preset,
            dict(job.config or {}),
            out_dir,
            progress=reporter.progress,
            should_cancel=reporter.should_cancel,
            **({"snapshot": partial} if partial is not None else {}),
        )
        run_s = time.monotonic() - t0
        if partial is not None:
            partial.close()  # the last snapshot written: its outcome counts
            _snapshot_figures(output, out_dir, partial)
        reporter.progress(reporter.total, reporter.total, "saving")
        _preview(out_dir)
        if reporter.stop_reason in ("deleted", "ended"):  # not ours any more: store nothing
            raise Cancelled("the job was deleted" if reporter.stop_reason == "deleted" else "the job was reaped")
        # all milliseconds: the run's mean ms per call by step, and run_ms the whole pipeline call (the api's run_s)
        timings = {**RunMetrics.from_dict(output.metrics).timings_ms, RUN_MS: round(1000 * run_s, 1)}
        saving = True
        _save_results(ctx, session, job_id, out_dir, output)
        status = JobStatus.SUCCEEDED
        log.info("job %s succeeded in %.1f s", job_id, run_s)
    except Cancelled as exc:
        if reporter.stop_reason == "deleted":
            log.info("job %s was deleted while running; its files are removed", job_id)
            ctx.store.delete_job(job_id)
            return None
        if reporter.stop_reason == "stopping":
            error = "the worker was stopped before the job finished; retry it"
        elif reporter.stop_reason == "cancelled":
            status, error = JobStatus.CANCELLED, str(exc) or "cancelled"
        else:
            error = str(exc) or "stopped"
        log.info("job %s stopped: %s", job_id, error)
        if reporter.stop_reason == "ended":  # reaped (maybe requeued): its files are not ours to touch
            return _finish(ctx, session, job_id, attempt, status, error, None, joblog)
    except NotFound as exc:  # the job (or its sequence) was deleted meanwhile
        log.info("job %s: %s; nothing to report", job_id, exc.message)
        ctx.store.delete_job(job_id)
        return None
    except Exception as exc:  # every failure becomes a failed job with a readable message
        error = _message(exc)
        log.error("job %s failed: %s", job_id, error)
        joblog.lines.append(traceback.format_exc())
        if saving:  # a failed job shows no half of a result (e.g. the disk filled up mid-save)
            _discard_results(ctx, session, job_id, attempt)
    finally:
        shutil.rmtree(out_dir, ignore_errors=True)
        if partial is not None:
            partial.remove()
        if own_session:  # the session's own job ended (however): so does its stream
            _end_session(ctx, session, job_id)
    return _finish(ctx, session, job_id, attempt, status, error, timings, joblog)


def _snapshot_figures(output: RunOutput, out_dir: Path, partial: PartialWriter) -> None:
    """What the partial results cost the pipeline thread (timings_ms["snapshots"], ms per frame) and, when they
    stopped being written, why (a warning: the fallback is on record), in the stored metrics and metrics.json."""
    if partial.frames:
        output.metrics.setdefault("timings_ms", {})["snapshots"] = round(1000 * partial.spent_s / partial.frames, 2)
    if partial.error is not None:
        output.metrics["warnings"] = [*output.metrics.get("warnings", []), partial.error]
    if (out_dir / artifacts.METRICS).is_file():
        write_run_metrics(out_dir / artifacts.METRICS, RunMetrics.from_dict(output.metrics))


def _end_session(ctx: WorkerContext, session: Session, job_id: str) -> None:
    """A live job ended (however): its stream ends too, and its sequence is recorded as an ordinary one."""
    try:
        seq = sequences.get(session, jobs.get(session, job_id).sequence_id)
        spool = live_spool.LiveSpool(ctx.store.resolve(seq.path))
        spool.end("the job ended", spool.count())
        live_spool.finalize(session, ctx.store, seq.id)
    except Exception as exc:  # the job's verdict stands; the sequence keeps its files
        log.warning("job %s: could not record its live session's sequence: %s", job_id, exc)


def _discard_results(ctx: WorkerContext, session: Session, job_id: str, attempt: int) -> None:
    try:
        job = jobs.get(session, job_id)
        if job.status != JobStatus.RUNNING or job.attempts != attempt:
            return  # reaped meanwhile: the reaper cleaned up, and a new attempt's files are not ours
        ctx.store.delete_job(job_id)
        jobs.discard_results(session, job_id)
    except Exception as exc:  # the job still fails; its partial results are what remains
        log.warning("job %s: could not remove its partial results: %s", job_id, exc)


def _preview(out_dir: Path) -> None:
    """A preview image next to the outputs; a run never fails for want of one."""
    try:
        write_trajectory_preview(out_dir)
    except Exception as exc:
        log.warning("no preview image: %s", exc)


def _message(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return (f"disk full: no space left for the job's files in the data directory ({exc.strerror}); "
                "free space and retry the job")
    message = getattr(exc, "message", None)
    if isinstance(message, str) and message:
        return message
    return f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__


def _save_results(ctx: WorkerContext, session: Session, job_id: str, out_dir: Path, output: RunOutput) -> None:
    for path in sorted(out_dir.iterdir()):
        if path.is_file() and not path.name.startswith("."):
            ctx.store.put_file(job_id, path.name, path)
    if output.frame_stats and not (out_dir / artifacts.FRAME_STATS).is_file():  # a pipeline that writes none
        rows = [r.to_stored() for r in output.frame_stats]
        ctx.store.write_text(job_id, artifacts.FRAME_STATS, format_frame_stats(rows, STORED_COLUMNS))
    metrics.save_run_metrics(session, job_id, output.metrics)
    for i in range(0, len(output.frame_stats), FRAME_STATS_CHUNK):
        metrics.add_frame_stats(session, job_id, output.frame_stats[i : i + FRAME_STATS_CHUNK])
    jobs.set_config(session, job_id, output.config)


def _finish(
    ctx: WorkerContext,
    session: Session,
    job_id: str,
    attempt: int,
    status: JobStatus,
    error: str | None,
    timings: dict[str, Any] | None,
    joblog: _JobLog,
) -> JobStatus | None:
    try:
        # clients read the error and log.txt without a token: no absolute server paths in either
        error = redact_paths(error, ctx.settings.data_dir) if error else error
        jobs.finish(session, job_id, status, error=error, timings=timings, attempt=attempt)
    except NotFound:
        ctx.store.delete_job(job_id)
        return None
    except Conflict as exc:  # someone else ended it (e.g. marked failed as orphaned): leave their verdict
        log.warning("job %s: %s", job_id, exc.message)
        return jobs.get(session, job_id).status
    try:
        text = redact_paths("\n".join(joblog.lines), ctx.settings.data_dir)
        ctx.store.write_text(job_id, artifacts.LOG, text + "\n")
    except (OSError, StorageError) as exc:
        log.warning("job %s: could not write its log: %s", job_id, exc)
    return status


def register_tasks(huey: Huey, ctx: WorkerContext) -> Any:
    """Register ``run_job`` on ``huey`` to execute jobs with ``ctx``; returns the task."""
    return register_run_job(huey, lambda job_id: execute_job(ctx, job_id))
