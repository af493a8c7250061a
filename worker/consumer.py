"""The worker process: a huey consumer (threads) running :func:`worker.tasks.execute_job`.

On start it takes a name no live worker on the data directory holds (:mod:`worker.identity`), migrates
the database and reaps the jobs its previous incarnation left running (:mod:`worker.reaping`); queued
jobs wait in the persistent queue (SQLite file or Redis) and are picked up. On SIGINT/SIGTERM running
jobs stop at the next frame, are marked failed ("retry it"), and it exits.
"""

from __future__ import annotations

import logging
import socket
from typing import Any

from huey import Huey
from huey.consumer import Consumer

from storage.artifacts import ArtifactStore
from storage.db import init_db, make_engine, make_session_factory
from storage.queue import make_huey
from storage.settings import Settings
from worker.identity import claim_name
from worker.reaping import reap_orphans, start_reaper
from worker.runner import PipelineFn, run_slam
from worker.snapshots import SnapshotConfig
from worker.tasks import WorkerContext, register_tasks

log = logging.getLogger("worker.consumer")


def build_context(settings: Settings, *, name: str | None = None, pipeline: PipelineFn = run_slam,
                  snapshots: SnapshotConfig | None = None) -> WorkerContext:
    """``snapshots``: write running jobs' partial results (``worker.snapshots``; live sessions always do)."""
    engine = make_engine(settings)
    init_db(engine)
    return WorkerContext(
        settings=settings,
        session_factory=make_session_factory(engine),
        store=ArtifactStore(settings.data_dir),
        name=name or socket.gethostname(),
        pipeline=pipeline,
        snapshots=snapshots,
    )


def make_worker_huey(settings: Settings, ctx: WorkerContext, **kwargs: Any) -> Huey:
    """The queue with ``run_job`` registered; ``ctx.enqueue`` then requeues through the same task."""
    huey = make_huey(settings, **kwargs)
    task = register_tasks(huey, ctx)
    ctx.enqueue = lambda job_id: task(job_id)  # never a second registration: it would replace the body
    return huey


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
    identity = claim_name(settings.data_dir, name)  # held until the process exits
    # the real pipeline takes the snapshot hook; a test double given here may not
    ctx = build_context(settings, name=identity.name, pipeline=pipeline,
                        snapshots=SnapshotConfig() if pipeline is run_slam else None)
    huey = make_worker_huey(settings, ctx)  # before reaping: requeued orphans go back on this queue
    reap_orphans(ctx)
    identity.touch()
    start_reaper(ctx, settings.heartbeat_timeout_s, alive=identity.touch)
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
    try:
        consumer.run()
    finally:
        identity.release()
