"""The worker process: a huey consumer (threads) running :func:`worker.tasks.execute_job`.

On start it migrates the database and fails the jobs its previous incarnation left running (same
worker name); queued jobs wait in the persistent queue (SQLite file or Redis) and are picked up. On
SIGINT/SIGTERM running jobs stop at the next frame, are marked failed ("retry it"), and it exits.
"""

from __future__ import annotations

import logging
import socket
import threading
from typing import Any

from huey import Huey
from huey.consumer import Consumer

from storage.artifacts import ArtifactStore
from storage.db import init_db, make_engine, make_session_factory
from storage.queue import make_huey
from storage.repositories import jobs
from storage.settings import Settings
from worker.runner import PipelineFn, run_slam
from worker.tasks import WorkerContext, register_tasks

log = logging.getLogger("worker.consumer")


def build_context(settings: Settings, *, name: str | None = None, pipeline: PipelineFn = run_slam) -> WorkerContext:
    engine = make_engine(settings)
    init_db(engine)
    return WorkerContext(
        settings=settings,
        session_factory=make_session_factory(engine),
        store=ArtifactStore(settings.data_dir),
        name=name or socket.gethostname(),
        pipeline=pipeline,
    )


def make_worker_huey(settings: Settings, ctx: WorkerContext, **kwargs: Any) -> Huey:
    huey = make_huey(settings, **kwargs)
    register_tasks(huey, ctx)
    return huey


def fail_orphans(ctx: WorkerContext) -> list[str]:
    """Jobs this worker name left running when its process died are marked failed (retryable)."""
    with ctx.session_factory() as session:
        failed = jobs.fail_orphaned(
            session, worker=ctx.name, error=f"the worker ({ctx.name}) stopped before the job finished; retry it"
        )
    for job_id in failed:
        log.warning("job %s was left running by a previous worker %s: marked failed", job_id, ctx.name)
    return failed


def fail_stale(ctx: WorkerContext, timeout_s: float) -> list[str]:
    """Jobs of any worker that stopped reporting (killed, machine lost) are marked failed (retryable)."""
    with ctx.session_factory() as session:
        failed = jobs.fail_stale(session, older_than_s=timeout_s)
    for job_id in failed:
        log.warning("job %s: its worker stopped reporting for %.0f s: marked failed", job_id, timeout_s)
    return failed


def _reaper(ctx: WorkerContext, timeout_s: float) -> threading.Thread:
    def loop() -> None:
        while not ctx.stopping.wait(timeout_s / 4):
            try:
                fail_stale(ctx, timeout_s)
            except Exception:  # a database hiccup must not kill the worker; the next round retries
                log.exception("checking for stale jobs failed")

    thread = threading.Thread(target=loop, name="stale-job-reaper", daemon=True)
    thread.start()
    return thread


class _StoppingConsumer(Consumer):
    """Any stop (SIGINT, SIGTERM) first tells running jobs to stop, then waits for them."""

    def __init__(self, huey: Huey, ctx: WorkerContext, **options: Any) -> None:
        super().__init__(huey, **options)
        self.ctx = ctx

    def stop(self, graceful: bool = False) -> None:
        self.ctx.stopping.set()
        super().stop(graceful=True)


def run_consumer(
    settings: Settings,
    *,
    workers: int = 1,
    name: str | None = None,
    pipeline: PipelineFn = run_slam,
    poll_max_delay_s: float = 1.0,
) -> None:
    """Run the consumer in this process until a signal stops it."""
    ctx = build_context(settings, name=name, pipeline=pipeline)
    fail_orphans(ctx)
    _reaper(ctx, settings.heartbeat_timeout_s)
    huey = make_worker_huey(settings, ctx)
    consumer = _StoppingConsumer(
        huey,
        ctx,
        workers=workers,
        worker_type="thread",
        periodic=False,
        max_delay=poll_max_delay_s,
        check_worker_health=True,
        shutdown_timeout=60,
    )
    queue = settings.queue_url.split(":", 1)[0] if settings.queue_url else f"sqlite {settings.queue_path}"
    database = (settings.database_url or "sqlite").split(":", 1)[0]  # never log credentials
    log.info("worker %s: %d thread(s), queue %s, database %s", ctx.name, workers, queue, database)
    consumer.run()
