"""End to end with real processes: `vtdslam serve` (uvicorn api + a worker + the viewer) on a temp data dir.

A generated sequence is uploaded over HTTP, a job runs to completion with the real pipeline, its metrics
are read from the API and from the database, artifacts are downloaded (with a range), progress streams
over SSE, a second job is cancelled mid-run, and Ctrl-C stops every process. Run once on the embedded
default (SQLite + SQLite queue) and once on PostgreSQL + Redis (skipped when they are not reachable).
"""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest

from tests.backend.api.data import tar_gz, write_sequence
from tests.backends import scaled_urls

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.slow


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Service:
    def __init__(self, data_dir: Path, env: dict[str, str], *flags: str) -> None:
        self.flags = list(flags)
        self.port = _free_port()
        self.url = f"http://127.0.0.1:{self.port}/api/v1"
        self.log = data_dir.parent / "serve.log"
        clean = {k: v for k, v in os.environ.items() if not k.startswith("VTD_") or k.startswith("VTD_TEST_")}
        self.env = {**clean, "VTD_DATA_DIR": str(data_dir), "VTD_VIEWER_PORT": str(_free_port()),
                    "PYTHONUNBUFFERED": "1", **env}
        self.proc: subprocess.Popen | None = None

    def start(self) -> None:
        self.logfh = open(self.log, "wb")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "cli.main", "serve", "--port", str(self.port), *self.flags],
            cwd=ROOT, env=self.env, stdout=self.logfh, stderr=subprocess.STDOUT,
        )
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            assert self.proc.poll() is None, self.tail()
            try:
                if httpx.get(f"{self.url}/health", timeout=1).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        raise AssertionError("api did not come up\n" + self.tail())

    def child_pids(self) -> list[int]:
        return [int(line.rsplit("pid ", 1)[1].rstrip(")"))
                for line in self.log.read_text().splitlines() if line.startswith("started ")]

    def stop(self) -> int:
        assert self.proc is not None
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)  # what Ctrl-C does
        try:
            return self.proc.wait(60)
        finally:
            self.logfh.close()

    def tail(self) -> str:
        return self.log.read_text()[-4000:] if self.log.exists() else ""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie waiting for its parent counts as gone
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


def _wait_job(client: httpx.Client, job_id: str, until, timeout: float = 90) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = client.get(f"/jobs/{job_id}").json()
        if until(job):
            return job
        time.sleep(0.1)
    raise AssertionError(f"job {job_id} stuck: {job}")


