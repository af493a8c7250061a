"""Loopback load on the api (embedded default: SQLite database + SQLite queue file), bounded in time.

Starts the api alone (uvicorn subprocess, free port, temp data dir), queues ``--jobs`` jobs, and while
a worker-like writer in this process claims jobs and reports their progress (like `vtdslam worker`,
but every 20 ms), runs for ``--seconds``:

- ``--clients`` threads that each loop over ``GET /jobs`` (a page of 50) and ``GET /jobs/{id}`` (polling);
- ``--uploaders`` threads uploading a small sequence archive (20 frames, 160x120, .tar.gz) again and again.

Prints a markdown table (endpoint | requests | p50 ms | p99 ms | errors); an error is a transport error
or a 5xx (4xx would be a bug of this script). Usage: ``python bench/bench_load.py [--seconds 30]``.
"""
from __future__ import annotations

import argparse
import io
import json
import os
import shutil
import socket
import subprocess
import sys
import tarfile
import tempfile
import threading
import time
from collections import defaultdict
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def small_archive(frames: int = 20, size: tuple[int, int] = (160, 120)) -> bytes:
    """A valid TUM-layout .tar.gz: textured RGB, constant 16-bit depth, its own camera.json."""
    import cv2
    import numpy as np

    rng = np.random.default_rng(0)
    w, h = size
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tf:
        def add(name: str, data: bytes) -> None:
            info = tarfile.TarInfo(f"load_seq/{name}")
            info.size = len(data)
            tf.addfile(info, io.BytesIO(data))

        stamps = [100.0 + i / 30 for i in range(frames)]
        depth = cv2.imencode(".png", np.full((h, w), 5000, np.uint16))[1].tobytes()
        for t in stamps:
            add(f"rgb/{t:.6f}.png", cv2.imencode(".png", rng.integers(0, 255, (h, w, 3), dtype=np.uint8))[1].tobytes())
            add(f"depth/{t:.6f}.png", depth)
        add("rgb.txt", "".join(f"{t:.6f} rgb/{t:.6f}.png\n" for t in stamps).encode())
        add("depth.txt", "".join(f"{t:.6f} depth/{t:.6f}.png\n" for t in stamps).encode())
        add("camera.json", json.dumps({"fx": 100.0, "fy": 100.0, "cx": w / 2, "cy": h / 2,
                                       "depth_scale": 5000.0, "width": w, "height": h}).encode())
    return buf.getvalue()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Stats:
    def __init__(self) -> None:
        self.ms: dict[str, list[float]] = defaultdict(list)
        self.errors: dict[str, int] = defaultdict(int)
        self.lock = threading.Lock()

    def timed(self, name: str, call) -> httpx.Response | None:
        t0 = time.perf_counter()
        try:
            r = call()
        except httpx.HTTPError:
            r = None
        ms = (time.perf_counter() - t0) * 1000
        with self.lock:
            self.ms[name].append(ms)
            if r is None or r.status_code >= 500:
                self.errors[name] += 1
            elif r.status_code >= 400:
                raise AssertionError(f"{name}: {r.status_code} {r.text[:200]}")
        return r

    def table(self) -> str:
        import numpy as np

        lines = ["| endpoint | requests | p50 ms | p99 ms | errors |", "|---|---|---|---|---|"]
        for name in sorted(self.ms):
            v = np.array(self.ms[name])
            lines.append(f"| {name} | {len(v)} | {np.percentile(v, 50):.1f} | {np.percentile(v, 99):.1f} "
                         f"| {self.errors[name]} |")
        return "\n".join(lines)


def writer(data_dir: Path, stop: threading.Event, counter: list[int]) -> None:
    """Claim queued jobs and report progress on them, like a worker with several threads."""
    from storage.db import make_engine, make_session_factory
    from storage.models import JobStatus
    from storage.repositories import jobs
    from storage.settings import get_settings

    engine = make_engine(get_settings(data_dir=data_dir))
    with make_session_factory(engine)() as session:
        while not stop.is_set():
            queued = jobs.list_jobs(session, status=JobStatus.QUEUED, limit=4)
            if not queued:
                break
            for job in queued:
                jobs.claim(session, job.id, "bench-writer")
            for i in range(25):
                for job in queued:
                    jobs.update_progress(session, job.id, frames_done=i, frames_total=25, stage="tracking")
                    counter[0] += 1
                time.sleep(0.02)
            for job in queued:
                jobs.finish(session, job.id, JobStatus.SUCCEEDED)
    engine.dispose()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--clients", type=int, default=50)
    ap.add_argument("--uploaders", type=int, default=2)
    ap.add_argument("--jobs", type=int, default=300, help="jobs queued before the run (listed and polled)")
    args = ap.parse_args()

    tmp = Path(tempfile.mkdtemp(prefix="bench-load-"))
    data = tmp / "data"
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("VTD_")}
    env["VTD_DATA_DIR"] = str(data)
    log = open(tmp / "api.log", "wb")
    api = subprocess.Popen([sys.executable, "-m", "uvicorn", "backend.app:create_app", "--factory",
                            "--host", "127.0.0.1", "--port", str(port), "--log-level", "warning"],
                           cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{port}/api/v1"
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                if httpx.get(f"{base}/health", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            if time.monotonic() > deadline or api.poll() is not None:
                raise SystemExit("api did not start:\n" + (tmp / "api.log").read_text())
            time.sleep(0.2)
        archive = small_archive()
        with httpx.Client(base_url=base, timeout=60) as c:
            seq = c.post("/sequences", files={"file": ("load_seq.tgz", archive)}, data={"camera": "tum1"}).json()
            ids = [c.post("/jobs", json={"sequence_id": seq["id"], "preset": "orb-only"}).json()["id"]
                   for _ in range(args.jobs)]

        stats, stop, writes = Stats(), threading.Event(), [0]
        end = time.monotonic() + args.seconds

        def client_loop(seed: int) -> None:
            import random

            rng = random.Random(seed)
            with httpx.Client(base_url=base, timeout=60) as c:
                while time.monotonic() < end:
                    stats.timed("GET /jobs (list 50)", lambda: c.get("/jobs", params={"limit": 50}))
                    stats.timed("GET /jobs/{id} (poll)", lambda: c.get(f"/jobs/{rng.choice(ids)}"))

        def upload_loop() -> None:
            with httpx.Client(base_url=base, timeout=120) as c:
                while time.monotonic() < end:
                    stats.timed("POST /sequences (upload 20 frames)", lambda: c.post(
                        "/sequences", files={"file": ("load_seq.tgz", archive)}, data={"camera": "tum1"}))

        threads = [threading.Thread(target=writer, args=(data, stop, writes), daemon=True)]
        threads += [threading.Thread(target=client_loop, args=(i,)) for i in range(args.clients)]
        threads += [threading.Thread(target=upload_loop) for _ in range(args.uploaders)]
        for t in threads:
            t.start()
        for t in threads[1:]:
            t.join()
        stop.set()
        threads[0].join(30)
        locked = (tmp / "api.log").read_text(errors="replace").count("database is locked")
        print(f"{args.clients} clients + {args.uploaders} uploaders for {args.seconds:.0f} s on loopback, "
              f"SQLite (WAL); worker-like progress writes meanwhile: {writes[0]}; "
              f"'database is locked' in the api log: {locked}; archive {len(archive) / 1024:.0f} KiB")
        print(stats.table())
    finally:
        api.terminate()
        try:
            api.wait(20)
        except subprocess.TimeoutExpired:
            api.kill()
        log.close()
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
