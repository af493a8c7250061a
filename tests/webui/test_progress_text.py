"""The dashboard's words for a running job's progress (app.js ``etaText``, run in Node): a live session that
caught up with its open stream is waiting for frames, not finishing. Skipped without Node."""
from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from storage.live import FINISHING_STAGE, STREAMING_STAGE

APP_JS = Path(__file__).resolve().parents[2] / "webui" / "static" / "js" / "app.js"
# app.js needs only these of a browser to load; etaText itself touches none of them
HARNESS = """
const fs = require("fs"), vm = require("vm");
const ctx = { window: {}, localStorage: { getItem: () => null }, console,
  document: { getElementById: () => null, addEventListener: () => {}, querySelectorAll: () => [] } };
vm.createContext(ctx);
vm.runInContext(fs.readFileSync(process.argv[1], "utf8") + "\\nthis.VTD = VTD;", ctx);
const jobs = JSON.parse(fs.readFileSync(0, "utf8"));
process.stdout.write(JSON.stringify(jobs.map((j) => ctx.VTD.etaText(j))));
"""


def eta_texts(jobs: list[dict]) -> list[str]:
    node = shutil.which("node")
    if node is None:
        pytest.skip("Node.js is not installed")
    done = subprocess.run([node, "-e", HARNESS, str(APP_JS)], input=json.dumps(jobs), capture_output=True,
                          text=True, timeout=60, check=True)
    return json.loads(done.stdout)


def running(stage: str, done: int, total: int, eta_s: float | None = None) -> dict:
    return {"status": "running", "stage": stage, "frames_done": done, "frames_total": total, "eta_s": eta_s}


def test_a_live_session_caught_up_with_its_open_stream_waits_and_finishes_only_once_it_ended() -> None:
    assert eta_texts([running(STREAMING_STAGE, 7, 7), running(STREAMING_STAGE, 5, 7),
                      running(FINISHING_STAGE, 7, 7)]) == [
        "caught up: 7 of 7 received frames processed, waiting for frames",
        "5 of 7 received frames processed",
        "frames done, finishing…",
    ]


def test_an_offline_run_shows_its_estimate_then_finishing() -> None:
    assert eta_texts([running("tracking", 3, 6, eta_s=12.0), running("dense", 6, 6),
                      {**running("tracking", 3, 6), "status": "failed"}]) == [
        "about 12 s left", "frames done, finishing…", ""]
