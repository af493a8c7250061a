"""A run's 3D viewer and the API docs in headless Chromium, with the service on a non-loopback-default host.

`vtdslam serve --host 127.0.0.2 --no-worker` (a second loopback address: Linux routes all of 127/8 without
setup) stands in for a LAN address: nothing may listen on 127.0.0.1, and the browser must reach the run's
viser scene through the api's own origin (``/viewer/{job_id}/`` and its WebSocket), one port only.
``/docs`` and ``/redoc`` must render with every request off that origin aborted (offline).

No worker: the run's artifacts are written straight into the data dir, which is all the viewer reads.
Needs Playwright's Python package and Debian's ``chromium``; skipped without them.
"""
from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import pytest

from storage.artifacts import ArtifactStore
from tests.backend.api.data import tar_gz, write_sequence
from tests.e2e.conftest import CHROMIUM, CHROMIUM_ARGS
from tests.e2e.services import ServiceProcesses, listening
from tests.webui.test_viewer import write_run

HOST = "127.0.0.2"
SCENE_TIMEOUT_MS = 60_000  # viser's first scene messages; SwiftShader and a shared CPU are slow
SESSION_HOLD_S = 65  # past six of the api's 10 s header timeouts (issue 60.1: a reconnect every 10 s)

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory, playwright_api) -> Iterator[ServiceProcesses]:
    """`vtdslam serve --host HOST --no-worker` on free ports of HOST and a temp data dir."""
    with ServiceProcesses(tmp_path_factory.mktemp("proxy"), HOST) as svc:
        svc.spawn("-m", "cli.main", "serve", "--host", HOST, "--port", str(svc.port), "--no-worker")
        svc.wait_until("the service", lambda: listening(HOST, svc.port) and listening(HOST, svc.viewer_port))
        yield svc


@pytest.fixture(scope="module")
def job_id(service: ServiceProcesses, tmp_path_factory: pytest.TempPathFactory) -> str:
    """A queued job (no worker runs it) whose run artifacts are in place, as a finished run leaves them."""
    tmp = tmp_path_factory.mktemp("seq")
    archive = tar_gz(write_sequence(tmp / "rgbd_dataset_proxy", n=3), tmp / "s.tgz", top="rgbd_dataset_proxy")
    with httpx.Client(base_url=f"{service.base}/api/v1", timeout=30) as api:
        r = api.post("/sequences", files={"file": ("s.tgz", archive.read_bytes(), "application/gzip")},
                     data={"camera": "tum1"})
        assert r.status_code == 201, r.text
        r = api.post("/jobs", json={"sequence_id": r.json()["id"], "preset": "orb-only"})
        assert r.status_code == 201, r.text
    job = r.json()["id"]
    write_run(ArtifactStore(service.data_dir).job_dir(job))
    return job


@pytest.fixture
def page(playwright_api, service: ServiceProcesses) -> Iterator[tuple[object, list[str], list[str]]]:
    """A Chromium page, the console errors and page errors it logs, and every URL it requested."""
    errors: list[str] = []
    requested: list[str] = []
    with playwright_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        pg = browser.new_page()
        pg.on("console", lambda msg: errors.append(msg.text) if msg.type == "error" else None)
        pg.on("pageerror", lambda exc: errors.append(str(exc)))
        pg.on("request", lambda req: requested.append(req.url))
        try:
            yield pg, errors, requested
        finally:
            browser.close()


def _off_origin(urls: list[str], service: ServiceProcesses) -> list[str]:
    own = f"{HOST}:{service.port}"
    return [u for u in urls if urlsplit(u).scheme in ("http", "https", "ws", "wss") and urlsplit(u).netloc != own]


def test_everything_binds_the_host_it_was_told(service: ServiceProcesses) -> None:
    assert listening(HOST, service.port) and listening(HOST, service.viewer_port)
    assert not listening("127.0.0.1", service.port) and not listening("127.0.0.1", service.viewer_port)


