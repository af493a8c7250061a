"""Benchmark the SLAM pipeline presets against OpenCV 5's cv2.Odometry on the same frames; print markdown.

    .venv/bin/python bench/bench_slam.py                       # 7-Scenes redkitchen, all frames, orb-only
    .venv/bin/python bench/bench_slam.py --max-frames 300 --presets orb-only --sequence DIR[:CAMERA]

Every run is a separate (spawned) process, so its peak RSS is its own. Tables: accuracy and speed, mean ms
per stage, and a check of map.ply: each dense-map point (map aligned rigidly to ground truth through the
trajectory's poses) seen by a held-out (non-keyframe) frame at its ground-truth pose gets the distance to
the nearest point of that frame's measured depth; the median is reported, and the same with estimated poses
(the map's self-consistency).
Benchmarks print figures; they assert nothing.
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sequence_spec import split_spec  # noqa: E402  (bench/, the script's own folder)


def _shared() -> Path:
    return Path(os.environ.get("VTD_SHARED_DIR", ROOT.parent / "shared")).resolve()


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run_preset(seq_dir: str, camera: str | None, preset: str, start: int, max_frames: int | None, out: str,
               overrides: dict | None) -> dict:
    """Child process: one pipeline run; returns its metrics plus the map check."""
    from sequence_spec import camera_of

    from worker.slam.io.sequence import Sequence
    from worker.slam.pipeline import run_pipeline
    from worker.slam.presets import get_preset

    seq = Sequence(seq_dir, camera_of(camera))
    res = run_pipeline(seq, get_preset(preset, overrides), out, start=start, max_frames=max_frames)
    m = dict(res.metrics)
    if seq.groundtruth is not None and res.cloud is not None:
        kf_frames = {kf.frame_index for kf in res.slam_map.keyframes}
        m["map_check"] = map_check(seq, res.trajectory, res.cloud[0], kf_frames, start)
    m["peak_rss_mb"] = round(_peak_rss_mb(), 1)
    return m


def run_odometry(seq_dir: str, camera: str | None, start: int, max_frames: int | None) -> dict:
    """Child process: cv2.Odometry (RGB + depth, frame to frame) over the same frames."""
    import cv2
    from sequence_spec import camera_of

    from worker.slam.evaluation.groundtruth_frame import evaluate_framed
    from worker.slam.geometry.se3 import inv, orthonormalize
    from worker.slam.io.sequence import Sequence
    from worker.slam.io.trajectory import Trajectory

    seq = Sequence(seq_dir, camera_of(camera))
    stop = len(seq) if max_frames is None else min(len(seq), start + max_frames)
    settings = cv2.OdometrySettings()
    prev, poses, stamps, fails, ms, cpu = None, [], [], 0, [], []
    for i in range(start, stop):
        f = seq[i]
        if prev is None:
            settings.setCameraMatrix(seq.camera.K.astype(np.float32))
            odo = cv2.Odometry(cv2.OdometryType_RGB_DEPTH, settings, cv2.OdometryAlgoType_COMMON)
        t0, c0 = time.perf_counter(), time.process_time()
        fr = cv2.OdometryFrame(f.depth, cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY))
        odo.prepareFrame(fr)
        if prev is None:
            T = np.eye(4)
        else:
            ok, Rt = odo.compute(prev, fr)  # Rt maps points of the previous camera into the current one
            if ok:
                T = poses[-1] @ inv(Rt)
            else:
                fails += 1
                T = poses[-1]
        ms.append((time.perf_counter() - t0) * 1000)
        cpu.append((time.process_time() - c0) * 1000)
        prev = fr
        poses.append(T)
        stamps.append(f.timestamp)
    traj = Trajectory(np.array(stamps), orthonormalize(np.stack(poses)))
    m = {"frames": len(poses), "tracked": len(poses) - fails, "lost": fails, "relocalisations": 0,
         "keyframes": 0, "fps": round(1000 / np.mean(ms), 2), "tracking_fps": round(1000 / np.mean(ms), 2),
         "tracking_cpu_ms": round(float(np.mean(cpu)), 3), "timings_ms": {"odometry": round(float(np.mean(ms)), 3)}}
    if seq.groundtruth is not None:
        m.update(evaluate_framed(seq.groundtruth, traj, seq.camera.groundtruth_frame).to_dict())
    m["peak_rss_mb"] = round(_peak_rss_mb(), 1)
    return m


def align_by_poses(gt: np.ndarray, est: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R 3x3, t 3): X_gt = R X_est + t from the same frames' (N,4,4) T_WC in both worlds, by the chordal mean
    of the rotations, then the centroids. Unlike a position-only fit (Umeyama, the ATE convention) it stays
    well-posed on short, nearly straight trajectories, where a position-only fit can tilt the world by
    degrees (4.4° on the synthetic room): fine for ATE, wrong for placing truth images in the map's world."""
    U, _, Vt = np.linalg.svd(np.einsum("nij,nkj->ik", gt[:, :3, :3], est[:, :3, :3]))
    R = U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt
    return R, (gt[:, :3, 3] - est[:, :3, 3] @ R.T).mean(0)


