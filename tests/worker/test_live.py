"""A live session end to end in one process: the api (TestClient) keeps the streamed frames, the worker's live
runner (the real pipeline) runs them as they arrive, the partial map grows while it runs, and the session ends
as an ordinary finished job with every artifact, also when the client just goes away."""
from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from formats import artifacts
from formats.ply import read_ply
from storage.settings import get_settings
from tests.backend.api.data import CAMERA, write_sequence
from tests.backend.api.live_client import frame_messages, start_session
from worker.consumer import build_context
from worker.live import LiveConfig, run_live_slam
from worker.snapshots import SnapshotConfig
from worker.tasks import execute_job

pytestmark = pytest.mark.usefixtures("no_vtd_env")  # tests/conftest.py
N = 24


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_sequence(tmp_path_factory.mktemp("live") / "seq", n=N)


@pytest.fixture
def service(tmp_path: Path):
    """(api client, worker context, recorded job ids) on one data dir."""
    settings = get_settings(data_dir=tmp_path / "data")
    queued: list[str] = []
    with TestClient(create_app(settings, enqueue=queued.append)) as client:
        ctx = build_context(settings, name="w1")
        ctx.progress_interval_s = 0.0
        yield client, ctx, queued


def _worker(ctx, job_id: str) -> tuple[threading.Thread, list]:
    out: list = []
    t = threading.Thread(target=lambda: out.append(execute_job(ctx, job_id)), daemon=True)
    t.start()
    return t, out


def _state(client: TestClient, job_id: str) -> dict | None:
    return client.get(f"/api/v1/jobs/{job_id}/partial").json()["state"]


def _wait_processed(client: TestClient, job_id: str, n: int, timeout: float = 60) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        state = _state(client, job_id)
        if state is not None and state["frames"] >= n:
            return state
        time.sleep(0.02)
    raise AssertionError(f"the worker did not process {n} frames in {timeout} s")


def test_live_session_runs_as_frames_arrive_and_its_map_grows(service, folder) -> None:
    client, ctx, _ = service
    # a snapshot after every frame, on the pipeline thread: the growth is seen per frame
    ctx.snapshots = SnapshotConfig(interval_s=0.0, background=False)
    s = start_session(client, CAMERA)
    job = s["job_id"]
    thread, result = _worker(ctx, job)
    sizes, keyframes = [], []
    with client.websocket_connect(s["stream_url"]) as ws:
        assert ws.receive_json()["type"] == "ready"
        for i, m in enumerate(frame_messages(folder)):
            ws.send_bytes(m)
            state = _wait_processed(client, job, i + 1)  # one frame at a time: nothing is dropped
            assert client.get(f"/api/v1/jobs/{job}").json()["status"] == "running"
            ply = ctx.store.job_dir(job) / artifacts.PARTIAL_MAP
            sizes.append(len(read_ply(ply)[0]))
            keyframes.append(state["run_keyframes"])
            assert state["recent"][-1]["index"] == i and state["recent"][-1]["arrival"] is not None
        ws.send_json({"type": "groundtruth", "text": (folder / "groundtruth.txt").read_text()})
        ws.send_json({"type": "end"})
        assert ws.receive_json()["frames"] == N
    thread.join(120)
    assert result == ["succeeded"] or str(result[0]) == "succeeded"
    assert keyframes[-1] > keyframes[0] and sizes[-1] > sizes[0]  # the map grew while the session ran
    assert all(b >= a for a, b in zip(keyframes, keyframes[1:]))
    names = {a["name"] for a in client.get(f"/api/v1/jobs/{job}/artifacts").json()}
    assert set(artifacts.PIPELINE_OUTPUTS) <= names and not names & set(artifacts.PARTIALS)
    m = client.get(f"/api/v1/jobs/{job}").json()["metrics"]
    assert m["live_frames_received"] == N and m["live_frames_dropped"] == 0 and m["live_frames_processed"] == N
    assert m["ate"]["rmse"] < 0.05  # the ground truth the client sent scores the run
    seq = client.get(f"/api/v1/sequences/{s['sequence_id']}").json()
    assert seq["frames"] == N and seq["has_groundtruth"]


