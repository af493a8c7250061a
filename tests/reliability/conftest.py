"""Fixtures of the reliability tests: a clean environment, a data dir with its api, worker processes."""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from storage.settings import Settings, get_settings
from tests.reliability.procs import Procs


@pytest.fixture(autouse=True)
def _no_vtd_env(no_vtd_env: None) -> None:
    """Every test here runs without a developer's VTD_* variables (tests/conftest.py)."""


@pytest.fixture
def procs(tmp_path: Path) -> Iterator[Procs]:
    group = Procs(tmp_path / "logs")
    try:
        yield group
    finally:
        group.close()


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    return get_settings(data_dir=tmp_path / "data")


def api_client(settings: Settings) -> TestClient:
    """The api in this process on ``settings`` (enqueueing to their queue): use as a context manager."""
    from backend.app import create_app

    return TestClient(create_app(settings), raise_server_exceptions=False)