def poses_by_frame(seq, traj, tol_s: float = 1e-4) -> dict[int, np.ndarray]:
    """Frame index of `seq` -> the estimated T_WC of `traj` (a run's trajectory: tracked frames only, so
    matched by timestamp, never by position)."""
    stamps = np.asarray(seq.timestamps, dtype=np.float64)
    out = {}
    for t, T in zip(traj.timestamps, traj.poses):
        k = int(np.searchsorted(stamps, t - tol_s))  # the first frame not before t - tol_s: the only candidate
        if k < len(stamps) and abs(stamps[k] - t) <= tol_s:
            out[k] = T
    return out


def map_check(seq, traj, xyz: np.ndarray, kf_frames: set[int], start: int, n_views: int = 8) -> dict:
    """Distance of map points to the measured surface of held-out frames, placed at their GT poses.

    The map is aligned rigidly to GT through the trajectory; each held-out (non-keyframe) frame's depth is
    back-projected at its GT pose; every map point inside that frame's view gets the distance to its nearest
    measured point. Median over views (metres); the same with the estimated poses shows self-consistency.
    """
    from scipy.spatial import cKDTree

    idx, gt = seq.groundtruth_for_frames()
    by_frame = poses_by_frame(seq, traj)  # the run's tracked frames (`start` is implied by the timestamps)
    in_run = np.array([int(i) in by_frame for i in idx], dtype=bool)
    idx, gt = idx[in_run], gt[in_run]
    est = np.stack([by_frame[int(i)] for i in idx]) if len(idx) else np.zeros((0, 4, 4))
    R, t = align_by_poses(gt, est)
    X_gt = xyz.astype(np.float64) @ R.T + t  # map in the ground-truth world
    X_est = xyz.astype(np.float64)
    held = [i for i in range(len(idx)) if idx[i] not in kf_frames]
    pick = [held[k] for k in np.linspace(0, len(held) - 1, min(n_views, len(held))).astype(int)]
    K = seq.camera.K
    out: dict = {"views": len(pick)}
    for key, poses, X in (("gt", gt, X_gt), ("est", est, X_est)):
        dists = []
        for k in pick:
            depth = seq[int(idx[k])].depth
            surf = _backproject(depth, K, poses[k], stride=2)
            dists.append(cKDTree(surf).query(X[_in_view(X, poses[k], K, depth)], k=1)[0])
        d = np.concatenate(dists) if dists else np.zeros(0)
        out[f"median_m_{key}"] = float(np.median(d)) if len(d) else None
        out[f"within_5cm_{key}"] = float(np.mean(d < 0.05)) if len(d) else None
        out["points"] = int(len(d))
    return out


def _backproject(depth: np.ndarray, K: np.ndarray, T_WC: np.ndarray, stride: int) -> np.ndarray:
    d = depth[::stride, ::stride]
    v, u = np.mgrid[0:d.shape[0], 0:d.shape[1]] * stride
    ok = d > 0
    z = d[ok].astype(np.float64)
    Xc = np.column_stack([(u[ok] - K[0, 2]) / K[0, 0] * z, (v[ok] - K[1, 2]) / K[1, 1] * z, z])
    return Xc @ T_WC[:3, :3].T + T_WC[:3, 3]


