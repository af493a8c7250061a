"""The task queue: the huey factory and the contract between the api (enqueues) and the worker (executes).

There is one task, ``run_job(job_id)``. huey routes a message by its task's ``module.name``; both sides
register the task through :func:`register_run_job`, so the name is the same while the api never imports the
worker. The api registers it without a body (it only enqueues); the worker passes the function that runs the job.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from huey import Huey, RedisHuey, SqliteHuey

from storage.errors import ConfigurationError
from storage.settings import Settings

QUEUE_NAME = "vtdslam"
TASK_NAME = "run_job"


def make_huey(settings: Settings, **kwargs: Any) -> Huey:
    """SQLite file queue in the data dir by default, Redis for ``redis://``/``rediss://`` URLs.

    ``kwargs`` go to huey (e.g. ``immediate=True`` in tests).
    """
    url = settings.queue_url
    if not url:
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        # Same busy timeout as the database: api and worker share the file.
        return SqliteHuey(name=QUEUE_NAME, filename=str(settings.queue_path), timeout=30, **kwargs)
    if url.startswith(("redis://", "rediss://", "unix://")):
        return RedisHuey(name=QUEUE_NAME, url=url, **kwargs)
    if url.startswith("sqlite:///"):
        path = Path(url[len("sqlite:///") :])
        path.parent.mkdir(parents=True, exist_ok=True)
        return SqliteHuey(name=QUEUE_NAME, filename=str(path), timeout=30, **kwargs)
    raise ConfigurationError(
        "VTD_QUEUE_URL must be redis://…, rediss://…, unix://… or sqlite:///PATH",
        {"queue_url": url},
    )


def register_run_job(huey: Huey, body: Callable[[str], object] | None = None) -> Any:
    """Register ``run_job(job_id)`` on ``huey`` and return the task (call it to enqueue).

    Jobs are never retried by the queue: retries are explicit (``POST /jobs/{id}/retry``).
    """

    def run_job(job_id: str) -> None:
        if body is None:
            raise RuntimeError("run_job was registered without a body: only a worker executes jobs")
        body(job_id)

    return huey.task(name=TASK_NAME, retries=0)(run_job)


def make_enqueue(huey: Huey) -> Callable[[str], None]:
    """A function that puts a job id on the queue (what the api calls after creating a job row)."""
    task = register_run_job(huey)

    def enqueue(job_id: str) -> None:
        task(job_id)

    return enqueue
