"""The 3D viewer of a running job: it opens on the partial results and redraws them as they grow, then turns
into the finished run's scene."""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

from formats import artifacts
from formats.ply import write_ply
from storage.artifacts import ArtifactStore
from storage.errors import NotFound
from webui.viewer.hub import HubConfig, ViewerHub
from webui.viewer.live_scene import FINAL, NOTHING, PARTIAL, partial_state


def _tum(n: int) -> str:
    return "".join(f"{i / 30:.6f} {i * 0.01:.4f} 0 {i * 0.02:.4f} 0 0 0 1\n" for i in range(n))


def _snapshot(d: Path, n: int, points: int) -> None:
    d.mkdir(parents=True, exist_ok=True)
    (d / artifacts.PARTIAL_STATE).write_text(json.dumps({"frames": n}))
    (d / artifacts.PARTIAL_TRAJECTORY).write_text(_tum(n))
    (d / artifacts.PARTIAL_KEYFRAMES).write_text(_tum(n).splitlines(keepends=True)[0])
    rng = np.random.default_rng(points)
    write_ply(d / artifacts.PARTIAL_MAP, rng.normal(size=(points, 3)).astype(np.float32),
              rng.integers(0, 255, (points, 3), dtype=np.uint8))


def _until(cond, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError("not reached in time")
        time.sleep(0.02)


def test_a_running_jobs_viewer_grows_then_becomes_the_finished_run(tmp_path: Path) -> None:
    store = ArtifactStore(tmp_path)
    hub = ViewerHub(store, HubConfig(refresh_s=0.05))
    d = store.job_dir("job1", create=True)
    assert partial_state(d) == NOTHING
    with pytest.raises(NotFound):
        hub.open_run("job1")  # nothing to show yet
    _snapshot(d, 5, 100)
    assert partial_state(d) == PARTIAL
    try:
        hub.open_run("job1")
        live = hub._live["job1"]
        assert live.shown == {"poses": 5, "keyframes": 1, "map": 100}
        time.sleep(0.05)  # a new mtime for the rewritten files
        _snapshot(d, 40, 900)
        _until(lambda: live.shown["map"] == 900 and live.shown["poses"] == 40)  # the map grew on screen
        # the job ends: final artifacts in place, snapshots removed
        (d / artifacts.TRAJECTORY).write_text(_tum(40))
        for name in artifacts.PARTIALS:
            (d / name).unlink(missing_ok=True)
        assert partial_state(d) == FINAL
        _until(lambda: "job1" not in hub._live)
        assert hub.open_run("job1").port > 0  # the same server, now the finished run's scene
    finally:
        hub.stop()