def _in_view(X: np.ndarray, T_WC: np.ndarray, K: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """bool (N,): world points that project into the frame where it measured depth."""
    h, w = depth.shape
    Pc = (X - T_WC[:3, 3]) @ T_WC[:3, :3]
    z = np.maximum(Pc[:, 2], 1e-6)
    u = np.round(K[0, 0] * Pc[:, 0] / z + K[0, 2]).astype(int)
    v = np.round(K[1, 1] * Pc[:, 1] / z + K[1, 2]).astype(int)
    ok = (Pc[:, 2] > 0.1) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    ok[ok] = depth[v[ok], u[ok]] > 0
    return ok


def _in_child(fn, *args):
    with mp.get_context("spawn").Pool(1) as pool:
        return pool.apply(fn, args)


def _f(x, nd=4):
    return "-" if x is None else f"{x:.{nd}f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sequence", action="append", help="DIR[:CAMERA] (default: 7-Scenes redkitchen:7scenes)")
    ap.add_argument("--presets", default="orb-only", help="comma-separated pipeline presets")
    ap.add_argument("--start", type=int, default=0)
    ap.add_argument("--max-frames", type=int, default=None)
    ap.add_argument("--config", default=None, help="JSON overrides applied to every preset")
    ap.add_argument("--no-baseline", action="store_true", help="skip cv2.Odometry")
    args = ap.parse_args()
    import json

    seqs = args.sequence or [f"{_shared() / 'data' / '7scenes_redkitchen'}:7scenes"]
    overrides = json.loads(args.config) if args.config else None
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for spec in seqs:
            seq_dir, camera = split_spec(spec)
            name = Path(seq_dir).name
            for preset in args.presets.split(","):
                t0 = time.perf_counter()
                m = _in_child(run_preset, seq_dir, camera, preset, args.start, args.max_frames,
                              str(Path(tmp) / f"{name}-{preset}"), overrides)
                rows.append((name, preset, m, time.perf_counter() - t0))
            if not args.no_baseline:
                t0 = time.perf_counter()
                m = _in_child(run_odometry, seq_dir, camera, args.start, args.max_frames)
                rows.append((name, "cv2.Odometry (RGB-D, frame-to-frame)", m, time.perf_counter() - t0))
    print(f"\nframes: start {args.start}, max {args.max_frames or 'all'}; machine: {os.cpu_count()} cores\n")
    print("| sequence | method | frames | tracked | lost | reloc | KFs | loops | ATE rmse (m) | ATE mean (m) | "
          "ATE corrected (m) | RPE trans (m/s) | RPE rot (deg/s) | RPE trans (m/frame) | RPE rot (deg/frame) | "
          "fps (end-to-end) | tracking fps | tracking CPU ms/frame | "
          "peak RSS (MB) |")
    print("|" + "---|" * 19)
    for name, method, m, _ in rows:
        ate, rpe, rpe_f = m.get("ate", {}), m.get("rpe", {}), m.get("rpe_frame", {})
        print(f"| {name} | {method} | {m['frames']} | {m['tracked']} | {m['lost']} | {m['relocalisations']} | "
              f"{m['keyframes']} | {m.get('loops_applied', '-')} | {_f(ate.get('rmse'))} | {_f(ate.get('mean'))} | "
              f"{_f(m.get('ate_corrected', {}).get('rmse'))} | "
              f"{_f(rpe.get('trans', {}).get('rmse'))} | {_f(rpe.get('rot_deg', {}).get('rmse'), 2)} | "
              f"{_f(rpe_f.get('trans', {}).get('rmse'))} | {_f(rpe_f.get('rot_deg', {}).get('rmse'), 3)} | "
              f"{m['fps']} | {m['tracking_fps']} | {m.get('tracking_cpu_ms')} | {m['peak_rss_mb']} |")
    stages = sorted({s for _, _, m, _ in rows for s in m["timings_ms"]})
    print("\nmean ms per call (tracking/read/stages per frame; local_mapping/loop_closure per keyframe; dense once)\n")
    print("| sequence | method | " + " | ".join(stages) + " |")
    print("|" + "---|" * (2 + len(stages)))
    for name, method, m, _ in rows:
        print(f"| {name} | {method} | " + " | ".join(_f(m["timings_ms"].get(s), 1) for s in stages) + " |")
    checks = [(n, p, m) for n, p, m, _ in rows if "map_check" in m]
    if checks:
        print("\nmap.ply check: distance of map points to the measured depth of held-out frames (map aligned to GT "
              "through the trajectory; frames at GT poses, and at estimated poses)\n")
        print("| sequence | method | dense points | views | points checked | median, GT poses (m) | within 5 cm | "
              "median, est. poses (m) | within 5 cm |")
        print("|---|---|---|---|---|---|---|---|---|")
        for name, method, m in checks:
            c = m["map_check"]
            print(f"| {name} | {method} | {m['dense_points']} | {c['views']} | {c['points']} | "
                  f"{_f(c['median_m_gt'])} | {_f(c['within_5cm_gt'], 3)} | {_f(c['median_m_est'])} | "
                  f"{_f(c['within_5cm_est'], 3)} |")


if __name__ == "__main__":
    main()
