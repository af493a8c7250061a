"""Real-time benchmark: end-to-end frames/s and per-stage ms of every preset, beside ORB-SLAM3; print markdown.

    .venv/bin/python bench/bench_realtime.py                      # Bonn crowd, 7-Scenes (1000 frames), synthetic room
    .venv/bin/python bench/bench_realtime.py --max-frames 150 --presets orb-only,full --no-orbslam3
    .venv/bin/python bench/bench_realtime.py --read-ahead 0       # frames decoded on the tracking thread

Every run is its own spawned process, so its peak RSS is its own. The machine may be shared: each run records
the 1-minute load average before and after it, and each preset's fps is also given as a ratio to `orb-only`
measured in the same benchmark on the same frames (the figure of merit that survives a noisy machine).

ORB-SLAM3 (optional, GPL-3.0, never a dependency of the service): `pip install pyorbslam3==0.1.1` (extra
`bench-orbslam3`); RGB-D mode without viewer, the vocabulary and settings of ../shared/models/orbslam3
(DATA.md). The vocabulary is gunzipped once into a cache folder outside the repository and handed over through
PYORBSLAM3_VOCAB. A sequence whose camera has no shipped settings gets settings written from its intrinsics
(the shipped Bonn file's layout and ORB parameters). ORB-SLAM3 is fed as fast as it takes frames (not paced at
the frame rate) unless --orbslam3-pace; its local mapping runs on its own thread, so unpaced it may fall behind.
Rows are skipped with the reason when the wheel, the vocabulary or the settings are absent.
Benchmarks print figures; they assert nothing.
"""
from __future__ import annotations

import argparse
import gzip
import importlib.util
import multiprocessing as mp
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sequence_spec import split_spec  # noqa: E402  (bench/, the script's own folder)

PRESETS = ("orb-only", "geometry-only", "no-restoration", "full")
REFERENCE = "orb-only"
ORBSLAM3 = "ORB-SLAM3 (RGB-D)"
VOCAB_GZ = "orbvoc_k10L5.txt.gz"


@dataclass
class Row:
    """One run: a method on a sequence, with the load average around it."""

    sequence: str
    method: str
    metrics: dict[str, Any] = field(default_factory=dict)
    load_before: float = 0.0
    load_after: float = 0.0
    skipped: str | None = None


def _shared() -> Path:
    return Path(os.environ.get("VTD_SHARED_DIR", ROOT.parent / "shared")).resolve()


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run_preset(seq_dir: str, camera: str | None, preset: str, max_frames: int | None, read_ahead: int) -> dict:
    """Child process: one pipeline run (no outputs written); its metrics with this process's peak RSS."""
    from sequence_spec import camera_of

    from worker.slam.io.sequence import Sequence
    from worker.slam.pipeline import run_pipeline
    from worker.slam.presets import get_preset

    seq = Sequence(seq_dir, camera_of(camera))
    res = run_pipeline(seq, get_preset(preset), None, max_frames=max_frames, read_ahead=read_ahead)
    m = dict(res.metrics)
    m["peak_rss_mb"] = round(_peak_rss_mb(), 1)
    return m


def run_orbslam3(seq_dir: str, camera: str, settings: str, vocab: str, max_frames: int | None,
                 pace: bool) -> dict:
    """Child process: ORB-SLAM3 RGB-D over the same frames, fed as cv2.imread gives them (BGR, raw depth)."""
    os.environ["PYORBSLAM3_VOCAB"] = vocab
    os.dup2(2, 1)  # ORB-SLAM3 prints its progress on stdout: keep the parent's tables clean
    import cv2
    import pyorbslam3
    from sequence_spec import camera_of

    from worker.slam.errors import EvaluationError
    from worker.slam.evaluation.metrics import evaluate
    from worker.slam.io.sequence import Sequence
    from worker.slam.io.trajectory import read_tum_trajectory

    seq = Sequence(seq_dir, camera_of(camera))
    refs = seq.frames[:max_frames] if max_frames is not None else seq.frames
    t0 = time.perf_counter()
    slam = pyorbslam3.Slam(vocab, settings, pyorbslam3.Sensor.RGBD, use_viewer=False)
    load_s = time.perf_counter() - t0
    ms, valid = [], 0
    t_loop = time.perf_counter()
    for ref in refs:
        if pace:  # wait for the frame's time, as a live camera would deliver it
            due = t_loop + ref.timestamp - refs[0].timestamp
            time.sleep(max(0.0, due - time.perf_counter()))
        t = time.perf_counter()
        bgr = cv2.imread(str(ref.rgb_path), cv2.IMREAD_COLOR)
        raw = cv2.imread(str(ref.depth_path), cv2.IMREAD_UNCHANGED)
        if bgr is None or raw is None:
            raise RuntimeError(f"cannot read {ref.rgb_path} or {ref.depth_path}")
        depth = raw.astype(np.float32)  # raw units; the settings' DepthMapFactor turns them into metres
        res = slam.track_rgbd(bgr, depth, ref.timestamp)
        ms.append((time.perf_counter() - t) * 1000)
        valid += int(res.pose_valid)
    loop_s = time.perf_counter() - t_loop
    slam.shutdown()
    m: dict[str, Any] = {"frames": len(refs), "tracked": valid, "lost": len(refs) - valid,
                         "fps": round(len(refs) / loop_s, 2), "tracking_fps": round(1000 / float(np.mean(ms)), 2),
                         "timings_ms": {"read+track": round(float(np.mean(ms)), 3)},
                         "vocabulary_load_s": round(load_s, 1)}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "trajectory.txt"
        slam.save_trajectory_tum(str(path))  # the final (BA- and loop-corrected) poses of tracked frames
        if seq.groundtruth is not None and path.is_file() and path.stat().st_size:
            try:
                m.update(evaluate(seq.groundtruth, read_tum_trajectory(path)).to_dict())
            except EvaluationError as exc:
                m["evaluation_error"] = exc.message
    m["peak_rss_mb"] = round(_peak_rss_mb(), 1)
    return m


