"""Real worker processes (and the api in process) on one data dir, for the crash and scale-out tests.

Every process started here is killed at teardown, whatever the test did; logs go to files a failing
assertion prints.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parents[2]
FINAL = ("succeeded", "failed", "cancelled")


def clean_env(**vtd: str) -> dict[str, str]:
    """This process's environment without a developer's VTD_* variables, plus ``vtd``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("VTD_") or k.startswith("VTD_TEST_")}
    return {**env, "PYTHONUNBUFFERED": "1", **vtd}


def wait_for(what: str, check: Callable[[], Any], timeout: float = 60, every: float = 0.1,
              context: Callable[[], str] = lambda: "") -> Any:
    """Poll ``check`` until it returns something truthy; fail with ``what`` (and ``context()``) after ``timeout``."""
    deadline = time.monotonic() + timeout
    last: Any = None
    while time.monotonic() < deadline:
        last = check()
        if last:
            return last
        time.sleep(every)
    raise AssertionError(f"timed out waiting for {what} (last: {last!r})\n{context()}")


class Procs:
    """Worker subprocesses of one test; :meth:`close` kills the survivors."""

    def __init__(self, logs: Path) -> None:
        self.logs = logs
        self.logs.mkdir(parents=True, exist_ok=True)
        self.all: list[subprocess.Popen[bytes]] = []
        self.files: list[Path] = []

    def worker(self, env: dict[str, str], *args: str, tag: str = "worker") -> subprocess.Popen[bytes]:
        log = self.logs / f"{tag}-{len(self.all)}.log"
        with open(log, "wb") as fh:  # the child keeps its own descriptor
            proc = subprocess.Popen([sys.executable, "-m", "cli.main", "worker", *args],
                                    cwd=ROOT, env=env, stdout=fh, stderr=subprocess.STDOUT)
        self.all.append(proc)
        self.files.append(log)
        return proc

    def log_of(self, proc: subprocess.Popen[bytes]) -> str:
        return self.files[self.all.index(proc)].read_text(errors="replace")

    def wait_ready(self, proc: subprocess.Popen[bytes], timeout: float = 60) -> str:
        """Wait for the consumer's start line; returns the worker's name."""
        def started() -> str | None:
            assert proc.poll() is None, self.log_of(proc)
            for line in self.log_of(proc).splitlines():
                if "worker.consumer" in line and " thread(s), queue " in line:
                    return line.split("worker ", 1)[1].split(":", 1)[0]
            return None
        return wait_for("the worker to start", started, timeout, context=lambda: self.log_of(proc))

    @staticmethod
    def kill9(proc: subprocess.Popen[bytes]) -> None:
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)

    @staticmethod
    def stop(proc: subprocess.Popen[bytes], timeout: float = 60) -> int:
        proc.send_signal(signal.SIGTERM)
        return proc.wait(timeout)

    def tails(self) -> str:
        return "\n".join(f"--- {f.name}\n{f.read_text(errors='replace')[-3000:]}" for f in self.files if f.exists())

    def close(self) -> None:
        for proc in self.all:
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)


def upload(client: Any, folder: Path, archive: Path) -> dict[str, Any]:
    """Upload a TUM-layout ``folder`` (as a .tar.gz) through the api; the sequence's JSON."""
    from tests.backend.api.data import tar_gz

    tar_gz(folder, archive, top=folder.name)
    with open(archive, "rb") as fh:
        r = client.post("/api/v1/sequences", files={"file": (archive.name, fh)}, data={"camera": "tum1"})
    assert r.status_code == 201, r.text
    return r.json()


def submit(client: Any, seq_id: str, preset: str = "orb-only") -> str:
    r = client.post("/api/v1/jobs", json={"sequence_id": seq_id, "preset": preset})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def job(client: Any, job_id: str) -> dict[str, Any]:
    r = client.get(f"/api/v1/jobs/{job_id}")
    assert r.status_code == 200, r.text
    return r.json()


def final_job(client: Any, job_id: str) -> dict[str, Any] | None:
    """The job once it has reached a FINAL status, else None (a ``wait_for`` check)."""
    j = job(client, job_id)
    return j if j["status"] in FINAL else None


def healthy(client: Any) -> bool:
    r = client.get("/api/v1/health")
    return r.status_code == 200 and r.json()["database"] == "ok"


def http_get(url: str) -> httpx.Response:
    return httpx.get(url, timeout=10)


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ApiProc:
    """The api alone as a uvicorn subprocess on loopback (what `vtdslam serve` runs)."""

    def __init__(self, env: dict[str, str], log: Path) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}/api/v1"
        self.log = log
        with open(log, "wb") as fh:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "uvicorn", "backend.app:create_app", "--factory", "--host", "127.0.0.1",
                 "--port", str(self.port), "--log-level", "warning"],
                cwd=ROOT, env=env, stdout=fh, stderr=subprocess.STDOUT)

    def wait_ready(self, timeout: float = 60) -> None:
        def up() -> bool:
            assert self.proc.poll() is None, self.output()
            try:
                return http_get(f"{self.url}/health").status_code == 200
            except httpx.HTTPError:
                return False
        wait_for("the api to answer", up, timeout, every=0.2, context=self.output)

    def output(self) -> str:
        return self.log.read_text(errors="replace") if self.log.exists() else ""

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
