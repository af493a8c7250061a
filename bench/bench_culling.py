"""Culling cost per frame on real images: `cull_frame` alone, guided vs brute-force matching.

    .venv/bin/python bench/bench_culling.py SEQ_DIR [--camera 7scenes] [--frames 60] [--lag 10]
    .venv/bin/python bench/bench_culling.py SEQ_DIR --camera bonn --pipeline no-restoration [--record CALLS]
    .venv/bin/python bench/bench_culling.py --replay CALLS [--passes 3]

SEQ_DIR is a sequence with truth (`vtdslam augment` / `vtdslam synth` output): its truth masks stand in for the
segmentation and its ground-truth poses, perturbed by 5 mm and 0.3° like a motion-model prediction, give the
predicted relative pose, so the figures isolate culling from the network and the tracker. ORB extraction is
not included (tracking needs it anyway). Wall time (run it on a quiet machine) and the calling thread's CPU
time; not the process's CPU time, which OpenCV's spinning worker threads inflate on an idle core.

`--pipeline PRESET` times `cull_frame` inside a whole run of that preset instead (any sequence, e.g. the real
../shared/data/bonn_crowd_dev): the preset's segmenter and the tracker's own predictions, every stage on one
thread (no read-ahead) so nothing else runs while it is timed. `--record CALLS` also saves every call's inputs
and result (a pickle of this tool's own making: ~2 MB per VGA frame); `--replay CALLS` times `cull_frame` on them
again (the calling thread's CPU time, best of `--passes` passes) and counts the results that differ from the
recorded ones: run it from two checkouts in turn to compare code on the same inputs, outputs included, with
none of the run's other threads or the tracker in the figure. Benchmarks print figures; they assert nothing.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import pickle
import sys
import time
from pathlib import Path
from unittest import mock

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worker.slam.camera import parse_camera  # noqa: E402
from worker.slam.catalog import shipped_catalog  # noqa: E402
from worker.slam.config import PipelineConfig  # noqa: E402
from worker.slam.dynamic import stage as culling_stage  # noqa: E402
from worker.slam.dynamic.culling import CullingConfig, CullingResult, cull_frame  # noqa: E402
from worker.slam.dynamic.stage import CullingStage  # noqa: E402
from worker.slam.features.orb import OrbExtractor  # noqa: E402
from worker.slam.geometry.se3 import inv  # noqa: E402
from worker.slam.io.sequence import Sequence  # noqa: E402
from worker.slam.pipeline import run_pipeline  # noqa: E402
from worker.slam.truth import load_truth  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequence", type=Path, nargs="?")
    ap.add_argument("--camera", default="7scenes")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--lag", type=int, default=10)
    ap.add_argument("--pipeline", metavar="PRESET", help="time culling inside a run of this pipeline preset")
    ap.add_argument("--record", type=Path, metavar="CALLS", help="with --pipeline: save every call to this file")
    ap.add_argument("--replay", type=Path, metavar="CALLS", help="time the calls saved by --record")
    ap.add_argument("--passes", type=int, default=3, help="passes over the saved calls (--replay)")
    args = ap.parse_args()
    if args.replay:
        if args.passes < 1 or not args.replay.is_file():
            ap.error(f"--replay needs an existing file and --passes >= 1 ({args.replay}, {args.passes})")
        _replay(args.replay, args.passes)
        return
    if args.sequence is None:
        ap.error("give SEQ_DIR (or --replay CALLS)")
    if args.record and not args.pipeline:
        ap.error("--record needs --pipeline PRESET")
    if args.pipeline:
        _in_pipeline(args.sequence, args.camera, args.pipeline, args.record)
        return
    seq, truth = Sequence(args.sequence, parse_camera(args.camera)), load_truth(args.sequence)
    if truth is None:
        ap.error(f"{args.sequence} has no truth (make one with `vtdslam augment` or `vtdslam synth`)")
    extractor = OrbExtractor(PipelineConfig().features)
    gt_idx, gt_poses = seq.groundtruth_for_frames()
    pose = dict(zip(gt_idx.tolist(), gt_poses))
    noise = np.eye(4)
    noise[:3, :3] = Rotation.from_euler("y", 0.3, degrees=True).as_matrix()
    noise[:3, 3] = [0.005, 0, 0]
    frames = []
    for i in range(min(args.frames + args.lag, len(seq))):
        f = seq[i]
        frames.append((extractor.extract(cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY), f.depth), f.depth,
                       truth.mask(i), pose.get(i)))
    K = seq.camera.K
    print(f"| {args.sequence.name}, lag {args.lag} | frames | matches | guided | wall ms median | wall ms p90 | "
          "thread CPU ms median |")
    print("|---|---|---|---|---|---|---|")
    for label, use_pose in (("brute force", False), ("guided", True)):
        ts, cpu, n, guided = [], [], [], 0
        for k in range(args.lag, len(frames)):
            (fp, dp, _, Tp), (fc, dc, mc, Tc) = frames[k - args.lag], frames[k]
            T = noise @ inv(Tc) @ Tp if use_pose and Tp is not None and Tc is not None else None
            t0, c0 = time.perf_counter(), time.thread_time()
            res = cull_frame(fp.uv, fp.desc, fc.uv, fc.desc, dc, mc, None, CullingConfig(), dp, K, T)
            ts.append(1000 * (time.perf_counter() - t0))
            cpu.append(1000 * (time.thread_time() - c0))
            n.append(res.matches)
            guided += res.guided
        print(f"| {label} | {len(ts)} | {np.median(n):.0f} | {guided} | {np.median(ts):.1f} | "
              f"{np.percentile(ts, 90):.1f} | {np.median(cpu):.1f} |", flush=True)


def _in_pipeline(root: Path, camera: str, preset: str, record: Path | None = None) -> None:
    """`cull_frame`'s wall time per frame in a run of `preset` on `root`, all stages on this thread; with
    `record`, every call's arguments and result saved there."""
    catalog = shipped_catalog()
    seq, config = Sequence(root, parse_camera(camera)), catalog.preset(preset)
    stages = catalog.build_stages(config, seq.camera)
    calls: list[tuple[tuple, dict, CullingResult]] = []

    def recorded(*a, **k) -> CullingResult:
        out = cull_frame(*a, **k)
        calls.append((a, k, out))
        return out

    with mock.patch.object(culling_stage, "cull_frame", recorded) if record else contextlib.nullcontext():
        res = run_pipeline(seq, config, None, stages=stages, read_ahead=0)
    culling = next(s for s in stages if isinstance(s, CullingStage))
    ms = np.array(culling.decision_ms)
    print(f"| {root.name}, `{preset}`, one thread | frames culled | guided | cull_frame ms median | p90 | mean | "
          "ATE rmse (m) | lost |")
    print("|---|---|---|---|---|---|---|---|")
    ate = res.metrics.get("ate", {}).get("rmse")
    print(f"| | {len(ms)} | {culling.guided} | {np.median(ms):.1f} | {np.percentile(ms, 90):.1f} | "
          f"{ms.mean():.1f} | {ate if ate is None else round(ate, 4)} | {res.metrics['lost']} |")
    if record:
        with open(record, "wb") as f:
            pickle.dump(calls, f, protocol=pickle.HIGHEST_PROTOCOL)
        print(f"{len(calls)} calls saved to {record}")


