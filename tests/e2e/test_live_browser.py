"""A live session seen in headless Chromium: `vtdslam serve` (api, worker, viewer), a client streaming a small
made-up sequence through `vtdslam stream`'s client, and the job page showing the run while it goes: its map-point
count and frames grow on the page during the session, then the finished job's results replace the live card.

Needs Playwright's Python package and Debian's ``chromium``; skipped without them.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from cli.stream.client import create_session, send, wait_ready
from cli.stream.source import tum_source
from tests.backend.api.data import write_sequence
from tests.e2e.conftest import CHROMIUM, CHROMIUM_ARGS
from tests.e2e.services import ServiceProcesses, listening

pytestmark = pytest.mark.slow
FRAMES, RATE = 60, 4.0  # 15 s of stream: several of the worker's one-a-second snapshots


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory, playwright_api) -> Iterator[ServiceProcesses]:
    with ServiceProcesses(tmp_path_factory.mktemp("live")) as svc:
        svc.spawn("-m", "cli.main", "serve", "--port", str(svc.port))
        svc.wait_until("the service", lambda: listening(svc.host, svc.port) and listening(svc.host, svc.viewer_port))
        yield svc


def _facts(pg) -> dict[str, str]:  # noqa: ANN001 (Playwright's Page)
    return pg.evaluate("""() => Object.fromEntries([...document.querySelectorAll('#live-facts div')]
        .map((d) => [d.querySelector('dt').textContent, d.querySelector('dd').textContent]))""")


def test_the_job_page_shows_the_map_grow_during_a_live_session(playwright_api, service: ServiceProcesses,
                                                              tmp_path: Path, shots: Path) -> None:
    folder = write_sequence(tmp_path / "seq", n=FRAMES)
    source = tum_source(folder)
    assert source.camera is not None
    session = create_session(service.base, None, source.camera, "orb-only", "browser live")
    job = session["job_id"]
    wait_ready(service.base, job)
    sender = threading.Thread(target=send, args=(service.base, session, source), kwargs={"rate": RATE}, daemon=True)
    with playwright_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        pg = browser.new_page()
        errors: list[str] = []
        pg.on("pageerror", lambda exc: errors.append(str(exc)))
        try:
            pg.goto(f"{service.base}/jobs/{job}")
            sender.start()
            pg.wait_for_selector("#live-card:not([hidden])", timeout=60_000)
            seen: list[tuple[int, int]] = []  # (frames run, map points) as the page showed them
            deadline = time.monotonic() + FRAMES / RATE + 60
            while sender.is_alive() and time.monotonic() < deadline:
                f = _facts(pg)
                if "Map points" in f:
                    seen.append((int(f["Frames run"]), int(f["Map points"])))
                time.sleep(0.5)
            pg.screenshot(path=str(shots / "live_session.png"), full_page=True)
            pg.wait_for_selector("#results:not([hidden])", timeout=120_000)  # the job finished
            assert pg.is_hidden("#live-card")
        finally:
            browser.close()
    sender.join(30)
    frames = [s[0] for s in seen]
    points = [s[1] for s in seen]
    assert frames and frames[-1] > frames[0], seen  # the page followed the frames as they were run
    assert max(points) > min(p for p in points if p > 0), seen  # and saw the map grow during the session
    assert not errors, errors
