"""Markers of the end-to-end tests (registered here too, so running this folder alone knows them)."""
from __future__ import annotations

import pytest


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "postgres: needs PostgreSQL at 127.0.0.1:5432 (skipped when absent)")
    config.addinivalue_line("markers", "redis: needs Redis at 127.0.0.1:6379 (skipped when absent)")
