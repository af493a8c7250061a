"""The job page shows the run's segmentation classes: the legend in the palette's colours, each class's share of the
frames and, with truth, the recall per true mover class (headless Chromium; skipped without it)."""
from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient

from storage.settings import Settings
from tests.e2e.conftest import playwright_api  # noqa: F401 (a fixture)
from tests.webui.in_process import ORIGIN, app_page, client, finished_job, settings  # noqa: F401 (fixtures)
from tests.webui.test_metrics_labels_browser import TUM

SEGMENTATION = {
    "source": "network", "backend": "tflite-teacher", "classes": ["background", "person", "car", "sofa"],
    "dynamic_classes": ["person", "car"], "frames": 20,
    "class_share": {"person": 0.1234, "car": 0.031}, "other_class_share": {"sofa": 0.02},
    "legend": [{"name": "person", "colour": "#c08080", "dynamic": True},
               {"name": "car", "colour": "#808080", "dynamic": True},
               {"name": "sofa", "colour": "#00c000", "dynamic": False}],
    "truth": {"frames_scored": 20, "recall_by_class": {"dog": {"recall": 0.5, "pixels": 800},
                                                       "person": {"recall": 0.9, "pixels": 1000}}},
}
CULLING = {"features_removed": 3, "truth": {"mask_iou": 0.5, "mask_recall_by_class": {
    "dog": {"recall": 0.25, "pixels": 700}, "person": {"recall": 0.8, "pixels": 900}}}}


def test_the_job_page_lists_the_classes_in_their_colours(playwright_api, client: TestClient,  # noqa: F811
                                                         settings: Settings, tmp_path: Path) -> None:  # noqa: F811
    job_id, _ = finished_job(client, settings, tmp_path, {**TUM, "segmentation": SEGMENTATION, "culling": CULLING},
                             "tum3")
    with app_page(playwright_api, client) as page:
        page.goto(f"{ORIGIN}/jobs/{job_id}")
        card = page.locator("#classes-card")
        playwright_api.expect(card).to_be_visible()
        playwright_api.expect(card).to_contain_text("potentially dynamic: person, car")
        items = page.locator("#classes-legend li")
        assert items.all_inner_texts() == ["person", "car", "sofa (not masked)"]
        swatch = page.locator("#classes-legend .swatch").first
        assert swatch.evaluate("e => getComputedStyle(e).backgroundColor") == "rgb(192, 128, 128)"
        share = page.locator("#class-share").inner_text()
        assert "12.3 %" in share and "3.1 %" in share and "seen, not masked" in share
        by_class = page.locator("#truth-by-class")
        playwright_api.expect(by_class).to_contain_text("dog")
        rows = by_class.locator("tbody tr").all_inner_texts()
        assert rows[0].split("\t") == ["dog", "50.0 %", "25.0 %", "800"]
        assert rows[1].split("\t") == ["person", "90.0 %", "80.0 %", "1000"]
        swatches = by_class.locator("tbody tr td:first-child .swatch")
        assert swatches.count() == 1  # person is in the run's legend, the dog (a class it lacks) is not
