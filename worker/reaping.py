"""Jobs of dead workers: requeued (up to ``Settings.requeue_orphans`` times, and at most once: a job whose
worker died twice is a poison job and failed, see ``storage.repositories.job_reaping.POISON_DEATHS``) or failed,
files removed.

Two ways to find them: on start a worker takes the jobs still running under its own name (its previous
process died: see :mod:`worker.identity`), and every worker's reaper thread takes running jobs of any
worker that has not reported for ``heartbeat_timeout_s`` (killed, machine lost; the api's reads do the
same, so this needs no live worker). Their partial outputs (the staging folder of the run, artifacts of an
interrupted save) are removed either way (``storage.reaping.settle``), so a failed job shows no half of a
result and a requeued one starts clean.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from storage.reaping import reap_stale_jobs, settle
from storage.repositories import job_reaping
from storage.repositories.job_reaping import Reaped
from worker.tasks import WorkerContext

log = logging.getLogger("worker.reaping")


def reap_orphans(ctx: WorkerContext) -> Reaped:
    """Jobs this worker name left running when its process died."""
    with ctx.session_factory() as session:
        reaped = job_reaping.reap_orphaned(
            session,
            worker=ctx.name,
            error=f"the worker ({ctx.name}) stopped before the job finished; retry it",
            requeue_limit=ctx.settings.requeue_orphans,
        )
        settle(session, ctx.store, reaped, f"was left running by a previous worker {ctx.name}", ctx.enqueue)
    return reaped


def reap_stale(ctx: WorkerContext, timeout_s: float) -> Reaped:
    """Jobs of any worker that stopped reporting for ``timeout_s`` (the api's reads reap them too)."""
    with ctx.session_factory() as session:
        return reap_stale_jobs(session, ctx.store, timeout_s=timeout_s, requeue_limit=ctx.settings.requeue_orphans,
                               enqueue=ctx.enqueue)


def start_reaper(
    ctx: WorkerContext, timeout_s: float, alive: Callable[[], None] | None = None
) -> threading.Thread:
    """A daemon thread reaping stale jobs every ``timeout_s / 4`` until ``ctx.stopping``; ``alive`` is
    called after every round that reached the database (the worker's health signal)."""

    def loop() -> None:
        while not ctx.stopping.wait(timeout_s / 4):
            try:
                reap_stale(ctx, timeout_s)
                if alive is not None:
                    alive()
            except Exception:  # a database hiccup must not kill the worker; the next round retries
                log.exception("checking for stale jobs failed")

    thread = threading.Thread(target=loop, name="stale-job-reaper", daemon=True)
    thread.start()
    return thread