def _in_child(fn: Callable[..., dict], *args: Any) -> dict:
    with mp.get_context("spawn").Pool(1) as pool:
        return pool.apply(fn, args)


def _timed_row(sequence: str, method: str, fn: Callable[..., dict], *args: Any) -> Row:
    before = os.getloadavg()[0]
    try:
        metrics = _in_child(fn, *args)
    except Exception as exc:  # one failing run is reported in its row; the others still run
        return Row(sequence, method, load_before=before, load_after=os.getloadavg()[0],
                   skipped=f"failed: {type(exc).__name__}: {exc}")
    return Row(sequence, method, metrics, before, os.getloadavg()[0])


def _vocabulary(models: Path) -> Path | str:
    """The gunzipped vocabulary in a cache folder outside the repository, or why it is unavailable."""
    src = models / VOCAB_GZ
    if not src.is_file():
        return f"no vocabulary {src}"
    cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "vtdslam-bench"
    dst = cache / src.name.removesuffix(".gz")
    if not dst.is_file() or dst.stat().st_mtime < src.stat().st_mtime:
        cache.mkdir(parents=True, exist_ok=True)
        part = dst.with_suffix(".part")
        with gzip.open(src, "rb") as fin, part.open("wb") as fout:
            shutil.copyfileobj(fin, fout)
        part.replace(dst)
    return dst


def _settings(models: Path, seq_dir: str, camera: str | None, work: Path) -> tuple[Path, str] | str:
    """(settings yaml, where it came from) for the sequence's camera, or why there are none."""
    from sequence_spec import camera_of

    from worker.slam.io.sequence import Sequence

    shipped = models / f"settings_{camera}.yaml"
    seq = Sequence(seq_dir, camera_of(camera))
    if seq.camera_source == "given" and shipped.is_file():
        return shipped, shipped.name
    template = models / "settings_bonn.yaml"
    if not template.is_file():
        return f"no ORB-SLAM3 settings for camera {camera!r} and no template {template}"
    cam = seq.camera
    values = {"Camera1.fx": f"{cam.fx:.6f}", "Camera1.fy": f"{cam.fy:.6f}", "Camera1.cx": f"{cam.cx:.6f}",
              "Camera1.cy": f"{cam.cy:.6f}", "Camera.width": str(cam.width), "Camera.height": str(cam.height),
              "RGBD.DepthMapFactor": f"{cam.depth_scale:.1f}"}
    text = template.read_text()
    for key, val in values.items():
        text = re.sub(rf"^{re.escape(key)}:.*$", f"{key}: {val}", text, flags=re.MULTILINE)
    out = work / f"orbslam3_{Path(seq_dir).name}.yaml"
    out.write_text(text)
    return out, f"written from {seq.camera_source} ({cam.name})"


def _orbslam3_unavailable(models: Path) -> str | None:
    if importlib.util.find_spec("pyorbslam3") is None:
        return "pyorbslam3 is not installed (pip install pyorbslam3==0.1.1, extra bench-orbslam3)"
    if not models.is_dir():
        return f"no {models}"
    return None


def _synth(work: Path, frames: int) -> str:
    """A synthetic room with walking people, rendered by `vtdslam synth`; DIR[:CAMERA]."""
    out = work / "synthetic_room"
    cmd = [sys.executable, "-c", "import sys; from cli.main import main; sys.exit(main())", "synth", str(out),
           "--frames", str(frames)]
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return f"{out}:tum3"  # its camera.json wins over the preset


def _f(x: float | None, nd: int = 4) -> str:
    return "-" if x is None else f"{x:.{nd}f}"


