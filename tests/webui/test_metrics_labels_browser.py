"""The job and batch pages label ATE and RPE with what they were measured against (headless Chromium).

Every request of the page is answered in process by the app's TestClient (no server), for a job whose
metrics.json is a Bonn run's: ATE against the raw marker ground truth and corrected, RPE per second and per
frame against the camera's ground truth. Skipped without Playwright or Chromium.
"""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlsplit

import pytest
from fastapi.testclient import TestClient

from backend.api.pages import include_dashboard
from backend.app import create_app
from storage.db import make_engine, make_session_factory
from storage.models import JobStatus
from storage.repositories import jobs, metrics
from storage.settings import Settings, get_settings
from tests.backend.api.data import tar_gz, write_sequence
from tests.e2e.conftest import CHROMIUM, CHROMIUM_ARGS, playwright_api  # noqa: F401 (a fixture)

pytestmark = pytest.mark.usefixtures("no_vtd_env")  # tests/conftest.py

CORRECTED = "camera (corrected from bonn-marker)"
STATS = {"rmse": 0.0207, "mean": 0.0187, "median": 0.0174, "std": 0.009, "max": 0.0569}
BONN = {
    "frames": 20, "tracked": 20, "lost": 0,
    "ate": {**STATS, "rmse": 0.0160}, "matched_poses": 20,
    "rpe": {"mode": "fixed-delta", "delta_s": 1.0, "max_pairs": 0, "pairs": 10, "trans": STATS,
            "rot_deg": {**STATS, "rmse": 0.587}},
    "groundtruth_frame": "bonn-marker", "ate_against": "bonn-marker (raw ground truth, published convention)",
    "ate_corrected_against": CORRECTED, "rpe_against": CORRECTED, "ate_corrected": {**STATS, "rmse": 0.0164},
    "rpe_frame": {"mode": "fixed-frames", "delta_s": None, "max_pairs": 0, "pairs": 18, "delta_frames": 1,
                  "trans": {**STATS, "rmse": 0.0117}, "rot_deg": {**STATS, "rmse": 0.366}},
}


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    return get_settings(data_dir=tmp_path / "data")


@pytest.fixture
def client(settings: Settings) -> Iterator[TestClient]:
    app = create_app(settings, enqueue=lambda job_id: None)
    include_dashboard(app)
    with TestClient(app) as c:
        yield c


TUM = {**{k: v for k, v in BONN.items() if not k.endswith("_against") and k != "groundtruth_frame"},
       "groundtruth_frame": "camera", "ate_against": "camera", "ate_corrected_against": "camera",
       "rpe_against": "camera", "ate_corrected": BONN["ate"]}


def _bonn_batch(client: TestClient, settings: Settings, tmp_path: Path, blob: dict = BONN,
                camera: str = "bonn") -> tuple[str, str]:
    folder = write_sequence(tmp_path / "bonn_like", n=4, camera_json=False)
    archive = tar_gz(folder, tmp_path / "b.tgz", top="bonn_like").read_bytes()
    r = client.post("/api/v1/sequences", files={"file": ("b.tgz", archive, "application/gzip")},
                    data={"camera": camera, "name": "bonn_like"})
    assert r.status_code == 201, r.text
    batch = client.post("/api/v1/batches", json={"sequence_ids": [r.json()["id"]], "presets": ["full"]}).json()
    job_id = batch["jobs"][0]["id"]
    engine = make_engine(settings)
    with make_session_factory(engine)() as s:
        jobs.claim(s, job_id, "w")
        metrics.save_run_metrics(s, job_id, blob)
        jobs.finish(s, job_id, JobStatus.SUCCEEDED)
    engine.dispose()
    return job_id, batch["id"]


def _answer(client: TestClient):
    def answer(route) -> None:
        req = route.request
        url = urlsplit(req.url)
        r = client.request(req.method, url.path + (f"?{url.query}" if url.query else ""),
                           headers={k: v for k, v in req.headers.items() if k.lower() != "host"})
        route.fulfill(status=r.status_code, headers=dict(r.headers), body=r.content)
    return answer


def test_job_and_batch_pages_label_the_figures(playwright_api, client: TestClient,  # noqa: F811
                                               settings: Settings, tmp_path: Path) -> None:
    job_id, batch_id = _bonn_batch(client, settings, tmp_path)
    tum_job, _ = _bonn_batch(client, settings, tmp_path / "tum", TUM, "tum3")
    errors: list[str] = []
    with playwright_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        try:
            page = browser.new_page()
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.route("http://vtd.test/**", _answer(client))
            page.goto(f"http://vtd.test/jobs/{tum_job}")  # camera ground truth: one ATE, no note
            playwright_api.expect(page.locator("#metrics-table")).to_contain_text("per frame), against camera")
            assert "ATE corrected" not in page.locator("#metrics-table").inner_text()
            assert page.locator("#metrics-gt-frame").count() == 0

            page.goto(f"http://vtd.test/jobs/{job_id}")
            table = page.locator("#metrics-table")
            playwright_api.expect(table).to_contain_text("ATE corrected (m), against " + CORRECTED)
            text = table.inner_text()
            assert "ATE, absolute trajectory error (m), against bonn-marker (raw ground truth, published " \
                   "convention)" in text
            assert f"RPE translation (m per 1 s), against {CORRECTED}" in text
            assert f"RPE rotation (° per frame), against {CORRECTED}" in text
            assert "0.0164" in text and "0.0117" in text and "0.366" in text
            playwright_api.expect(page.locator("#metrics-gt-frame")).to_contain_text("not of the camera")
            playwright_api.expect(page.locator("#facts")).to_contain_text("yes, the bonn-marker's pose")

            page.goto(f"http://vtd.test/batches/{batch_id}")
            playwright_api.expect(page.locator("#batch-gt-frame")).to_contain_text("bonn_like (bonn-marker)")
            page.select_option("#metric", "ate_corrected_rmse")
            playwright_api.expect(page.locator("#compare")).to_contain_text("0.0164")
            page.select_option("#metric", "rpe_frame_rot_rmse")
            playwright_api.expect(page.locator("#compare")).to_contain_text("0.366")
        finally:
            browser.close()
    assert not errors, errors
