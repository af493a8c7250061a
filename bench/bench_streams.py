"""Other requests' latency while many job event streams are open (issue 24: streams held the pool).

    .venv/bin/python bench/bench_streams.py [--streams 50] [--requests 200] [--database-url URL]

Starts the api (uvicorn, loopback) on a temp data dir, uploads a tiny sequence, marks a job running,
opens ``--streams`` ``GET /jobs/{id}/events`` streams and times ``--requests`` sequential
``GET /jobs/{id}`` and ``GET /jobs`` calls from a second client. Prints p50 / p99 / max. Asserts nothing.
"""
from __future__ import annotations

import argparse
import contextlib
import statistics
import sys
import tempfile
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from backend.app import create_app  # noqa: E402
from storage.settings import get_settings  # noqa: E402
from tests.backend.api.data import tar_gz, write_sequence  # noqa: E402
from tests.backend.api.live import serve  # noqa: E402
from tests.backend.api.test_streams import _open_stream, _running_job  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--streams", type=int, default=50)
    ap.add_argument("--requests", type=int, default=200)
    ap.add_argument("--database-url", default=None)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        seq = write_sequence(root / "seq" / "rgbd_dataset_bench", n=6)
        tgz = tar_gz(seq, root / "seq.tgz", top="rgbd_dataset_bench").read_bytes()
        settings = get_settings(data_dir=root / "data", database_url=args.database_url,
                                max_streams_per_client=args.streams + 1)
        app = create_app(settings, enqueue=lambda _job_id: None)
        with serve(app) as base, contextlib.ExitStack() as stack:
            job_id = _running_job(base, tgz, settings)
            client = stack.enter_context(httpx.Client(base_url=base, timeout=60,
                                                      limits=httpx.Limits(max_connections=args.streams + 5)))
            codes = [_open_stream(stack, client, job_id) for _ in range(args.streams)]
            times, statuses = [], []
            with httpx.Client(base_url=base, timeout=60) as other:
                for i in range(args.requests):
                    url = f"/api/v1/jobs/{job_id}" if i % 2 else "/api/v1/jobs"
                    t0 = time.perf_counter()
                    statuses.append(other.get(url).status_code)
                    times.append(time.perf_counter() - t0)
    times.sort()
    p99 = times[min(len(times) - 1, int(0.99 * len(times)))]
    print("| streams open | requests | non-200 | p50 ms | p99 ms | max ms | database |")
    print("|---|---|---|---|---|---|---|")
    print(f"| {codes.count(200)} | {len(times)} | {sum(s != 200 for s in statuses)} | "
          f"{statistics.median(times) * 1e3:.1f} | {p99 * 1e3:.1f} | {times[-1] * 1e3:.1f} | "
          f"{'postgresql' if args.database_url else 'sqlite'} |")


if __name__ == "__main__":
    main()
