import uuid
from pathlib import Path

import pytest
from huey import Huey, RedisHuey, SqliteHuey
from huey.api import TaskWrapper

from storage.errors import ConfigurationError
from storage.queue import QUEUE_NAME, make_huey
from storage.settings import Settings


def _define_add(huey: Huey) -> TaskWrapper:
    """What both the api (to enqueue) and the worker (to run) do with the worker's task module."""

    @huey.task(name="add")
    def add(a: int, b: int) -> int:
        return a + b

    return add


def test_default_is_sqlite_file_in_data_dir(settings: Settings) -> None:
    huey = make_huey(settings)
    assert isinstance(huey, SqliteHuey) and huey.name == QUEUE_NAME == "vtdslam"
    assert huey.storage.filename == str(settings.data_dir / "queue.db")
    _define_add(huey)(1, 2)
    assert huey.pending_count() == 1
    # another process's huey (the worker) sees the same queue and runs the task
    worker = make_huey(settings)
    _define_add(worker)
    task = worker.dequeue()
    assert task is not None and task.args == (1, 2)
    assert worker.execute(task) == 3


def test_sqlite_url(settings: Settings, tmp_path: Path) -> None:
    path = tmp_path / "q" / "jobs.db"
    huey = make_huey(settings.model_copy(update={"queue_url": f"sqlite:///{path}"}))
    assert isinstance(huey, SqliteHuey) and huey.storage.filename == str(path)


def test_immediate_mode_for_tests(settings: Settings) -> None:
    huey = make_huey(settings, immediate=True)

    @huey.task()
    def double(x: int) -> int:
        return 2 * x

    assert double(4)() == 8


def test_unknown_scheme(settings: Settings) -> None:
    with pytest.raises(ConfigurationError):
        make_huey(settings.model_copy(update={"queue_url": "amqp://x"}))


def test_redis_url_builds_redis_huey_without_connecting(settings: Settings) -> None:
    huey = make_huey(settings.model_copy(update={"queue_url": "redis://example.invalid:6379/3"}))
    assert isinstance(huey, RedisHuey) and huey.name == "vtdslam"
    kwargs = huey.storage.pool.connection_kwargs
    assert (kwargs["host"], kwargs["port"], kwargs["db"]) == ("example.invalid", 6379, 3)


@pytest.mark.redis
def test_redis_roundtrip(settings: Settings, redis_url: str) -> None:
    huey = make_huey(settings.model_copy(update={"queue_url": redis_url}))

    @huey.task()
    def echo(tag: str) -> str:
        return tag

    tag = uuid.uuid4().hex
    echo(tag)
    # Take tasks until ours: the test database may hold others; leave nothing of ours behind.
    for _ in range(huey.pending_count()):
        task = huey.dequeue()
        if task is not None and task.args == (tag,):
            assert huey.execute(task) == tag
            break
    else:
        pytest.fail("enqueued task not found in Redis")
