"""The queue contract between the api (enqueues) and the worker (executes): one task, ``run_job(job_id)``.

huey routes a message by its task's ``module.name``; both sides register the task through
:func:`register_run_job`, so the name is the same while the api never imports the worker. The api
registers it without a body (it only enqueues); the worker passes the function that runs the job.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from huey import Huey

TASK_NAME = "run_job"


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
