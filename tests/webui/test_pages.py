"""The dashboard's pages, static assets and the viewer endpoint, through FastAPI's TestClient."""
from __future__ import annotations

import json
import re
import socket
import threading
import time
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from backend.api.pages import STATIC_DIR, include_dashboard
from backend.api.viewer import ViewerUnavailable, ask_hub
from backend.app import create_app
from storage.settings import Settings, get_settings
from tests.backend.api.data import tar_gz, write_sequence
from webui.viewer.hub import QuietHTTPServer

PAGE_WEIGHT_BUDGET = 80_000
"""Bytes of the job page with its CSS and scripts (uncompressed): no frameworks, no bundles."""

pytestmark = pytest.mark.usefixtures("no_vtd_env")  # tests/conftest.py


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class FakeHub:
    """A stand-in for `vtdslam viewer`'s control API: answers GET /runs/{id} like the real hub."""

    def __init__(self, status: int = 200, body: dict | None = None, delay_s: float = 0.0) -> None:
        self.status, self.body, self.delay_s = status, body, delay_s
        self.paths: list[str] = []  # request paths, in arrival order
        hub = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802
                hub.paths.append(self.path)
                time.sleep(hub.delay_s)
                job_id = self.path.rsplit("/", 1)[-1]
                payload = json.dumps(hub.body or {"job_id": job_id, "port": 45678}).encode()
                self.send_response(hub.status)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(payload)))
                self.end_headers()
                self.wfile.write(payload)

            def log_message(self, *args: object) -> None:
                pass

        self.server = QuietHTTPServer(("127.0.0.1", 0), Handler)
        # join slow handlers on close, so none writes to stderr while a later test captures it
        self.server.daemon_threads, self.server.block_on_close = False, True
        self.port = self.server.server_address[1]
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    def __enter__(self) -> FakeHub:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.server.shutdown()
        self.server.server_close()


def _client(settings: Settings) -> TestClient:
    app = create_app(settings, enqueue=lambda job_id: None)
    include_dashboard(app)
    return TestClient(app)


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    return get_settings(data_dir=tmp_path / "data", viewer_port=_free_port())  # nothing listens there


@pytest.fixture
def client(settings: Settings) -> Iterator[TestClient]:
    with _client(settings) as c:
        yield c