def _interrupted_upload(svc: Service, archive: Path) -> None:
    """A client that sends half an upload and hangs up: nothing may stay in staging."""
    data = archive.read_bytes()
    boundary = "vtdboundary"
    head = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"camera\"\r\n\r\ntum1\r\n"
            f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"x.tgz\"\r\n"
            "Content-Type: application/gzip\r\n\r\n").encode()
    body_len = len(head) + len(data) + len(f"\r\n--{boundary}--\r\n")
    with socket.create_connection(("127.0.0.1", svc.port)) as sock:
        sock.sendall((f"POST /api/v1/sequences HTTP/1.1\r\nHost: x\r\nContent-Length: {body_len}\r\n"
                      f"Content-Type: multipart/form-data; boundary={boundary}\r\n\r\n").encode())
        sock.sendall(head + data[: len(data) // 2])
        time.sleep(0.5)
    staging = Path(svc.env["VTD_DATA_DIR"]) / "staging"
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(staging.glob("upload-*")):
        time.sleep(0.1)
    assert not any(staging.glob("upload-*")), list(staging.rglob("*"))[:10]


def _flow(svc: Service, tmp_path: Path, db_rows: Callable[[str], tuple[float | None, int]]) -> None:
    small = tar_gz(write_sequence(tmp_path / "small", n=20), tmp_path / "small.tgz", top="rgbd_small")
    large = tar_gz(write_sequence(tmp_path / "large", n=400), tmp_path / "large.tgz", top="rgbd_large")
    with httpx.Client(base_url=svc.url, timeout=60) as client:
        with open(small, "rb") as fh:
            r = client.post("/sequences", files={"file": ("rgbd_small.tgz", fh)}, data={"camera": "tum1"})
        assert r.status_code == 201, r.text
        seq = r.json()
        assert seq["frames"] == 20 and seq["has_groundtruth"]

        job = client.post("/jobs", json={"sequence_id": seq["id"], "preset": "orb-only"}).json()
        events = []
        with client.stream("GET", f"/jobs/{job['id']}/events", params={"interval": 0.2}) as stream:
            for line in stream.iter_lines():
                if line.startswith("event: "):
                    events.append(line[7:])
        assert events[-1] == "end" and "progress" in events
        done = client.get(f"/jobs/{job['id']}").json()
        assert done["status"] == "succeeded", svc.tail()
        assert done["frames_done"] == done["frames_total"] == 20 and done["progress"] == 1.0
        assert done["metrics"]["ate"]["rmse"] < 0.05 and done["metrics"]["tracked"] == 20
        assert done["config"]["name"] == "orb-only"

        ate_rmse, n_frames = db_rows(done["id"])
        assert ate_rmse == pytest.approx(done["metrics"]["ate"]["rmse"]) and n_frames == 20

        names = {a["name"] for a in client.get(f"/jobs/{job['id']}/artifacts").json()}
        assert {"trajectory.txt", "keyframes.txt", "map.ply", "metrics.json", "config.json",
                "frame_stats.csv", "log.txt", "preview.png"} <= names
        preview = client.get(f"/jobs/{job['id']}/artifacts/preview.png")
        assert preview.headers["content-type"] == "image/png" and preview.content[:4] == b"\x89PNG"
        traj = client.get(f"/jobs/{job['id']}/artifacts/trajectory.txt")
        assert traj.status_code == 200 and len([ln for ln in traj.text.splitlines() if ln[:1].isdigit()]) == 20
        ply = client.get(f"/jobs/{job['id']}/artifacts/map.ply", headers={"Range": "bytes=0-2"})
        assert ply.status_code == 206 and ply.content == b"ply"
        assert json.loads(client.get(f"/jobs/{job['id']}/artifacts/metrics.json").text)["frames"] == 20

        table = client.get("/batches/" + client.post("/batches", json={
            "sequence_ids": [seq["id"]], "presets": ["orb-only"]}).json()["id"] + "/table").json()
        assert table[0]["sequence_name"] == "rgbd_small"

        with open(large, "rb") as fh:
            big = client.post("/sequences", files={"file": ("large.tgz", fh)}, data={"camera": "tum1"}).json()
        slow = client.post("/jobs", json={"sequence_id": big["id"], "preset": "orb-only"}).json()
        running = _wait_job(client, slow["id"], lambda j: j["status"] == "running" and j["frames_done"] > 0)
        t0 = time.monotonic()
        assert client.post(f"/jobs/{slow['id']}/cancel").status_code == 200
        cancelled = _wait_job(client, slow["id"], lambda j: j["status"] in ("cancelled", "succeeded", "failed"))
        assert cancelled["status"] == "cancelled", cancelled
        assert time.monotonic() - t0 < 5 and cancelled["frames_done"] < 400
        assert running["frames_total"] == 400
        retried = client.post(f"/jobs/{slow['id']}/retry").json()
        assert retried["status"] in ("queued", "running") and retried["attempts"] == 2  # a worker may be quick
        client.post(f"/jobs/{slow['id']}/cancel")
        n_seqs = client.get("/sequences").json()["total"]
    _interrupted_upload(svc, large)
    with httpx.Client(base_url=svc.url, timeout=60) as client:
        assert client.get("/sequences").json()["total"] == n_seqs


@pytest.fixture
def sqlite_service(tmp_path: Path) -> Iterator[Service]:
    svc = Service(tmp_path / "data", {})
    svc.start()
    yield svc
    svc.stop()


def test_embedded_default_sqlite(sqlite_service: Service, tmp_path: Path):
    import sqlite3

    def rows(job_id: str) -> tuple[float | None, int]:
        with sqlite3.connect(tmp_path / "data" / "vtdslam.db") as db:
            (ate,) = db.execute("SELECT ate_rmse FROM run_metrics WHERE job_id = ?", (job_id,)).fetchone()
            (n,) = db.execute("SELECT count(*) FROM frame_stats WHERE job_id = ?", (job_id,)).fetchone()
        return ate, n

    _flow(sqlite_service, tmp_path, rows)
    children = sqlite_service.child_pids()
    assert len(children) == 3  # api, worker, viewer
    viewer_port = int(sqlite_service.env["VTD_VIEWER_PORT"])
    with socket.create_connection(("127.0.0.1", viewer_port), timeout=5):
        pass
    assert sqlite_service.stop() == 0, sqlite_service.tail()
    assert not any(_alive(p) for p in children), sqlite_service.tail()
    assert "stopped" in sqlite_service.tail()


def test_queued_jobs_wait_for_a_worker_and_survive_restarts(tmp_path: Path):
    """`serve --no-worker` queues; the next `serve` (with its worker) picks the job up from the queue file."""
    small = tar_gz(write_sequence(tmp_path / "small", n=10), tmp_path / "small.tgz")
    api_only = Service(tmp_path / "data", {}, "--no-worker", "--no-viewer")
    api_only.start()
    try:
        assert len(api_only.child_pids()) == 1
        with httpx.Client(base_url=api_only.url, timeout=60) as client:
            seq = client.post("/sequences", files={"file": ("s.tgz", small.read_bytes())},
                              data={"camera": "tum1"}).json()
            job = client.post("/jobs", json={"sequence_id": seq["id"], "preset": "orb-only"}).json()
            time.sleep(1.5)
            assert client.get(f"/jobs/{job['id']}").json()["status"] == "queued"
    finally:
        assert api_only.stop() == 0
    full = Service(tmp_path / "data", {}, "--no-viewer")
    full.start()
    try:
        with httpx.Client(base_url=full.url, timeout=60) as client:
            done = _wait_job(client, job["id"], lambda j: j["status"] in ("succeeded", "failed", "cancelled"))
            assert done["status"] == "succeeded", full.tail()
    finally:
        assert full.stop() == 0


@pytest.fixture
def scaled_service(tmp_path: Path) -> Iterator[tuple[Service, str]]:
    with scaled_urls("vtd_e2e_") as (db_url, queue_url):
        svc = Service(tmp_path / "data", {"VTD_DATABASE_URL": db_url, "VTD_QUEUE_URL": queue_url}, "--no-viewer")
        try:
            svc.start()
            yield svc, db_url
        finally:
            if svc.proc is not None:
                svc.stop()


@pytest.mark.postgres
@pytest.mark.redis
def test_scaled_out_postgres_and_redis(scaled_service, tmp_path: Path):
    import psycopg

    svc, db_url = scaled_service

    def rows(job_id: str) -> tuple[float | None, int]:
        with psycopg.connect(db_url) as conn:
            metrics = conn.execute("SELECT ate_rmse FROM run_metrics WHERE job_id = %s", (job_id,)).fetchone()
            count = conn.execute("SELECT count(*) FROM frame_stats WHERE job_id = %s", (job_id,)).fetchone()
        assert metrics is not None and count is not None, "the finished job has no run_metrics row"
        return metrics[0], count[0]

    _flow(svc, tmp_path, rows)
    assert not (tmp_path / "data" / "vtdslam.db").exists() and not (tmp_path / "data" / "queue.db").exists()
    assert svc.stop() == 0, svc.tail()
