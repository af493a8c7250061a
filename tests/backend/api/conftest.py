"""An app on a temp data dir and SQLite, with a recording queue instead of huey."""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from storage.db import make_engine, make_session_factory
from storage.models import JobStatus
from storage.repositories import jobs, metrics
from storage.settings import Settings, get_settings
from tests.backend.api.data import tar_gz, write_sequence


@pytest.fixture(autouse=True)
def _no_vtd_env(no_vtd_env: None) -> None:
    """Every test here runs without a developer's VTD_* variables (tests/conftest.py)."""


class RecordingQueue:
    def __init__(self) -> None:
        self.ids: list[str] = []
        self.fail = False

    def __call__(self, job_id: str) -> None:
        if self.fail:
            raise ConnectionError("queue down")
        self.ids.append(job_id)


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    return get_settings(data_dir=tmp_path / "data", import_root=tmp_path / "imports")


@pytest.fixture
def queue() -> RecordingQueue:
    return RecordingQueue()


@pytest.fixture
def client(settings: Settings, queue: RecordingQueue) -> Iterator[TestClient]:
    with TestClient(create_app(settings, enqueue=queue)) as c:
        yield c


@pytest.fixture(scope="session")
def seq_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_sequence(tmp_path_factory.mktemp("seq") / "rgbd_dataset_test", n=6)


@pytest.fixture(scope="session")
def seq_tgz(seq_folder: Path, tmp_path_factory: pytest.TempPathFactory) -> bytes:
    return tar_gz(seq_folder, tmp_path_factory.mktemp("arch") / "seq.tgz", top="rgbd_dataset_test").read_bytes()


def upload(client: TestClient, data: bytes, *, filename: str = "seq.tgz", camera: str = "tum1",
           name: str | None = None, headers: dict | None = None, allow_duplicate: bool = False):
    form = {"camera": camera}
    if name is not None:
        form["name"] = name
    if allow_duplicate:  # the same archive again (several tests upload one fixture many times)
        form["allow_duplicate"] = "true"
    return client.post("/api/v1/sequences", files={"file": (filename, data, "application/gzip")},
                       data=form, headers=headers or {})


def finish_with_metrics(settings: Settings, runs: dict[str, dict]) -> None:
    """What a worker leaves in the database for each job id of `runs`: claimed, its run metrics saved, succeeded."""
    engine = make_engine(settings)
    with make_session_factory(engine)() as s:
        for job_id, blob in runs.items():
            jobs.claim(s, job_id, "w")
            metrics.save_run_metrics(s, job_id, blob)
            jobs.finish(s, job_id, JobStatus.SUCCEEDED)
    engine.dispose()


def leftovers(settings: Settings) -> list[str]:
    """Files under the data dir other than the database and queue files."""
    root = settings.data_dir
    return sorted(
        p.relative_to(root).as_posix() for p in root.rglob("*")
        if p.is_file() and not p.name.startswith(("vtdslam.db", "queue.db"))
    )
