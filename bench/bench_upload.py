"""Upload throughput and api memory for a large sequence archive, over loopback.

Builds a ~1 GB .zip (stored, like a Bonn download: PNG frames do not compress) of a valid 640x480
TUM-layout sequence, starts the api alone (uvicorn, no worker) on a temp data dir, and uploads it:

- *rejected after the body*: the same archive with an unknown camera, refused once the body is in
  (the HTTP + multipart streaming path; a .tgz is also unpacked on the fly by then);
- *full upload*: streamed, unpacked, validated, installed (what a user waits for).

The api's RSS is sampled every 20 ms; the peak (VmHWM) shows whether memory stays flat. Prints a
markdown table. Usage: ``python bench/bench_upload.py [--size-mb 1024] [--keep]``.
"""
from __future__ import annotations

import argparse
import io
import os
import shutil
import signal
import socket
import subprocess
import sys
import tarfile
import tempfile
import threading
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def build_archive(path: Path, size_mb: int) -> tuple[int, int]:
    """A zip (stored) or .tgz (gzip level 1), by ``path``'s suffix, of one top-level folder with enough
    640x480 frames to reach ``size_mb``."""
    import cv2
    import numpy as np

    rng = np.random.default_rng(0)
    fast = [cv2.IMWRITE_PNG_COMPRESSION, 1]
    ok, rgb = cv2.imencode(".png", rng.integers(0, 255, (480, 640, 3), dtype=np.uint8), fast)
    ok2, depth = cv2.imencode(".png", rng.integers(500, 20000, (480, 640), dtype=np.uint16), fast)
    assert ok and ok2
    rgb_b, depth_b = rgb.tobytes(), depth.tobytes()
    frames = max(1, size_mb * 1024 * 1024 // (len(rgb_b) + len(depth_b)))
    stamps = [1000.0 + i / 30 for i in range(frames)]
    files = {
        "bench_seq/rgb.txt": ("# rgb\n" + "".join(f"{t:.6f} rgb/{t:.6f}.png\n" for t in stamps)).encode(),
        "bench_seq/depth.txt": ("# depth\n" + "".join(f"{t:.6f} depth/{t:.6f}.png\n" for t in stamps)).encode(),
    }
    for t in stamps:
        files[f"bench_seq/rgb/{t:.6f}.png"] = rgb_b
        files[f"bench_seq/depth/{t:.6f}.png"] = depth_b
    if path.suffix == ".zip":
        with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as zf:
            for name, data in files.items():
                zf.writestr(name, data)
    else:
        with tarfile.open(path, "w:gz", compresslevel=1) as tf:
            for name, data in files.items():
                info = tarfile.TarInfo(name)
                info.size = len(data)
                tf.addfile(info, io.BytesIO(data))
    return frames, path.stat().st_size


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _status(pid: int, key: str) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1]) * 1024
    return 0


class RssSampler(threading.Thread):
    def __init__(self, pid: int) -> None:
        super().__init__(daemon=True)
        self.pid, self.done = pid, threading.Event()
        self.samples: list[int] = []  # resident bytes, one every 20 ms

    def run(self) -> None:
        while not self.done.is_set():
            self.samples.append(_status(self.pid, "VmRSS"))
            time.sleep(0.02)


def upload(url: str, archive: Path, camera: str) -> tuple[int, float]:
    """POST with curl when present (a fast client), else httpx streaming the file."""
    t0 = time.perf_counter()
    if shutil.which("curl"):
        out = subprocess.run(
            ["curl", "-s", "-o", "/dev/null", "-w", "%{http_code}", "-F", f"camera={camera}",
             "-F", f"file=@{archive};type=application/zip", url],
            capture_output=True, text=True, check=True)
        code = int(out.stdout)
    else:
        import httpx

        with open(archive, "rb") as fh:
            code = httpx.post(url, files={"file": (archive.name, fh)}, data={"camera": camera}, timeout=600).status_code
    return code, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size-mb", type=int, default=1024)
    ap.add_argument("--runs", type=int, default=2, help="full uploads (the best is reported with all)")
    ap.add_argument("--format", choices=["zip", "tgz", "both"], default="both",
                    help="zip: Bonn-style stored zip (saved, then unpacked); "
                         "tgz: TUM-style (unpacked while it arrives)")
    ap.add_argument("--keep", action="store_true", help="keep the temp folder")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="vtd-bench-upload-", dir=os.environ.get("VTD_BENCH_TMP")))
    api = None
    try:
        port = _free_port()
        env = {k: v for k, v in os.environ.items() if not k.startswith("VTD_")}
        env.update(VTD_DATA_DIR=str(work / "data"), VTD_MAX_UPLOAD_BYTES=str(8 * 1024**3))
        api = subprocess.Popen([sys.executable, "-m", "uvicorn", "backend.app:create_app", "--factory",
                                "--port", str(port), "--log-level", "warning"], cwd=ROOT, env=env)
        url = f"http://127.0.0.1:{port}/api/v1/sequences"
        import httpx

        for _ in range(200):
            try:
                httpx.get(f"http://127.0.0.1:{port}/api/v1/health", timeout=1)
                break
            except httpx.HTTPError:
                time.sleep(0.1)
        rss_idle = _status(api.pid, "VmRSS")
        rows = []
        formats = ["zip", "tgz"] if args.format == "both" else [args.format]
        for fmt in formats:
            archive = work / f"bench_seq.{fmt}"
            t0 = time.perf_counter()
            frames, size = build_archive(archive, args.size_mb)
            print(f"{archive.name}: {size / 1e6:.0f} MB, {frames} frames, built in {time.perf_counter() - t0:.1f} s",
                  file=sys.stderr)
            cases = [("bad camera: rejected after the body (tgz: unpacked on the fly)", "tum9", 422)]
            cases += [("full upload (stream + unpack + validate + install)", "tum3", 201)] * args.runs
            for label, camera, expect in cases:
                subprocess.run(["sync"], check=False)  # start each run with no dirty pages pending
                sampler = RssSampler(api.pid)
                sampler.start()
                code, secs = upload(url, archive, camera)
                sampler.done.set()
                sampler.join()
                assert code == expect, f"{fmt} {label}: HTTP {code}"
                rows.append((f".{fmt} {size / 1e6:.0f} MB", label, code, secs, size / secs / 1e6,
                             max(sampler.samples) / 2**20))
            archive.unlink()
        peak = _status(api.pid, "VmHWM")
        print(f"\nUpload of ~{args.size_mb} MiB sequence archives ({frames} frames 640x480 PNG) to the api "
              f"(uvicorn, 1 process) on loopback, client curl, {os.cpu_count()} CPUs\n")
        print("| archive | run | HTTP | seconds | MB/s | api RSS max during (MiB) |")
        print("|---|---|---|---|---|---|")
        for arch, label, code, secs, mbps, rss in rows:
            print(f"| {arch} | {label} | {code} | {secs:.2f} | {mbps:.0f} | {rss:.0f} |")
        print(f"\napi RSS idle before: {rss_idle / 2**20:.0f} MiB; api peak RSS (VmHWM) over all runs: "
              f"{peak / 2**20:.0f} MiB")
    finally:
        if api is not None:
            api.send_signal(signal.SIGTERM)
            api.wait(30)
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