@pytest.fixture(scope="module")
def seq_tgz(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    folder = write_sequence(tmp_path_factory.mktemp("seq") / "rgbd_dataset_web", n=4)
    return tar_gz(folder, tmp_path_factory.mktemp("arch") / "seq.tgz", top="rgbd_dataset_web").read_bytes()


def _job(client: TestClient, seq_tgz: bytes) -> str:
    r = client.post("/api/v1/sequences", files={"file": ("seq.tgz", seq_tgz, "application/gzip")},
                    data={"camera": "tum1"})
    assert r.status_code == 201, r.text
    r = client.post("/api/v1/jobs", json={"sequence_id": r.json()["id"], "preset": "orb-only"})
    assert r.status_code == 201, r.text
    return r.json()["id"]


PAGES = {
    "/": "sequences.js",
    "/sequences": "sequences.js",
    "/jobs": "jobs.js",
    "/jobs/0123456789abcdef": "job.js",
    "/batches/0123456789abcdef": "batch.js",
}


@pytest.mark.parametrize("path", list(PAGES))
def test_every_page_renders(client: TestClient, path: str) -> None:
    r = client.get(path)
    assert r.status_code == 200
    assert r.headers["content-type"].startswith("text/html")
    html = r.text
    assert "<title>" in html and "/static/css/app.css" in html and "/static/js/app.js" in html
    assert f"/static/js/{PAGES[path]}" in html
    assert "http://" not in html.replace("http://www.w3.org", "")  # nothing from another origin (no CDN)


def test_first_page_shows_runs_before_sequences(client: TestClient) -> None:
    html = client.get("/").text
    assert html.index('id="active-runs"') < html.index('id="recent-runs"') < html.index('id="seq-table"')
    assert "/static/js/activity.js" in html and 'href="/jobs"' in html


def test_batch_page_has_plots_truth_and_the_same_result_note(client: TestClient) -> None:
    html = client.get("/batches/0123456789abcdef").text
    for box in ("plot-ate", "plot-rpe", "plot-fps", "plot-traj", "truth-compare"):
        assert f'id="{box}"' in html
    for metric in ("mask_iou", "feature_precision", "feature_recall", "restoration_psnr", "relocalisations"):
        assert f'<option value="{metric}"' in html
    note = html[html.index('id="same-results"'):]
    assert "restoration.restored_features" in note and "features_removed" in note
    # the note says full and no-restoration track alike because restored features are off by default
    from worker.slam.presets import get_preset

    assert get_preset("full").section("restoration").restored_features is False
    assert get_preset("no-restoration").stages + ["restoration"] == get_preset("full").stages
    assert get_preset("geometry-only").stages == ["culling"] and get_preset("orb-only").stages == []


def test_wide_tables_scroll_inside_their_card(client: TestClient) -> None:
    for path in PAGES:
        html = client.get(path).text
        tables = html.count("<table")
        assert tables == len(re.findall(r'<div class="scroll">\s*<table', html)), path


def test_sequences_page_offers_the_presets(client: TestClient) -> None:
    html = client.get("/sequences").text
    for camera in ("tum1", "tum3", "bonn", "7scenes"):
        assert f'<option value="{camera}"' in html
    assert 'value="orb-only"' in html and 'type="file"' in html


def test_ids_in_urls_are_escaped(client: TestClient) -> None:
    r = client.get('/jobs/"><img src=x onerror=alert(1)>')
    assert r.status_code == 200
    assert "<img" not in r.text and "&#34;&gt;&lt;img" in r.text


@pytest.mark.parametrize("name,ctype", [
    ("css/app.css", "text/css"), ("js/app.js", "javascript"), ("js/sequences.js", "javascript"),
    ("js/jobs.js", "javascript"), ("js/job.js", "javascript"), ("js/batch.js", "javascript"),
    ("js/activity.js", "javascript"), ("js/plot.js", "javascript"), ("js/batch_plots.js", "javascript"),
    ("js/live.js", "javascript"), ("js/classes.js", "javascript"),
])
def test_static_assets_are_served(client: TestClient, name: str, ctype: str) -> None:
    r = client.get(f"/static/{name}")
    assert r.status_code == 200 and ctype in r.headers["content-type"]
    assert r.content == (STATIC_DIR / name).read_bytes()


def test_unknown_static_asset_is_404(client: TestClient) -> None:
    assert client.get("/static/js/nope.js").status_code == 404


def test_pages_stay_out_of_the_api_schema(client: TestClient) -> None:
    paths = client.get("/openapi.json").json()["paths"]
    assert "/api/v1/jobs/{job_id}/viewer" in paths
    assert "/jobs/{job_id}" not in paths and "/" not in paths


def test_include_dashboard_twice_is_harmless(settings: Settings) -> None:
    app = create_app(settings, enqueue=lambda job_id: None)
    include_dashboard(app)
    n = len(app.routes)
    include_dashboard(app)
    assert len(app.routes) == n


def test_job_page_weight(client: TestClient) -> None:
    html = client.get("/jobs/0123456789abcdef")
    assets = re.findall(r'(?:href|src)="(/static/[^"?]+)', html.text)
    assert len(assets) == 6  # app.css, app.js, plot.js, classes.js, job.js, live.js
    sizes = {a: len(client.get(a).content) for a in assets}
    total = len(html.content) + sum(sizes.values())
    print(f"\njob page weight: {total} bytes (html {len(html.content)}, " +
          ", ".join(f"{Path(a).name} {n}" for a, n in sizes.items()) + ")")
    assert total < PAGE_WEIGHT_BUDGET


def test_viewer_is_503_when_the_hub_is_down(client: TestClient, seq_tgz: bytes) -> None:
    job_id = _job(client, seq_tgz)
    r = client.get(f"/api/v1/jobs/{job_id}/viewer")
    assert r.status_code == 503
    err = r.json()["error"]
    assert err["code"] == "viewer_unavailable" and "vtdslam viewer" in err["message"]


def test_viewer_of_an_unknown_job_is_404(client: TestClient) -> None:
    r = client.get("/api/v1/jobs/nosuchjob/viewer")
    assert r.status_code == 404 and r.json()["error"]["code"] == "not_found"


def test_viewer_url_is_on_the_apis_own_origin(tmp_path: Path, seq_tgz: bytes) -> None:
    with FakeHub() as hub:
        settings = get_settings(data_dir=tmp_path / "data", viewer_port=hub.port)
        with _client(settings) as client:
            job_id = _job(client, seq_tgz)
            r = client.get(f"/api/v1/jobs/{job_id}/viewer")
            assert r.status_code == 200, r.text
            # a path, not the run server's port: whoever reaches the api reaches the viewer (one port)
            assert r.json() == {"url": f"/viewer/{job_id}/"}
    assert hub.paths == [f"/runs/{job_id}"]


def test_viewer_passes_on_the_hubs_refusal(tmp_path: Path, seq_tgz: bytes) -> None:
    refusal = {"error": {"code": "not_found", "message": "run has no trajectory yet", "detail": None}}
    with FakeHub(status=404, body=refusal) as hub:
        settings = get_settings(data_dir=tmp_path / "data", viewer_port=hub.port)
        with _client(settings) as client:
            r = client.get(f"/api/v1/jobs/{_job(client, seq_tgz)}/viewer")
    assert r.status_code == 404
    err = r.json()["error"]
    assert err.pop("request_id") and err == refusal["error"]  # the hub's words, with this request's id


def test_viewer_hub_error_is_503(tmp_path: Path, seq_tgz: bytes) -> None:
    with FakeHub(status=500, body={"oops": 1}) as hub:
        settings = get_settings(data_dir=tmp_path / "data", viewer_port=hub.port)
        with _client(settings) as client:
            r = client.get(f"/api/v1/jobs/{_job(client, seq_tgz)}/viewer")
    assert r.status_code == 503 and r.json()["error"]["code"] == "viewer_unavailable"


def test_a_hub_that_hangs_times_out_in_words() -> None:
    with FakeHub(delay_s=2.0) as hub:
        with pytest.raises(ViewerUnavailable, match="did not answer within 0.3 s"):
            ask_hub(f"http://127.0.0.1:{hub.port}", "job1", timeout=0.3)
