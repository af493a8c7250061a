"""The job and batch pages label ATE and RPE with what they were measured against (headless Chromium).

Every request of the page is answered in process by the app's TestClient (`tests/webui/in_process.py`), for a job
whose metrics.json is a Bonn run's: ATE against the raw marker ground truth and corrected, RPE per second and per
frame against the camera's ground truth. Skipped without Playwright or Chromium.
"""
from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from storage.settings import Settings
from tests.e2e.conftest import playwright_api  # noqa: F401 (a fixture)
from tests.webui.in_process import ORIGIN, app_page, client, finished_job, settings  # noqa: F401 (fixtures)

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


TUM = {**{k: v for k, v in BONN.items() if not k.endswith("_against") and k != "groundtruth_frame"},
       "groundtruth_frame": "camera", "ate_against": "camera", "ate_corrected_against": "camera",
       "rpe_against": "camera", "ate_corrected": BONN["ate"]}


def test_job_and_batch_pages_label_the_figures(playwright_api, client: TestClient,  # noqa: F811
                                               settings: Settings, tmp_path: Path) -> None:  # noqa: F811
    job_id, batch_id = finished_job(client, settings, tmp_path, BONN, "bonn")
    tum_job, _ = finished_job(client, settings, tmp_path / "tum", TUM, "tum3")
    with app_page(playwright_api, client) as page:
        page.goto(f"{ORIGIN}/jobs/{tum_job}")  # camera ground truth: one ATE, no note
        playwright_api.expect(page.locator("#metrics-table")).to_contain_text("per frame), against camera")
        assert "ATE corrected" not in page.locator("#metrics-table").inner_text()
        assert page.locator("#metrics-gt-frame").count() == 0

        page.goto(f"{ORIGIN}/jobs/{job_id}")
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

        page.goto(f"{ORIGIN}/batches/{batch_id}")
        playwright_api.expect(page.locator("#batch-gt-frame")).to_contain_text("bonn_like (bonn-marker)")
        page.select_option("#metric", "ate_corrected_rmse")
        playwright_api.expect(page.locator("#compare")).to_contain_text("0.0164")
        page.select_option("#metric", "rpe_frame_rot_rmse")
        playwright_api.expect(page.locator("#compare")).to_contain_text("0.366")
