"""Dense map cleanliness and accuracy per fusion method (point merge, TSDF, with or without carving); prints markdown.

    .venv/bin/python bench/bench_map.py --sequence SYNTH:tum3 --sequence AUG:7scenes --max-frames 300

Sequences with truth (`vtdslam synth` / `vtdslam augment`) get both checks, others the accuracy check
only (the people columns read "-"). For every method the pipeline runs
once (a spawned `vtdslam run`), then `map.ply` is checked two ways:

- *people in the map*: every 3rd frame's truly moving pixels (truth masks) are back-projected with that
  frame's measured depth at its ground-truth pose, brought into the map's world by a rigid fit of whole poses
  (`bench_slam.align_by_poses`; before 2026-12-04 the position-only fit of `groundtruth_aligned.txt`, which
  tilts the synthetic room's world by 4.4° and so counted floor under the walkers as people);
  the share of map points within 5 cm of any of them is reported. Static surfaces a person touched (the
  floor under a foot, a wall walked along) count there too, so a second column keeps only those points that
  are also more than 5 cm from the true static scene (the truth's background depth of the same frames):
  what is really a person in the map;
- *people in the map, real footage* (`--references TEACHER`, for sequences without truth such as
  ../shared/data/bonn_crowd_dev, evaluation only): every `--reference-every`-th frame's person pixels by the
  teacher (`reference_masks`: the 513 DeepLabV3 of bench_msnet, border band ignored, cached outside the
  repository) back-projected with the measured depth at the run's *estimated* poses (the map's own frame; no
  ground-truth convention involved); only the "near a person" column, as there is no true static scene;
- *accuracy*: bench_slam's check of map points against held-out frames' measured depth at their GT poses (and,
  last column, at the estimated poses: the map's agreement with the frames it did not fuse, free of any
  ground-truth convention such as Bonn's marker-to-camera offset).

Benchmarks print figures; they assert nothing.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

NEAR_M = 0.05


def _backproject(depth: np.ndarray, keep: np.ndarray, K: np.ndarray, T_WC: np.ndarray, stride: int) -> np.ndarray:
    ok = keep & (depth > 0)
    v, u = np.nonzero(ok)
    z = depth[ok].astype(np.float64)
    Xc = np.column_stack([(u * stride - K[0, 2]) / K[0, 0] * z, (v * stride - K[1, 2]) / K[1, 1] * z, z])
    return Xc @ T_WC[:3, :3].T + T_WC[:3, 3]


def gt_in_map_world(seq, traj) -> dict[int, np.ndarray]:
    """Frame index -> 4x4 ground-truth T_WC in the estimate's (the map's) world, for the frames of the run
    `traj` (from frame 0) that have a ground-truth pose; rigid fit of whole poses (see the module doc)."""
    from bench_slam import align_by_poses, poses_by_frame

    idx, gt = seq.groundtruth_for_frames()
    est = poses_by_frame(seq, traj)  # tracked frames only: matched by timestamp
    keep = np.array([int(i) in est for i in idx], dtype=bool)
    idx, gt = idx[keep], gt[keep]
    R, t = align_by_poses(gt, np.stack([est[int(i)] for i in idx]))
    A_inv = np.eye(4)  # gt world -> estimate world
    A_inv[:3, :3], A_inv[:3, 3] = R.T, -R.T @ t
    return {int(i): A_inv @ T for i, T in zip(idx, gt)}


def truth_points(seq, truth, poses: dict[int, np.ndarray], every: int = 3,
                 stride: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """World points (`poses`' world) of every `every`-th frame with a pose: the truly moving pixels (N,3), and
    the static scene behind everything (its true background depth) (M,3)."""
    K = seq.camera.K
    people, static = [], []
    for i in range(0, min(len(truth), len(seq)), every):
        if i not in poses:
            continue
        mask = truth.mask(i)[::stride, ::stride]
        people.append(_backproject(seq[i].depth[::stride, ::stride], mask, K, poses[i], stride))
        bg = truth.background_depth(i)[::2 * stride, ::2 * stride]
        static.append(_backproject(bg, np.ones(bg.shape, bool), K, poses[i], 2 * stride))
    return np.vstack(people), np.vstack(static)


def reference_people(seq, traj, teacher: Path, every: int, cache: Path, stride: int = 2,
                     erode_px: int = 8) -> np.ndarray:
    """(N,3) points, in the run's world, of the teacher's person pixels of every `every`-th tracked frame,
    at the estimated poses (see the module doc). The masks are eroded by `erode_px` first: a teacher's mask
    spills a few pixels past the silhouette, and there the depth is the wall behind, which would count the
    walls people walked past as people."""
    import cv2
    from bench_slam import poses_by_frame

    from worker.slam.segmentation.reference_masks import ReferenceRecipe, reference_masks

    est = poses_by_frame(seq, traj)  # tracked frames only: matched by timestamp
    frames = [i for i in range(0, len(seq), every) if i in est]
    masks = reference_masks([seq.frames[i].rgb_path for i in frames], ReferenceRecipe(teacher), cache)
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * erode_px + 1, 2 * erode_px + 1))
    pts = []
    for i, m in zip(frames, masks):
        ref = np.asarray(cv2.imread(str(m), cv2.IMREAD_UNCHANGED))
        person = cv2.erode((ref == 1).astype(np.uint8), disc) > 0
        pts.append(_backproject(seq[i].depth[::stride, ::stride], person[::stride, ::stride], seq.camera.K,
                                est[i], stride))
    return np.vstack(pts) if pts else np.zeros((0, 3))


def check(seq_dir: Path, camera: str, run: Path, references: tuple[Path, int, Path] | None = None) -> dict:
    from bench_slam import map_check
    from scipy.spatial import cKDTree

    from formats import artifacts
    from formats.ply import read_ply
    from formats.run_metrics import read_run_metrics
    from worker.slam.camera import load_camera_file, parse_camera
    from worker.slam.io.sequence import Sequence
    from worker.slam.io.trajectory import read_tum_trajectory
    from worker.slam.truth import load_truth

    seq = Sequence(seq_dir, load_camera_file(seq_dir) or parse_camera(camera))
    truth = load_truth(seq_dir)
    xyz, _ = read_ply(run / "map.ply")
    traj = read_tum_trajectory(run / "trajectory.txt")
    X = xyz.astype(np.float64)
    near = off_static = people = None
    if truth is not None:
        people, static = truth_points(seq, truth, gt_in_map_world(seq, traj))
        off_static = cKDTree(static).query(X, k=1)[0] > NEAR_M
    elif references is not None:
        people = reference_people(seq, traj, *references)
    if people is not None:
        near = cKDTree(people).query(X, k=1)[0] < NEAR_M if len(people) else np.zeros(len(xyz), bool)
    kf_stamps = read_tum_trajectory(run / "keyframes.txt").timestamps
    kf_frames = {int(i) for i in np.flatnonzero(np.isin(np.round(seq.timestamps, 6), np.round(kf_stamps, 6)))}
    metrics = read_run_metrics(run / artifacts.METRICS)
    near_share = float(near.mean()) if near is not None and len(xyz) else None
    on_share = float((near & off_static).mean()) if near is not None and off_static is not None and len(xyz) else None
    out = {"map_points": int(len(xyz)), "near_people": near_share, "on_people": on_share,
           "ate": metrics.ate.rmse if metrics.ate else None, "dense_ms": metrics.timings_ms.get("dense")}
    out.update(map_check(seq, traj, xyz, kf_frames, 0))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sequence", action="append", required=True, help="DIR:CAMERA (with truth/)")
    ap.add_argument("--methods", default="points,points+carve,tsdf",
                    help="comma-separated dense.method values, each optionally with +carve (dense.carve)")
    ap.add_argument("--preset", default="full")
    ap.add_argument("--max-frames", type=int, default=300)
    ap.add_argument("--out", default=None, help="where runs go (default: a temp folder)")
    ap.add_argument("--config", default=None, help="JSON overrides for every run (its `dense` keys are the methods')")
    ap.add_argument("--references", type=Path, default=None, metavar="TEACHER",
                    help="people in the map of sequences without truth, from this teacher's person masks "
                         "(e.g. ../shared/models/deeplabv3_mnv2_pascal_quant.tflite)")
    ap.add_argument("--reference-every", type=int, default=5, help="every n-th frame gets a reference mask")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/vtd_map_refs"),
                    help="where the reference masks are made once (never inside the repo)")
    args = ap.parse_args()
    if args.cache.resolve().is_relative_to(ROOT):
        ap.error("--cache must be outside the repository (reference masks are never committed)")
    refs = (args.references, args.reference_every, args.cache) if args.references else None
    extra = json.loads(args.config) if args.config else {}
    base = Path(args.out or tempfile.mkdtemp(prefix="bench_map_"))
    rows = []
    for spec in args.sequence:
        seq_dir, camera = spec.rsplit(":", 1)
        for method in args.methods.split(","):
            run = base / f"{Path(seq_dir).name}_{method}"
            cmd = [str(ROOT / ".venv/bin/vtdslam"), "run", seq_dir, "--camera", camera, "--out", str(run),
                   "--preset", args.preset, "--max-frames", str(args.max_frames),
                   "--config", json.dumps({**extra, "dense": {**extra.get("dense", {}), "method": method.split("+")[0],
                                                              "carve": "+carve" in method}})]
            subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
            rows.append((Path(seq_dir).name, method, check(Path(seq_dir), camera, run, refs)))
    print(f"runs in {base}\n")
    print(f"| sequence | dense map | points | within {NEAR_M * 100:.0f} cm of a person | of those, off the static "
          "scene | median to held-out depth, GT poses (m) | within 5 cm | ATE (m) | dense ms | median, estimated "
          "poses (m) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, method, r in rows:
        share = "-" if r["near_people"] is None else f"{100 * r['near_people']:.2f} %"
        on = "-" if r["on_people"] is None else f"{100 * r['on_people']:.2f} %"
        med = "-" if r.get("median_m_gt") is None else f"{r['median_m_gt']:.4f}"
        w5 = "-" if r.get("within_5cm_gt") is None else f"{r['within_5cm_gt']:.3f}"
        ate = "-" if r["ate"] is None else f"{r['ate']:.4f}"
        est = "-" if r.get("median_m_est") is None else f"{r['median_m_est']:.4f}"
        print(f"| {name} | {method} | {r['map_points']} | {share} | {on} | {med} | {w5} | {ate} | {r['dense_ms']} | "
              f"{est} |")


if __name__ == "__main__":
    main()