def test_client_gone_mid_stream_the_job_finishes_with_what_was_received(service, folder) -> None:
    client, ctx, _ = service
    s = start_session(client, CAMERA)
    thread, result = _worker(ctx, s["job_id"])
    with client.websocket_connect(s["stream_url"]) as ws:
        ws.receive_json()
        for m in frame_messages(folder, 10):
            ws.send_bytes(m)
        ws.send_json({"type": "ping"})
        assert ws.receive_json()["frames"] == 10
    thread.join(120)
    assert str(result[0]) == "succeeded"
    job = client.get(f"/api/v1/jobs/{s['job_id']}").json()
    assert job["metrics"]["live_frames_received"] == 10
    assert job["metrics"]["live_frames_processed"] + job["metrics"]["live_frames_dropped"] == 10
    assert job["metrics"]["live_end"] == "client disconnected"
    traj = client.get(f"/api/v1/jobs/{s['job_id']}/artifacts/trajectory.txt").text
    assert len([ln for ln in traj.splitlines() if ln and not ln.startswith("#")]) >= 3
    assert client.get(f"/api/v1/sequences/{s['sequence_id']}").json()["frames"] == 10  # every frame kept


def test_a_worker_behind_drops_the_oldest_frames_and_counts_them(service, folder) -> None:
    """All frames arrive before the runner starts: it keeps only the newest `max_behind` waiting."""
    client, ctx, _ = service
    s = start_session(client, CAMERA)
    with client.websocket_connect(s["stream_url"]) as ws:
        ws.receive_json()
        for m in frame_messages(folder):
            ws.send_bytes(m)
        ws.send_json({"type": "ping"})
        assert ws.receive_json()["frames"] == N
        # the stream is still open: the job runs as a live session, N frames behind at its start
        ctx.live_pipeline = lambda *a, **k: run_live_slam(*a, **k, live=LiveConfig(max_behind=4))
        thread, result = _worker(ctx, s["job_id"])
        _wait_processed(client, s["job_id"], 4)
        ws.send_json({"type": "end"})
        ws.receive_json()
    thread.join(120)
    m = client.get(f"/api/v1/jobs/{s['job_id']}").json()["metrics"]
    assert str(result[0]) == "succeeded"
    assert m["live_frames_dropped"] == N - 4 and m["live_frames_processed"] == 4
    assert json.loads(client.get(f"/api/v1/jobs/{s['job_id']}/artifacts/metrics.json").text)["frames"] == 4


def test_a_restoring_preset_runs_live_with_causal_references(service, folder) -> None:
    """`full` restores from neighbouring frames; a stream has none after the latest, so a live session takes
    them from the past (restoration.references 'causal') instead of reading frames that do not exist yet."""
    client, ctx, _ = service
    s = start_session(client, CAMERA, preset="full")
    thread, result = _worker(ctx, s["job_id"])
    with client.websocket_connect(s["stream_url"]) as ws:
        ws.receive_json()
        for i, m in enumerate(frame_messages(folder, 12)):
            ws.send_bytes(m)
            _wait_processed(client, s["job_id"], i + 1, timeout=120)
        ws.send_json({"type": "end"})
        ws.receive_json()
    thread.join(300)
    job = client.get(f"/api/v1/jobs/{s['job_id']}").json()
    assert str(result[0]) == "succeeded", job["error"]
    assert job["config"]["restoration"]["references"] == "causal" and job["metrics"]["live_frames_processed"] == 12


def test_a_second_job_on_a_receiving_session_follows_it_and_leaves_it_alone(service, folder) -> None:
    """Another job queued on the session's sequence while it receives runs live too (another preset, say); when
    it ends first, the session goes on for its client and its own job."""
    client, ctx, _ = service
    s = start_session(client, CAMERA)
    own, own_result = _worker(ctx, s["job_id"])
    messages = frame_messages(folder, 12)
    with client.websocket_connect(s["stream_url"]) as ws:
        ws.receive_json()
        ws.send_bytes(messages[0])
        _wait_processed(client, s["job_id"], 1)
        other = client.post("/api/v1/jobs", json={"sequence_id": s["sequence_id"], "preset": "orb-only"}).json()
        thread, result = _worker(ctx, other["id"])
        _wait_processed(client, other["id"], 0)
        assert client.post(f"/api/v1/jobs/{other['id']}/cancel").status_code == 200
        thread.join(120)
        assert str(result[0]) == "cancelled"
        for i, m in enumerate(messages[1:]):  # the stream goes on
            ws.send_bytes(m)
            _wait_processed(client, s["job_id"], i + 2)
        ws.send_json({"type": "end"})
        assert ws.receive_json()["frames"] == 12
    own.join(120)
    assert str(own_result[0]) == "succeeded"
    assert client.get(f"/api/v1/jobs/{s['job_id']}").json()["metrics"]["live_frames_processed"] == 12
