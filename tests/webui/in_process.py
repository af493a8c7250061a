"""Opening the dashboard's pages in headless Chromium with every request answered in process by the app's
TestClient (no server), for a job whose metrics.json a test writes (`finished_job`). The browser tests of the job
and batch pages share it."""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import pytest
from fastapi.testclient import TestClient

from backend.api.pages import include_dashboard
from backend.app import create_app
from storage.settings import Settings, get_settings
from tests.backend.api.conftest import finish_with_metrics
from tests.backend.api.data import tar_gz, write_sequence
from tests.e2e.conftest import CHROMIUM, CHROMIUM_ARGS

ORIGIN = "http://vtd.test"


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    return get_settings(data_dir=tmp_path / "data")


@pytest.fixture
def client(settings: Settings) -> Iterator[TestClient]:
    app = create_app(settings, enqueue=lambda job_id: None)
    include_dashboard(app)
    with TestClient(app) as c:
        yield c


def finished_job(client: TestClient, settings: Settings, tmp_path: Path, blob: dict, camera: str) -> tuple[str, str]:
    """(job id, batch id) of a succeeded `full` job on a small uploaded sequence whose run metrics are `blob`."""
    folder = write_sequence(tmp_path / "bonn_like", n=4, camera_json=False)
    archive = tar_gz(folder, tmp_path / "b.tgz", top="bonn_like").read_bytes()
    r = client.post("/api/v1/sequences", files={"file": ("b.tgz", archive, "application/gzip")},
                    data={"camera": camera, "name": "bonn_like"})
    assert r.status_code == 201, r.text
    batch = client.post("/api/v1/batches", json={"sequence_ids": [r.json()["id"]], "presets": ["full"]}).json()
    job_id = batch["jobs"][0]["id"]
    finish_with_metrics(settings, {job_id: blob})
    return job_id, batch["id"]


@contextmanager
def app_page(playwright_api: Any, client: TestClient) -> Iterator[Any]:
    """A Chromium page whose requests to `ORIGIN` the app answers in process; fails the test on a page error."""
    errors: list[str] = []
    with playwright_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        try:
            page = browser.new_page()
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.route(f"{ORIGIN}/**", _answer(client))
            yield page
        finally:
            browser.close()
    assert not errors, errors


def _answer(client: TestClient):  # noqa: ANN202 - a Playwright route handler
    def answer(route) -> None:  # noqa: ANN001
        req = route.request
        url = urlsplit(req.url)
        r = client.request(req.method, url.path + (f"?{url.query}" if url.query else ""),
                           headers={k: v for k, v in req.headers.items() if k.lower() != "host"})
        route.fulfill(status=r.status_code, headers=dict(r.headers), body=r.content)
    return answer
