"""The dashboard in headless Chromium against real processes (api + worker + viewer) on a temp data dir.

Through the pages only: upload a generated sequence (drag-and-drop input, progress), see a refused upload's
error in words, start a job, follow it live to the end, check the job page's metrics table and SVG plots,
open the embedded 3D viewer (≥ 10 s of real time for SwiftShader's WebGL), run a batch and read its table.
Screenshots of every page go to ``$VTD_SCREENSHOT_DIR`` (default: a temp folder printed by the test); the
job page's time to first render and page weight on loopback are printed.

Needs Playwright's Python package and Debian's ``chromium`` (``/usr/bin/chromium``); skipped without them.
"""
from __future__ import annotations

import inspect
import os
import signal
import socket
import subprocess
import sys
import time
import zipfile
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = os.environ.get("VTD_TEST_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--enable-unsafe-swiftshader"]
JOB_TIMEOUT_MS = 300_000  # the pipeline runs on a shared CPU
VIEWER_WAIT_S = 12
UPLOAD_BYTES_PER_S = 16 * 1024 * 1024
TIMING_RUNS = 5

pytestmark = pytest.mark.slow


def dashboard_app():
    """`create_app` with the dashboard, whether or not the factory already includes it (uvicorn factory)."""
    from backend.api.pages import include_dashboard
    from backend.app import create_app

    app = create_app()
    include_dashboard(app)
    return app


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _dashboard_in_factory() -> bool:
    import backend.app

    return "include_dashboard" in inspect.getsource(backend.app)


class Processes:
    """`vtdslam serve` (api + worker + viewer) when create_app includes the dashboard; otherwise the api
    through :func:`dashboard_app`, `vtdslam worker` and `vtdslam viewer` as three processes."""

    def __init__(self, tmp: Path) -> None:
        self.port, self.viewer_port = _free_port(), _free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        clean = {k: v for k, v in os.environ.items() if not k.startswith("VTD_") or k.startswith("VTD_TEST_")}
        self.env = {**clean, "VTD_DATA_DIR": str(tmp / "data"), "VTD_PORT": str(self.port),
                    "VTD_VIEWER_PORT": str(self.viewer_port), "PYTHONUNBUFFERED": "1"}
        self.log_path = tmp / "service.log"
        self.procs: list[tuple[subprocess.Popen, int]] = []

    def _spawn(self, args: list[str], stop_signal: int) -> None:
        p = subprocess.Popen([sys.executable, *args], cwd=ROOT, env=self.env, stdout=self.log,
                             stderr=subprocess.STDOUT, start_new_session=True)
        self.procs.append((p, stop_signal))

    def start(self) -> None:
        self.log = open(self.log_path, "wb")
        if _dashboard_in_factory():
            self._spawn(["-m", "cli.main", "serve"], signal.SIGINT)
            self._wait_api()
        else:
            self._spawn(["-m", "uvicorn", "tests.e2e.test_dashboard_browser:dashboard_app", "--factory",
                         "--host", "127.0.0.1", "--port", str(self.port)], signal.SIGTERM)
            self._wait_api()  # it migrates the database; then the others start
            self._spawn(["-m", "cli.main", "worker"], signal.SIGTERM)
            self._spawn(["-m", "cli.main", "viewer"], signal.SIGINT)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                if httpx.get(f"http://127.0.0.1:{self.viewer_port}/health", timeout=1).status_code == 200:
                    return
            except httpx.HTTPError:
                time.sleep(0.3)
        raise AssertionError("the viewer hub did not come up\n" + self.tail())

    def _wait_api(self) -> None:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            for p, _ in self.procs:
                assert p.poll() is None, self.tail()
            try:
                if httpx.get(f"{self.base}/api/v1/health", timeout=1).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        raise AssertionError("the api did not come up\n" + self.tail())

    def stop(self) -> None:
        for p, sig in self.procs:
            if p.poll() is None:
                p.send_signal(sig)
        for p, _ in self.procs:
            try:
                p.wait(40)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        self.log.close()

    def tail(self) -> str:
        self.log.flush()
        return self.log_path.read_text(errors="replace")[-5000:]


@pytest.fixture(scope="module")
def browser_kit():
    playwright = pytest.importorskip("playwright.sync_api", reason="Playwright's Python package is not installed")
    if not Path(CHROMIUM).exists():
        pytest.skip(f"no Chromium at {CHROMIUM} (apt-get install chromium)")
    return playwright


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory, browser_kit) -> Iterator[Processes]:
    svc = Processes(tmp_path_factory.mktemp("dash"))
    svc.start()
    try:
        yield svc
    finally:
        svc.stop()


