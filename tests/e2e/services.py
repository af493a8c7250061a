"""The service as processes for the browser tests: `vtdslam serve` (or the api, worker and viewer apart) on
free ports of one host and a temp data dir, without a developer's VTD_* variables, all output in one log."""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from types import TracebackType

import httpx

ROOT = Path(__file__).resolve().parents[2]
START_TIMEOUT_S = 60
STOP_TIMEOUT_S = 40


def free_port(host: str = "127.0.0.1") -> int:
    with socket.socket() as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def listening(host: str, port: int) -> bool:
    try:
        socket.create_connection((host, port), timeout=1).close()
    except OSError:
        return False
    return True


class ServiceProcesses:
    """Processes sharing one environment (``VTD_DATA_DIR``, ``VTD_PORT`` and ``VTD_VIEWER_PORT`` on free
    ports of ``host``) and one log; leaving the ``with`` block stops each with its own signal, then kills
    what is still running, even when starting failed half-way."""

    def __init__(self, tmp: Path, host: str = "127.0.0.1") -> None:
        self.host = host
        self.port, self.viewer_port = free_port(host), free_port(host)
        self.data_dir = tmp / "data"
        clean = {k: v for k, v in os.environ.items() if not k.startswith("VTD_") or k.startswith("VTD_TEST_")}
        self.env = {**clean, "VTD_DATA_DIR": str(self.data_dir), "VTD_PORT": str(self.port),
                    "VTD_VIEWER_PORT": str(self.viewer_port), "PYTHONUNBUFFERED": "1"}
        self.log_path = tmp / "service.log"
        self.log = open(self.log_path, "wb")  # noqa: SIM115 (closed in stop)
        self.procs: list[tuple[subprocess.Popen[bytes], int]] = []

    @property
    def base(self) -> str:
        return f"http://{self.host}:{self.port}"

    def spawn(self, *args: str, stop_signal: int = signal.SIGINT) -> subprocess.Popen[bytes]:
        """``python *args`` in the repository root; ``stop_signal`` is what ends it cleanly."""
        p = subprocess.Popen([sys.executable, *args], cwd=ROOT, env=self.env, stdout=self.log,
                             stderr=subprocess.STDOUT, start_new_session=True)
        self.procs.append((p, stop_signal))
        return p

    def wait_until(self, what: str, ready: Callable[[], bool], timeout: float = START_TIMEOUT_S) -> None:
        """Poll ``ready`` (an HTTP error counts as not yet) while every process lives."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for p, _ in self.procs:
                assert p.poll() is None, self.tail()
            try:
                if ready():
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        raise AssertionError(f"{what} did not come up\n" + self.tail())

    def healthy(self, url: str) -> Callable[[], bool]:
        return lambda: httpx.get(url, timeout=1).status_code == 200

    def stop(self) -> None:
        for p, sig in self.procs:
            if p.poll() is None:
                p.send_signal(sig)
        for p, _ in self.procs:
            try:
                p.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        self.log.close()

    def tail(self) -> str:
        if not self.log.closed:
            self.log.flush()
        return self.log_path.read_text(errors="replace")[-5000:]

    def __enter__(self) -> ServiceProcesses:
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()
