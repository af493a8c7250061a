"""The real Chromium the browser tests drive (Debian's; Playwright never downloads one) and where their
screenshots go."""
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


@pytest.fixture(scope="module")
def shots(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Where screenshots go: ``$VTD_SCREENSHOT_DIR`` or a temp folder (its path is printed)."""
    d = Path(os.environ.get("VTD_SCREENSHOT_DIR") or tmp_path_factory.mktemp("screenshots"))
    d.mkdir(parents=True, exist_ok=True)
    print(f"\nscreenshots in {d}")
    return d
