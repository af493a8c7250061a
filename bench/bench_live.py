"""Live session benchmark: stream a sequence at a fixed rate into the embedded service (`vtdslam serve`: api, worker
and viewer hub as separate processes on this machine) and print what a user of the page sees.

    .venv/bin/python bench/bench_live.py \
        [--seq ../shared/data/bonn_crowd_dev] [--camera bonn] [--preset no-restoration] [--rate 30]

Measured: the delay from a frame's arrival at the api to its pose being readable on the job page's endpoint
(`GET /jobs/{id}/partial`, polled here every `--poll` seconds, 0.1 by default; the page polls every 0.5 s) and,
inside that, to the worker's pose (the worker's own clock, same machine); frames dropped by the worker (the job's
`live_frames_dropped`); the peak resident memory of api, worker and viewer (each process's VmHWM, summed: an upper
bound of the joint peak); the live run's ATE (the ground truth is sent after the frames) against an offline
`vtdslam run` of the very frames the session kept. The 3D viewer is opened on the running job (the hub then
redraws its partial map every second); no browser renders it. Timings depend on what else loads the CPU.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
import numpy as np
from live_args import add_stream_args  # bench/, the script's own folder

from cli.stream.client import create_session, send, wait_ready
from cli.stream.source import tum_source


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _children(pid: int) -> list[int]:
    out = []
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                if int((p / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                    out.append(int(p.name))
            except (OSError, IndexError, ValueError):
                continue
    return out


def _usage(pid: int) -> tuple[str, float, float]:
    """(role, peak resident MB, CPU seconds) of a `vtdslam serve` child."""
    cmd = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    role = "api" if b"cli.api_server" in cmd else cmd[3].decode() if len(cmd) > 3 else "?"
    peak = next((int(ln.split()[1]) / 1024 for ln in Path(f"/proc/{pid}/status").read_text().splitlines()
                 if ln.startswith("VmHWM:")), float("nan"))
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return role, peak, (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class PagePoller(threading.Thread):
    """Polls the job's partial results like the job page; records when each frame's pose was first readable."""

    def __init__(self, base: str, job_id: str, period_s: float = 0.05) -> None:
        super().__init__(daemon=True)
        self.url, self.period = f"{base}/api/v1/jobs/{job_id}/partial", period_s
        self.seen: dict[int, tuple[float, float | None, float]] = {}  # index -> (seen, arrival, worker done)
        self.stop = threading.Event()

    def run(self) -> None:
        with httpx.Client(timeout=10) as client:
            while not self.stop.is_set():
                try:
                    p = client.get(self.url).json()
                except (httpx.HTTPError, ValueError):
                    p = {}
                now = time.time()
                for r in (p.get("state") or {}).get("recent", []):
                    self.seen.setdefault(r["index"], (now, r["arrival"], r["done"]))
                if p.get("status") in ("succeeded", "failed", "cancelled"):
                    return
                self.stop.wait(self.period)


def _wait_job(base: str, job_id: str, timeout: float = 900) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = httpx.get(f"{base}/api/v1/jobs/{job_id}", timeout=10).json()
        if job["status"] in ("succeeded", "failed", "cancelled"):
            return job
        time.sleep(0.5)
    raise TimeoutError(f"job {job_id} did not finish in {timeout} s")


def _offline_ate(seq_dir: Path, camera: str, preset: str, out: Path) -> tuple[float | None, float]:
    t0 = time.monotonic()
    subprocess.run([sys.executable, "-m", "cli.main", "run", str(seq_dir), "--camera", camera, "--preset", preset,
                    "--out", str(out), "--quiet"], check=True, stdout=subprocess.DEVNULL)
    m = json.loads((out / "metrics.json").read_text())
    return (m.get("ate") or {}).get("rmse"), time.monotonic() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_stream_args(ap)
    ap.add_argument("--poll", type=float, default=0.1, help="Seconds between polls of the page's endpoint.")
    ap.add_argument("--no-offline", action="store_true", help="Skip the offline run of the same frames.")
    args = ap.parse_args()

    source = tum_source(args.seq, args.max_frames)
    with tempfile.TemporaryDirectory(prefix="bench-live-") as tmp:
        port = _free_port()
        base = f"http://127.0.0.1:{port}"
        env = {**os.environ, "VTD_DATA_DIR": f"{tmp}/data", "VTD_PORT": str(port),
               "VTD_VIEWER_PORT": str(_free_port())}
        serve = subprocess.Popen([sys.executable, "-m", "cli.main", "serve"], env=env, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL)
        try:
            for _ in range(600):
                try:
                    if httpx.get(f"{base}/api/v1/health", timeout=2).status_code == 200:
                        break
                except httpx.HTTPError:
                    pass
                time.sleep(0.1)
            time.sleep(3)  # the worker and the viewer hub start beside the api
            session = create_session(base, None, args.camera, args.preset, "bench-live")
            job_id = session["job_id"]
            poller = PagePoller(base, job_id, args.poll)
            poller.start()
            wait_ready(base, job_id)
            viewer = threading.Timer(3.0, lambda: httpx.get(f"{base}/api/v1/jobs/{job_id}/viewer", timeout=30))
            viewer.start()  # the page opens the 3D viewer once the run has poses
            before = _stream_cpu(serve.pid)
            t0 = time.monotonic()
            report = send(base, session, source, rate=args.rate)
            stream_s = time.monotonic() - t0
            during = {r: c - before.get(r, 0.0) for r, c in _stream_cpu(serve.pid).items()}
            job = _wait_job(base, job_id)
            poller.stop.set()
            usage = [_usage(pid) for pid in _children(serve.pid)]
        finally:
            serve.send_signal(signal.SIGINT)
            serve.wait(60)
        _report(args, source, report, stream_s, job, poller, usage, during, Path(tmp))


def _stream_cpu(serve_pid: int) -> dict[str, float]:
    """CPU seconds so far of each `vtdslam serve` child and of this process (the client and the page poller)."""
    cpu = {role: c for role, _, c in (_usage(pid) for pid in _children(serve_pid))}
    t = os.times()
    cpu["bench (client + poller)"] = t.user + t.system
    return cpu


def _report(args, source, report, stream_s, job, poller, usage, during, tmp: Path) -> None:  # noqa: ANN001
    m = job.get("metrics") or {}
    page = np.array([1000 * (s - a) for s, a, _ in poller.seen.values() if a is not None])
    worker = np.array([1000 * (d - a) for _, a, d in poller.seen.values() if a is not None])
    received, dropped = m.get("live_frames_received"), m.get("live_frames_dropped")
    offline, offline_s = (None, None)
    if not args.no_offline and job["status"] == "succeeded":
        seq_dir = tmp / "data" / "sequences" / job["sequence_id"]
        offline, offline_s = _offline_ate(seq_dir, args.camera, args.preset, tmp / "offline")
    live_ate = (m.get("ate") or {}).get("rmse")
    rows = [
        ("sequence", f"{args.seq.name}, {len(source.frames)} frames sent at {args.rate:g} Hz in {stream_s:.1f} s"),
        ("preset / camera", f"{args.preset} / {args.camera}"),
        ("job", f"{job['status']}" + (f" ({job['error']})" if job.get("error") else "")),
        ("frames received / processed / dropped",
         f"{received} / {m.get('live_frames_processed')} / {dropped}"
         + (f" ({100 * dropped / received:.1f} % dropped)" if received and dropped is not None else "")),
        (f"arrival -> pose on the page (polled every {args.poll:g} s), median / p99 (ms)", _pct(page)),
        ("arrival -> pose in the worker, median / p99 (ms)", _pct(worker)),
        ("poses seen by the page poller", f"{len(page)} of {m.get('live_frames_processed')}"),
        ("peak memory api + worker + viewer (MB)",
         f"{sum(u[1] for u in usage):.0f} ({', '.join(f'{r} {p:.0f}' for r, p, _ in usage)})"),
        ("CPU seconds by process (whole session)", ", ".join(f"{r} {c:.1f}" for r, _, c in usage)),
        ("CPU seconds by process while the frames were sent", ", ".join(f"{r} {c:.1f}" for r, c in during.items())
         + f" of {2 * stream_s:.1f} on two cores"),
        ("ATE RMSE live (m)", _m(live_ate)),
        ("ATE RMSE offline, same frames (m)", _m(offline) + (f" ({offline_s:.0f} s)" if offline_s else "")),
        ("live / offline ATE", f"{live_ate / offline:.3f}" if live_ate and offline else "-"),
        ("live run: fps of the frames it ran; top steps (ms per call)",
         f"{_m(m.get('fps'))}; " + ", ".join(f"{k} {v:.0f}" for k, v in sorted(
             ((k, v) for k, v in (m.get("timings_ms") or {}).items() if isinstance(v, int | float)),
             key=lambda kv: -kv[1])[:4])
         + f"; snapshots {(m.get('timings_ms') or {}).get('snapshots', '-')} per frame"),
        ("offline fps, same frames, same machine", f"{len(source.frames) / offline_s:.1f}" if offline_s else "-"),
        ("load average at the end", " ".join(f"{x:.1f}" for x in os.getloadavg())),
    ]
    width = max(len(k) for k, _ in rows)
    print(f"\n{'measure'.ljust(width)} | value\n{'-' * width}-|------")
    for k, v in rows:
        print(f"{k.ljust(width)} | {v}")


def _pct(a: np.ndarray) -> str:
    return f"{np.median(a):.0f} / {np.percentile(a, 99):.0f}" if len(a) else "-"


def _m(v: float | None) -> str:
    return f"{v:.4f}" if isinstance(v, int | float) else "-"


if __name__ == "__main__":
    main()