def test_the_runs_viewer_opens_through_the_apis_origin(page, service: ServiceProcesses, job_id: str,
                                                       shots: Path) -> None:
    pg, errors, requested = page
    r = httpx.get(f"{service.base}/api/v1/jobs/{job_id}/viewer", timeout=30)
    assert r.status_code == 200, r.text
    url = r.json()["url"]
    assert url == f"/viewer/{job_id}/"
    frames: list[int] = []
    sockets: list[str] = []

    def on_socket(ws) -> None:  # noqa: ANN001 (Playwright's WebSocket)
        sockets.append(ws.url)
        ws.on("framereceived", lambda payload: frames.append(len(payload)))

    pg.on("websocket", on_socket)
    pg.goto(service.base + url, wait_until="load")
    deadline = time.monotonic() + SCENE_TIMEOUT_MS / 1000
    while not frames and time.monotonic() < deadline:
        pg.wait_for_timeout(250)
    assert frames, f"no scene message through the proxy; sockets {sockets}, errors {errors}\n{service.tail()}"
    assert sockets == [f"ws://{HOST}:{service.port}/viewer/{job_id}"]
    pg.wait_for_selector("canvas", timeout=SCENE_TIMEOUT_MS)
    # the run's own controls, built by the hub's scene code, arrived over the proxied socket
    pg.get_by_text(f"Run {job_id[:8]}", exact=True).wait_for(timeout=SCENE_TIMEOUT_MS)
    pg.get_by_text("Ground truth", exact=True).wait_for(timeout=SCENE_TIMEOUT_MS)
    pg.wait_for_timeout(2000)  # let the first frames render before judging the console
    pg.screenshot(path=str(shots / "viewer_through_api_origin.png"))
    assert not _off_origin(requested + sockets, service)
    assert not errors, errors


def test_a_viewer_session_through_the_api_holds_a_minute(page, service: ServiceProcesses, job_id: str) -> None:
    """One socket for the whole session: never closed, never reopened (the page's reconnects would open more)."""
    pg, errors, _requested = page
    sockets: list[str] = []
    closed: list[str] = []
    frames: list[float] = []

    def on_socket(ws) -> None:  # noqa: ANN001 (Playwright's WebSocket)
        sockets.append(ws.url)
        ws.on("close", lambda w: closed.append(w.url))
        ws.on("socketerror", lambda err: closed.append(f"error: {err}"))
        ws.on("framereceived", lambda _payload: frames.append(time.monotonic()))

    pg.on("websocket", on_socket)
    pg.goto(f"{service.base}/viewer/{job_id}/", wait_until="load")
    deadline = time.monotonic() + SCENE_TIMEOUT_MS / 1000
    while not frames and time.monotonic() < deadline:
        pg.wait_for_timeout(250)
    assert frames, f"no scene message through the proxy; sockets {sockets}, errors {errors}\n{service.tail()}"
    opened = time.monotonic()
    while time.monotonic() - opened < SESSION_HOLD_S:
        pg.wait_for_timeout(1000)
        assert not closed, f"the viewer's socket closed after {time.monotonic() - opened:.1f} s: {closed}"
    assert sockets == [f"ws://{HOST}:{service.port}/viewer/{job_id}"], sockets  # zero reconnects
    pg.get_by_text(f"Run {job_id[:8]}", exact=True).wait_for(timeout=5_000)  # the scene is still live
    assert not errors, errors


@pytest.mark.parametrize(("path", "rendered"), [("/docs", ".swagger-ui .opblock"), ("/redoc", "[role=menuitem]")])
def test_api_docs_render_offline(page, service: ServiceProcesses, path: str, rendered: str) -> None:
    pg, errors, requested = page
    blocked: list[str] = []

    def only_local(route) -> None:  # noqa: ANN001 (Playwright's Route)
        if urlsplit(route.request.url).hostname == HOST:
            route.continue_()
        else:
            blocked.append(route.request.url)
            route.abort()

    pg.route("**/*", only_local)
    pg.goto(service.base + path, wait_until="load")
    pg.wait_for_selector(rendered, timeout=30_000)
    assert "VTD-SLAM" in pg.title()
    assert blocked == [] and not _off_origin(requested, service)
    assert not errors, errors


def test_the_dashboards_api_link_opens_the_docs_offline(page, service: ServiceProcesses) -> None:
    pg, errors, requested = page
    pg.route("**/*", lambda route: route.continue_() if urlsplit(route.request.url).hostname == HOST
             else route.abort())
    pg.goto(service.base + "/", wait_until="load")
    pg.get_by_role("link", name="API", exact=True).click()
    pg.wait_for_selector(".swagger-ui .opblock", timeout=30_000)
    assert urlsplit(pg.url).path == "/docs"
    assert not _off_origin(requested, service)
    assert not errors, errors
