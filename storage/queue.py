"""The task queue factory. Tasks are defined by the worker; the api only enqueues."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from huey import Huey, RedisHuey, SqliteHuey

from storage.errors import ConfigurationError
from storage.settings import Settings

QUEUE_NAME = "vtdslam"


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
