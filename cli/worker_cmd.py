"""`vtdslam worker`: run the job queue's consumer (the SLAM pipeline) in this process."""
from __future__ import annotations

from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    app.command("worker")(worker_command)


def worker_command(
    workers: Annotated[int, typer.Option(min=1, max=64, help="Jobs run at once (threads).")] = 1,
    name: Annotated[str | None, typer.Option(
        help="Worker name stored on its jobs (default: the host name). Unique per worker process: on start "
             "a worker marks jobs still 'running' under its name as failed (their process died).")] = None,
) -> None:
    """Take jobs from the queue (VTD_QUEUE_URL, default a SQLite file in VTD_DATA_DIR) and run them.

    Ctrl-C or SIGTERM stops running jobs at the next frame (they are marked failed, retry them) and exits.
    """
    import logging

    from storage.settings import get_settings
    from worker.consumer import run_consumer

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    run_consumer(get_settings(), workers=workers, name=name)
