"""Markers of the end-to-end tests (registered here too, so running this folder alone knows them), and the
real Chromium the browser tests drive (Debian's; Playwright never downloads one)."""
from __future__ import annotations

import os
from pathlib import Path
from types import ModuleType

import pytest

CHROMIUM = os.environ.get("VTD_TEST_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--enable-unsafe-swiftshader"]


@pytest.fixture(scope="module")
def playwright_api() -> ModuleType:
    """playwright.sync_api, or a skip with the reason (no package, no Chromium)."""
    api = pytest.importorskip("playwright.sync_api", reason="Playwright's Python package is not installed")
    if not Path(CHROMIUM).exists():
        pytest.skip(f"no Chromium at {CHROMIUM} (apt-get install chromium)")
    return api


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "postgres: needs PostgreSQL at 127.0.0.1:5432 (skipped when absent)")
    config.addinivalue_line("markers", "redis: needs Redis at 127.0.0.1:6379 (skipped when absent)")
