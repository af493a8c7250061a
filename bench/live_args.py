"""The stream options the two live benchmarks share (`bench_live.py`, `bench_live_worker.py`)."""
from __future__ import annotations

import argparse
import os
from pathlib import Path


def add_stream_args(ap: argparse.ArgumentParser) -> None:
    """--seq (default: ../shared's bonn_crowd_dev), --camera, --preset, --rate (Hz), --max-frames."""
    shared = Path(os.environ.get("VTD_SHARED_DIR", "../shared"))
    ap.add_argument("--seq", type=Path, default=shared / "data/bonn_crowd_dev")
    ap.add_argument("--camera", default="bonn")
    ap.add_argument("--preset", default="no-restoration")
    ap.add_argument("--rate", type=float, default=30.0)
    ap.add_argument("--max-frames", type=int, default=None)