def _print_tables(rows: list[Row]) -> None:
    ref_fps = {r.sequence: r.metrics["fps"] for r in rows if r.method == REFERENCE and not r.skipped}
    print("| sequence | method | frames | lost | ATE rmse (m) | fps (end-to-end) | fps / orb-only | "
          "tracking fps | peak RSS (MB) | load avg 1 min (before → after) |")
    print("|" + "---|" * 10)
    for r in rows:
        if r.skipped:
            reason = " ".join(r.skipped.split())[:300]  # one table cell: OpenCV's messages span lines
            print(f"| {r.sequence} | {r.method} | skipped: {reason} |" + " |" * 7)
            continue
        m = r.metrics
        ate = m.get("ate", {}).get("rmse")
        ref = ref_fps.get(r.sequence)
        ratio = _f(m["fps"] / ref, 2) if ref else "-"
        print(f"| {r.sequence} | {r.method} | {m['frames']} | {m['lost']} | "
              f"{_f(ate) if ate is not None else m.get('evaluation_error', '-')} | {m['fps']} | {ratio} | "
              f"{m['tracking_fps']} | {m['peak_rss_mb']} | {r.load_before:.2f} → {r.load_after:.2f} |")
    ran = [r for r in rows if not r.skipped]
    stages = list(dict.fromkeys(s for r in ran for s in r.metrics["timings_ms"]))
    print("\nmean ms per call (read and the stages per frame; local_mapping/loop_closure per keyframe; "
          "global_ba and dense once; ORB-SLAM3: read + track per frame)\n")
    print("| sequence | method | " + " | ".join(stages) + " |")
    print("|" + "---|" * (2 + len(stages)))
    for r in ran:
        print(f"| {r.sequence} | {r.method} | " + " | ".join(_f(r.metrics["timings_ms"].get(s), 1) for s in stages)
              + " |")


def main() -> None:
    doc = __doc__ or ""
    ap = argparse.ArgumentParser(description=doc.split("\n")[0])
    ap.add_argument("--sequence", action="append",
                    help="DIR[:CAMERA] (default: bonn_crowd_dev:bonn and 7scenes_redkitchen:7scenes from ../shared)")
    ap.add_argument("--presets", default=",".join(PRESETS), help="comma-separated pipeline presets")
    ap.add_argument("--max-frames", type=int, default=None,
                    help="frames per sequence (default: all; 7-Scenes 1000; synthetic room 300)")
    ap.add_argument("--read-ahead", type=int, default=2, help="frames decoded ahead on a thread (0: none)")
    ap.add_argument("--no-synth", action="store_true", help="skip the synthetic room")
    ap.add_argument("--no-orbslam3", action="store_true", help="skip ORB-SLAM3")
    ap.add_argument("--orbslam3-pace", action="store_true", help="feed ORB-SLAM3 at the frame rate")
    args = ap.parse_args()

    data, models = _shared() / "data", _shared() / "models" / "orbslam3"
    presets = args.presets.split(",")
    if REFERENCE not in presets:
        presets.insert(0, REFERENCE)  # the ratio needs it in the same run
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        seqs: list[tuple[str, int | None]] = [(s, args.max_frames) for s in args.sequence or []] or [
            (f"{data / 'bonn_crowd_dev'}:bonn", args.max_frames),
            (f"{data / '7scenes_redkitchen'}:7scenes", args.max_frames or 1000)]
        if not args.no_synth:
            n = args.max_frames or 300
            seqs.append((_synth(work, n), n))
        why_not = None if not args.no_orbslam3 else "--no-orbslam3"
        why_not = why_not or _orbslam3_unavailable(models)
        vocab = None if why_not else _vocabulary(models)
        if isinstance(vocab, str):
            why_not = vocab
        for spec, n in seqs:
            seq_dir, camera = split_spec(spec)
            name = Path(seq_dir).name
            for preset in presets:
                rows.append(_timed_row(name, preset, run_preset, seq_dir, camera, preset, n, args.read_ahead))
                print(f"# {name} {preset}: done", file=sys.stderr, flush=True)
            settings = None if why_not else _settings(models, seq_dir, camera, work)
            if why_not or isinstance(settings, str):
                rows.append(Row(name, ORBSLAM3, skipped=why_not or str(settings)))
                continue
            assert settings is not None and isinstance(vocab, Path)
            path, source = settings
            row = _timed_row(name, ORBSLAM3, run_orbslam3, seq_dir, camera, str(path), str(vocab), n,
                             args.orbslam3_pace)
            row.method += f" [{'paced' if args.orbslam3_pace else 'unpaced'}; settings {source}]"
            rows.append(row)
    load = os.getloadavg()
    print(f"\nmachine: {os.cpu_count()} cores; load average now {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; "
          f"read-ahead {args.read_ahead}; frames per sequence: {args.max_frames or 'default'}\n")
    _print_tables(rows)


if __name__ == "__main__":
    main()