@pytest.fixture(scope="module")
def shots(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = Path(os.environ.get("VTD_SCREENSHOT_DIR") or tmp_path_factory.mktemp("screenshots"))
    d.mkdir(parents=True, exist_ok=True)
    print(f"\nscreenshots in {d}")
    return d


@pytest.fixture(scope="module")
def archive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`vtdslam synth` (60 frames, one walker), zipped the way a user would."""
    tmp = tmp_path_factory.mktemp("synth")
    seq = tmp / "synth_walk60"
    env = {k: v for k, v in os.environ.items() if not k.startswith("VTD_") or k.startswith("VTD_TEST_")}
    subprocess.run([sys.executable, "-m", "cli.main", "synth", str(seq), "--frames", "60", "--people", "1"],
                   cwd=ROOT, env=env, check=True, capture_output=True, timeout=300)
    out = tmp / "synth_walk60.zip"
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as zf:  # PNGs: compressing again gains nothing
        for path in sorted(seq.rglob("*")):
            if path.is_file():
                zf.write(path, Path("synth_walk60") / path.relative_to(seq))
    return out


@pytest.fixture(scope="module")
def js_errors() -> list[str]:
    """Uncaught exceptions of the pages' scripts (filled by the `page` fixture)."""
    return []


@pytest.fixture(scope="module")
def page(browser_kit, service: Processes, js_errors: list[str]):
    with browser_kit.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        context = browser.new_context(viewport={"width": 1280, "height": 900}, base_url=service.base)
        pg = context.new_page()
        pg.set_default_timeout(30_000)
        pg.on("pageerror", lambda exc: js_errors.append(str(exc)))
        yield pg
        browser.close()


TIMING_JS = """() => {
    const nav = performance.getEntriesByType('navigation')[0];
    const paint = Object.fromEntries(performance.getEntriesByType('paint').map(e => [e.name, e.startTime]));
    const res = performance.getEntriesByType('resource');
    const sum = (xs) => xs.reduce((a, r) => a + (r.encodedBodySize || 0), 0);
    return {fcp: paint['first-contentful-paint'], dcl: nav.domContentLoadedEventEnd, load: nav.loadEventEnd,
            plotted: (performance.getEntriesByName('vtd-plots-drawn')[0] || {}).startTime, html: nav.encodedBodySize,
            shell: nav.encodedBodySize + sum(res.filter(r => r.name.includes('/static/'))),
            all: nav.encodedBodySize + sum(res), requests: res.length + 1};
}"""


def _shot(page, shots: Path, name: str) -> None:
    page.screenshot(path=str(shots / f"{name}.png"), full_page=True)


def test_dashboard_flow(page, js_errors: list[str], service: Processes, archive: Path, shots: Path,
                        tmp_path: Path) -> None:
    expect = pytest.importorskip("playwright.sync_api").expect

    # --- a refused upload says why, in words ---
    page.goto("/sequences")
    bogus = tmp_path / "not_a_sequence.zip"
    with zipfile.ZipFile(bogus, "w") as zf:
        zf.writestr("notes/readme.txt", "no rgb.txt here")
    page.set_input_files("#file", str(bogus))
    page.click("#upload-btn")
    err = page.locator("#upload-error")
    expect(err).to_be_visible(timeout=30_000)
    assert "Upload refused" in err.inner_text() and len(err.inner_text()) > 30
    _shot(page, shots, "01_sequences_upload_refused")

    # --- upload the generated sequence through the drop zone's input ---
    page.set_input_files("#file", str(archive))
    expect(page.locator("#file-chosen")).to_contain_text("synth_walk60.zip")
    page.select_option("#camera", "tum3")
    cdp = page.context.new_cdp_session(page)  # a slow link, so the progress bar is seen moving
    cdp.send("Network.enable")
    cdp.send("Network.emulateNetworkConditions", {"offline": False, "latency": 0, "downloadThroughput": -1,
                                                   "uploadThroughput": UPLOAD_BYTES_PER_S})
    page.click("#upload-btn")
    page.wait_for_function("() => { const b = document.getElementById('upload-bar');"
                           " return b.hasAttribute('value') && b.value > 0.05 && b.value < 0.95; }", timeout=60_000)
    expect(page.locator("#upload-text")).to_contain_text(" of ")
    _shot(page, shots, "02a_sequences_upload_progress")
    cdp.send("Network.emulateNetworkConditions", {"offline": False, "latency": 0, "downloadThroughput": -1,
                                                   "uploadThroughput": -1})
    row = page.locator("#seq-body tr", has_text="synth_walk60")
    expect(row).to_be_visible(timeout=120_000)
    expect(page.locator("#upload-text")).to_contain_text("60 frames")
    expect(row.locator(".badge.gt")).to_have_text("GT")
    page.wait_for_function("() => [...document.querySelectorAll('img.thumb')].every(i => i.complete)")
    assert page.evaluate("document.querySelector('img.thumb').naturalWidth") > 0
    _shot(page, shots, "02_sequences_uploaded")

    # --- start a job with orb-only; the job page follows it live ---
    for box in page.locator('input[name="preset"]:checked').all():  # the default preset is pre-checked
        box.uncheck()
    page.locator('input[name="preset"][value="orb-only"]').check()
    row.locator("button.run").click()
    page.wait_for_url("**/jobs/*")
    job_id = page.url.rstrip("/").rsplit("/", 1)[-1]
    page.wait_for_function("() => document.getElementById('job-bar').value > 0"
                           " || /succeeded|failed/.test(document.getElementById('job-status').textContent)",
                           timeout=JOB_TIMEOUT_MS)
    _shot(page, shots, "03_job_live")  # progress streamed over SSE (unless the run was quicker than the shot)
    expect(page.locator("#job-status .badge")).to_have_text("succeeded", timeout=JOB_TIMEOUT_MS)

    # --- the jobs list shows it with its headline ATE ---
    page.goto("/jobs")
    jrow = page.locator(f"#job-{job_id}")
    expect(jrow).to_contain_text("succeeded")
    expect(jrow).to_contain_text("orb-only")
    assert any(u in jrow.inner_text() for u in (" mm", " cm", " m"))
    _shot(page, shots, "04_jobs")

    # --- job page: time to first render and weight, cold (fresh browser contexts: empty caches), median of 5 ---
    runs = []
    for _ in range(TIMING_RUNS):
        cold = page.context.browser.new_context(viewport={"width": 1280, "height": 900}, base_url=service.base)
        try:
            fresh = cold.new_page()
            fresh.goto(f"/jobs/{job_id}", wait_until="load")
            expect(fresh.locator("#plot-traj svg path.series").first).to_be_visible()
            runs.append(fresh.evaluate(TIMING_JS))
        finally:
            cold.close()
    med = {k: sorted(r[k] for r in runs)[len(runs) // 2] for k in ("fcp", "dcl", "load", "plotted")}
    timing = {**runs[-1], **med, "fcp_min": min(r["fcp"] for r in runs), "fcp_max": max(r["fcp"] for r in runs)}
    print(f"\njob page on loopback, cold cache, median of {TIMING_RUNS}: first contentful paint {{fcp:.0f}} ms "
          "(min {fcp_min:.0f}, max {fcp_max:.0f}), DOMContentLoaded {dcl:.0f} ms, load {load:.0f} ms, plots drawn "
          "at {plotted:.0f} ms; weight: html {html} B, html+css+js {shell} B, with the run's data {all} B in "
          "{requests} requests".format(**timing))
    assert timing["fcp"] is not None and 20_000 < timing["shell"] < 80_000
    page.goto(f"/jobs/{job_id}")
    expect(page.locator("#plot-traj svg path.series").first).to_be_visible()  # the estimate (+ GT when written)

    metrics = page.locator("#metrics-table")
    expect(metrics).to_contain_text("ATE, absolute trajectory error (m)")
    expect(metrics).to_contain_text("frames/s")
    assert page.locator("#metrics-table tbody tr").count() >= 5
    expect(page.locator("#plot-timing svg rect.bar").first).to_be_visible()
    assert page.locator("#plot-timing svg rect.bar").count() >= 3
    expect(page.locator("#plot-ate")).not_to_be_empty()  # a plot, or a sentence saying why there is none
    expect(page.locator("#downloads")).to_contain_text("trajectory.txt")
    expect(page.locator("#downloads")).to_contain_text("map.ply")
    _shot(page, shots, "05_job")

    # --- the 3D viewer, embedded and opened on this run ---
    page.click("#viewer-btn")
    frame = page.locator("#viewer")
    page.wait_for_function("() => document.getElementById('viewer').src.startsWith('http')", timeout=60_000)
    src = frame.get_attribute("src")
    assert src.startswith("http://127.0.0.1:") and src.endswith("/")
    page.frame_locator("#viewer").locator("canvas").first.wait_for(state="attached", timeout=60_000)
    expect(page.locator("#viewer-error")).to_be_hidden()
    time.sleep(VIEWER_WAIT_S)  # SwiftShader renders WebGL at a few frames per second: real time
    page.locator("#viewer-wrap").scroll_into_view_if_needed()
    page.locator("#viewer-wrap").screenshot(path=str(shots / "06_viewer.png"))
    _shot(page, shots, "07_job_with_viewer")

    # --- a batch of the sequence from the Sequences page: the comparison table ---
    page.goto("/sequences")
    seq_row = page.locator("#seq-body tr", has_text="synth_walk60")
    seq_row.locator("input.seq-sel").check()
    for box in page.locator('input[name="preset"]:checked').all():
        box.uncheck()
    for preset in ("orb-only", "geometry-only"):  # two presets: the table shows % change vs orb-only
        page.locator(f'input[name="preset"][value="{preset}"]').check()
    page.click("#batch-btn")
    page.wait_for_url("**/batches/*")
    expect(page.locator("#batch-status .badge")).to_have_text("finished", timeout=JOB_TIMEOUT_MS)
    table = page.locator("#compare")
    expect(table).to_contain_text("synth_walk60")
    expect(table.locator("td.best")).to_have_count(1)
    href = f"/api/v1/batches/{page.url.rsplit('/', 1)[-1]}/table?format=csv"
    expect(page.locator("#csv-link")).to_have_attribute("href", href)
    csv = httpx.get(service.base + href, timeout=10)
    assert csv.headers["content-type"].startswith("text/csv") and "ate_rmse" in csv.text.splitlines()[0]
    _shot(page, shots, "08_batch")

    assert not js_errors, js_errors
