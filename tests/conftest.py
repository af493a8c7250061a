"""Shared fixtures: where the real data lives (../shared, or VTD_SHARED_DIR) and skips when it is absent; an
environment without a developer's VTD_* variables (folders and modules that need it turn it on)."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def shared_dir() -> Path:
    return Path(os.environ.get("VTD_SHARED_DIR", ROOT.parent / "shared")).resolve()


@pytest.fixture(scope="session")
def shared() -> Path:
    path = shared_dir()
    if not (path / "data").is_dir():
        pytest.skip(f"real data not found at {path} (set VTD_SHARED_DIR); a user's fresh machine has none")
    return path


@pytest.fixture(scope="session")
def redkitchen(shared: Path) -> Path:
    path = shared / "data" / "7scenes_redkitchen"
    if not (path / "rgb.txt").is_file():
        pytest.skip(f"{path} not present")
    return path


@pytest.fixture(scope="session")
def bonn_dev(shared: Path) -> Path:
    """bonn_crowd_dev: evaluation only (DATA.md)."""
    path = shared / "data" / "bonn_crowd_dev"
    if not (path / "rgb.txt").is_file():
        pytest.skip(f"{path} not present")
    return path


@pytest.fixture
def no_vtd_env(monkeypatch: pytest.MonkeyPatch) -> None:
    """A developer's or CI's VTD_* variables must not redirect tests to real data (VTD_TEST_* stay)."""
    for key in list(os.environ):
        if key.startswith("VTD_") and not key.startswith("VTD_TEST_"):
            monkeypatch.delenv(key)
