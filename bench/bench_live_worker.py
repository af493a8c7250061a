"""The worker's live runner alone, without api, viewer or network: a thread spools a sequence's frames at a fixed
rate (as the api keeps them: files in place, then the spool line), `worker.live.run_live_slam` follows with a
snapshot writer; prints frames dropped, ATE, and where the CPU went while the frames came: milliseconds of CPU
per frame run, by thread (pipeline, feed/reader, each prepare thread, snapshot writers) and for the process.

    .venv/bin/python bench/bench_live_worker.py [--seq ../shared/data/bonn_crowd_dev] [--rate 30] [--max-frames N]

CPU per frame by thread says which lane limits the rate and is far less sensitive to other load on the machine than
the drops are. Runs from any checkout (it uses that checkout's `worker.live`): run it from two worktrees back to
back to compare. Benchmarks print figures; they assert nothing.
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, os.getcwd())  # the checkout it is run from

from live_args import add_stream_args  # noqa: E402 (bench/, the script's own folder)

from cli.stream.source import tum_source  # noqa: E402
from storage.artifacts import ArtifactStore  # noqa: E402
from storage.live import LiveSpool, SpooledFrame  # noqa: E402
from worker.live import run_live_slam  # noqa: E402
from worker.snapshots import PartialWriter  # noqa: E402


def _cpu_by_thread() -> dict[str, float]:
    """CPU seconds of each live Python thread (by name, pool suffixes removed) and of the whole process."""
    out = {"process": time.process_time()}
    tick = os.sysconf("SC_CLK_TCK")
    for t in threading.enumerate():
        try:
            f = Path(f"/proc/self/task/{t.native_id}/stat").read_text().rsplit(")", 1)[1].split()
        except (OSError, TypeError):
            continue
        out[t.name.rstrip("_0123456789")] = (int(f[11]) + int(f[12])) / tick
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    add_stream_args(ap)
    args = ap.parse_args()

    src = tum_source(args.seq, args.max_frames)
    data = [(t, r.read_bytes(), d.read_bytes(), r.suffix) for t, r, d in src.frames]
    tmp = Path(tempfile.mkdtemp(prefix="bench-live-worker-"))
    spool = LiveSpool(tmp / "seq")
    spool.create()
    ready = threading.Event()
    marks: dict[str, dict[str, float]] = {}
    loads: dict[str, float] = {}

    def feed() -> None:
        ready.wait()
        marks["start"], loads["start"] = _cpu_by_thread(), os.getloadavg()[0]
        t0 = time.monotonic()
        for i, (t, rgb, depth, ext) in enumerate(data):
            time.sleep(max(0.0, t0 + i / args.rate - time.monotonic()))
            name = f"{t:.6f}"
            (spool.folder / f"rgb/{name}{ext}").write_bytes(rgb)
            (spool.folder / f"depth/{name}.png").write_bytes(depth)
            spool.append(SpooledFrame(i, t, round(time.time(), 6), f"rgb/{name}{ext}", f"depth/{name}.png"))
        time.sleep(0.3)  # the last frames run
        marks["end"], loads["end"] = _cpu_by_thread(), os.getloadavg()[0]
        if src.groundtruth:
            (spool.folder / "groundtruth.txt").write_text(src.groundtruth)
        spool.end("client ended the stream", len(data))

    def progress(done: int, total: int, stage: str) -> None:
        if stage == "waiting for frames":
            ready.set()

    threading.Thread(target=feed, name="spooler", daemon=True).start()
    writer = PartialWriter(ArtifactStore(tmp / "data"), "bench")
    try:
        out = run_live_slam(spool.folder, {"preset": args.camera}, args.preset, {}, tmp / "out", progress=progress,
                            should_cancel=lambda: False, snapshot=writer)
    finally:
        writer.close()
        shutil.rmtree(tmp, ignore_errors=True)
    m = out.metrics
    n = m["live_frames_processed"]
    a, b = marks["start"], marks["end"]
    per = {k: 1000 * (b[k] - a.get(k, 0.0)) / n for k in b if k != "spooler"}
    rows = [
        ("sequence", f"{args.seq.name}: {len(data)} frames at {args.rate:g} Hz, preset {args.preset}"),
        ("frames received / run / dropped", f"{m['live_frames_received']} / {n} / {m['live_frames_dropped']} "
                                            f"({100 * m['live_frames_dropped'] / m['live_frames_received']:.1f} %)"),
        ("ATE RMSE live (m)", f"{(m.get('ate') or {}).get('rmse', float('nan')):.4f}"),
        ("CPU ms per frame run, whole process", f"{per.pop('process'):.1f}"),
        ("CPU ms per frame run, by thread", ", ".join(f"{k} {v:.1f}" for k, v in sorted(per.items(),
                                                                                          key=lambda kv: -kv[1]))),
        ("snapshots on the pipeline thread (ms per frame)", f"{1000 * writer.spent_s / max(1, writer.frames):.2f}"),
        ("load average, start -> end of the stream", f"{loads['start']:.1f} -> {loads['end']:.1f}"),
    ]
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k.ljust(width)} | {v}")


if __name__ == "__main__":
    main()