def _replay(path: Path, passes: int) -> None:
    """Thread CPU ms of `cull_frame` on the calls saved by `--record`, and how many results differ."""
    with open(path, "rb") as f:
        calls = pickle.load(f)  # this tool's own file (see the module docstring)
    for a, k, _ in calls[:20]:  # compiled kernels and caches warm
        cull_frame(*a, **k)
    best: np.ndarray | None = None
    differ = 0
    for p in range(passes):
        ms = []
        for a, k, want in calls:
            c0 = time.thread_time()
            got = cull_frame(*a, **k)
            ms.append(1000 * (time.thread_time() - c0))
            differ += p == 0 and not _same(got, want)
        if best is None or np.median(ms) < np.median(best):
            best = np.array(ms)
    assert best is not None
    print(f"| {path.name} | calls | thread CPU ms median | p90 | mean | results unlike the recorded ones |")
    print("|---|---|---|---|---|---|")
    print(f"| best of {passes} passes | {len(calls)} | {np.median(best):.2f} | {np.percentile(best, 90):.2f} | "
          f"{best.mean():.2f} | {differ} |")


def _same(a: CullingResult, b: CullingResult) -> bool:
    """Every field equal (arrays element by element), the entropy included."""
    return all(np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y
               for x, y in ((getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a)))


if __name__ == "__main__":
    main()
