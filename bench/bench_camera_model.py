"""Which camera model and which trajectory do a sequence's own images agree with? Print markdown.

    .venv/bin/python bench/bench_camera_model.py --sequence ../shared/data/7scenes_redkitchen:7scenes \
        [--estimate RUN/trajectory.txt]

Up to four tables, all from the images and the sequence's ground truth (nothing is fitted to ATE):

1. *Colour focal length*: ORB matches between colour frames 20 and 40 apart, and the epipolar (Sampson)
   distance of each match under the ground-truth relative pose, for a range of focal lengths (principal point
   as the camera's). The focal length the colour images were taken with gives the smallest distances.
2. *Depth focal length*: each depth frame's points moved by the ground-truth relative pose into a frame 10-300
   frames away and compared with that frame's depth (share within 5 cm, median difference of those), for a range
   of focal lengths of the depth image.
3. *Trajectory against depth* (with `--estimate`): the same depth comparison for frame pairs 5-15 and 150+ frames
   apart, at the ground truth's relative poses and at the estimate's.

4. *Depth edges in a pose graph* (with `--estimate --pose-graph`): the estimate's frames every `--node-every`
   become nodes linked by the estimate's own relative poses; node pairs at least five nodes apart whose views
   overlap are aligned by ICP (OpenCV's `cv2.Odometry`, depth type, half resolution, started at the estimate's
   relative pose) and kept as edges where the alignment raised the depth agreement; each frame takes its
   nearest node's correction. ATE and its Sim(3) scale before and after, for several edge weights, with and
   without the edges' translation. An offline test of the lead that the long-range table suggests.

`--write-registered OUT --colour-focal F [--lever-x M]` also writes a copy of the sequence whose depth is
registered to the colour camera (depth pixels back-projected with the camera's intrinsics, moved by the lever
arm, projected with focal F, nearest surface kept), a `camera.json` with focal F and `depth_registered`, and the
ground truth moved to the colour camera (for sequences whose depth images come from their own camera, such
as 7-Scenes; an experiment, not a product feature).

Benchmarks print figures; they assert nothing.
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
from evo.core import metrics, sync

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worker.slam.camera import parse_camera  # noqa: E402
from worker.slam.dynamic.epipolar import fundamental_of_pose  # noqa: E402
from worker.slam.evaluation.metrics import evaluate, to_evo  # noqa: E402
from worker.slam.features.depth import backproject  # noqa: E402
from worker.slam.geometry.se3 import inv, orthonormalize, pose_distance  # noqa: E402
from worker.slam.inpainting.warp import render_depth  # noqa: E402
from worker.slam.io.sequence import Sequence  # noqa: E402
from worker.slam.io.trajectory import Trajectory, read_tum_trajectory, write_tum_trajectory  # noqa: E402
from worker.slam.mapping.pose_graph import optimize_pose_graph  # noqa: E402

INLIER_M = 0.05
"""Depth differences within this count as agreement (beyond it: another surface, or occlusion)."""


def sampson_px(T_ji: np.ndarray, p_i: np.ndarray, p_j: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(N,) Sampson distances (pixels) of matches `p_i` -> `p_j` (N, 2) under the relative pose T_ji (frame i
    camera -> frame j camera) and intrinsics K."""
    F = fundamental_of_pose(T_ji[:3, :3], T_ji[:3, 3], K)
    x_i, x_j = np.c_[p_i, np.ones(len(p_i))], np.c_[p_j, np.ones(len(p_j))]
    Fx, Ftx = x_i @ F.T, x_j @ F
    den = Fx[:, 0] ** 2 + Fx[:, 1] ** 2 + Ftx[:, 0] ** 2 + Ftx[:, 1] ** 2
    return np.abs(np.sum(x_j * Fx, 1)) / np.sqrt(den)


def depth_agreement(z_i: np.ndarray, z_j: np.ndarray, T_ij: np.ndarray, K: np.ndarray,
                    step: int = 4) -> tuple[float, float]:
    """Frame j's depth points (every `step`-th pixel of `z_j` (H, W) m) moved into frame i by T_ij (j camera ->
    i camera) and projected with K: (share of those landing on depth in `z_i` that agree within `INLIER_M`,
    median absolute difference of the agreeing ones, m); (0, nan) when under 200 land."""
    h, w = z_j.shape
    ys, xs = np.mgrid[0:h:step, 0:w:step]
    z = z_j[ys, xs]
    ok = z > 0
    X = backproject(np.stack([xs[ok], ys[ok]], 1), z[ok], K) @ T_ij[:3, :3].T + T_ij[:3, 3]
    front = X[:, 2] > 0.1
    X = X[front]
    u = np.round(X[:, 0] / X[:, 2] * K[0, 0] + K[0, 2]).astype(int)
    v = np.round(X[:, 1] / X[:, 2] * K[1, 1] + K[1, 2]).astype(int)
    inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    seen = z_i[v[inside], u[inside]]
    has = seen > 0
    diff = np.abs(seen[has] - X[inside][has, 2])
    agree = diff < INLIER_M
    if agree.sum() < 200:
        return 0.0, float("nan")
    return float(agree.mean()), float(np.median(diff[agree]))


def _pairs(n: int, poses: dict[int, np.ndarray], gaps: range, stride: int, max_deg: float = 25.0,
           max_m: float = 0.8) -> list[tuple[int, int]]:
    """Frame pairs (i, j), j - i in `gaps`, i every `stride` frames, whose ground-truth views overlap."""
    out = []
    for i in range(0, n, stride):
        for j in gaps:
            j += i
            if i in poses and j in poses:
                metres, radians = pose_distance(poses[i], poses[j])
                if metres <= max_m and np.degrees(radians) <= max_deg:
                    out.append((i, j))
    return out


def register_depth(depth_mm: np.ndarray, K_depth: np.ndarray, K_colour: np.ndarray,
                   lever_x_m: float) -> np.ndarray:
    """`depth_mm` (H, W) uint16 of the depth camera, as seen by a colour camera `lever_x_m` along the depth
    camera's x axis with intrinsics `K_colour`: each depth pixel splatted to its nearest colour pixel, the nearest
    surface kept. (H, W) uint16, 0 where no depth lands."""
    h, w = depth_mm.shape
    ys, xs = np.mgrid[0:h, 0:w]
    ok = (depth_mm > 0) & (depth_mm < 65535)
    z = depth_mm[ok].astype(np.float64) / 1000.0
    x, y, _ = backproject(np.stack([xs[ok], ys[ok]], 1), z, K_depth).T
    x = x - lever_x_m
    u = np.round(K_colour[0, 0] * x / z + K_colour[0, 2]).astype(int)
    v = np.round(K_colour[1, 1] * y / z + K_colour[1, 2]).astype(int)
    inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    u, v, d = u[inside], v[inside], depth_mm[ok][inside]
    far_first = np.argsort(-d.astype(np.int64))  # nearer points overwrite farther ones
    out = np.zeros_like(depth_mm)
    out[v[far_first], u[far_first]] = d[far_first]
    return out


def write_registered(seq: Sequence, out: Path, colour_focal: float, lever_x_m: float) -> None:
    """A copy of 7-Scenes-like `seq` (`data/frame-*.depth.png`, millimetres) in `out` with registered depth."""
    src = seq.root
    (out / "data").mkdir(parents=True, exist_ok=False)
    for name in ("rgb.txt", "depth.txt", "associations.txt"):
        if (src / name).exists():
            shutil.copy(src / name, out / name)
    cam = seq.camera
    K_colour = np.array([[colour_focal, 0, cam.cx], [0, colour_focal, cam.cy], [0, 0, 1.0]])
    for path in sorted((src / "data").iterdir()):
        if path.name.endswith(".depth.png"):
            depth = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if depth is None:
                raise SystemExit(f"cannot read {path}")
            cv2.imwrite(str(out / "data" / path.name), register_depth(depth, cam.K, K_colour, lever_x_m))
        else:
            (out / "data" / path.name).symlink_to(path.resolve())
    lever = np.eye(4)
    lever[0, 3] = lever_x_m
    gt = read_tum_trajectory(src / "groundtruth.txt")
    write_tum_trajectory(out / "groundtruth.txt", Trajectory(gt.timestamps, gt.poses @ lever),
                         f"ground truth of the colour camera ({lever_x_m:g} m along the depth camera's x)")
    camera = cam.to_dict() | {"fx": colour_focal, "fy": colour_focal, "depth_registered": True,
                              "name": f"{cam.name}-registered-{colour_focal:g}"}
    (out / "camera.json").write_text(json.dumps(camera, indent=1))
    print(f"\nwrote {out}: depth registered to a colour camera of focal {colour_focal:g}, lever {lever_x_m:g} m")


def icp_edges(nodes: list[int], est: dict[int, np.ndarray], depth_of: Callable[[int], np.ndarray],
              K: np.ndarray, min_gap: int = 5) -> list[tuple[int, int, np.ndarray, float, float]]:
    """(node a, node b, relative pose T_ab (b camera -> a camera), agreement before, after) for node pairs at
    least `min_gap` nodes apart whose estimated views overlap (<= 0.6 m, <= 20°), aligned by ICP at half
    resolution from the estimate's relative pose; only alignments that raised the depth agreement to >= 0.7 and
    moved the pose by <= 0.15 m and 5°."""
    Kh = K.astype(np.float64).copy()
    Kh[:2] /= 2  # pixel (u, v) of the every-second-pixel copy is (2u, 2v) of the full image
    settings = cv2.OdometrySettings()
    settings.setCameraMatrix(Kh.astype(np.float32))
    settings.setMaxDepth(4.0)
    odometry = cv2.Odometry(cv2.OdometryType_DEPTH, settings, cv2.OdometryAlgoType_COMMON)
    small = {i: np.ascontiguousarray(depth_of(i)[::2, ::2], np.float32) for i in nodes}
    out = []
    for ia, a in enumerate(nodes):
        for ib in range(ia + min_gap, len(nodes)):
            b = nodes[ib]
            metres, radians = pose_distance(est[a], est[b])
            if metres > 0.6 or np.degrees(radians) > 20:
                continue
            T_ab = inv(est[a]) @ est[b]
            ok, Rt = odometry.compute(render_depth(small[b], small[b] > 0, T_ab, Kh)[1], small[a])
            if not ok:
                continue
            T_new = Rt @ T_ab
            before = depth_agreement(small[a], small[b], T_ab, Kh, step=1)[0]
            after = depth_agreement(small[a], small[b], T_new, Kh, step=1)[0]
            moved_m, moved_rad = pose_distance(T_ab, T_new)
            if after >= max(0.7, before) and moved_m <= 0.15 and np.degrees(moved_rad) <= 5:
                out.append((ia, ib, T_new, before, after))
    return out


def _sim3(gt: Trajectory, traj: Trajectory) -> tuple[float, float]:
    """(ATE rmse m after a Sim(3) alignment, its scale)."""
    ref, est = sync.associate_trajectories(to_evo(gt), to_evo(traj), max_diff=0.02)
    scale = est.align(ref, correct_scale=True)[2]
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    return float(ape.get_statistic(metrics.StatisticsType.rmse)), float(scale)


def depth_pose_graph(seq: Sequence, est_traj: Trajectory, est: dict[int, np.ndarray], gt: dict[int, np.ndarray],
                     depth_of: Callable[[int], np.ndarray], node_every: int) -> None:
    """Print the depth-edge pose-graph test (table 4 of the module's docstring)."""
    nodes = [k for k in sorted(est) if k % node_every == 0]
    edges = icp_edges(nodes, est, depth_of, seq.camera.K)
    err = np.array([pose_distance(inv(gt[nodes[a]]) @ gt[nodes[b]], inv(est[nodes[a]]) @ est[nodes[b]])
                    + pose_distance(inv(gt[nodes[a]]) @ gt[nodes[b]], T) for a, b, T, _, _ in edges
                    if nodes[a] in gt and nodes[b] in gt])
    print(f"\nDepth edges ({len(nodes)} nodes every {node_every} frames, {len(edges)} ICP edges kept)\n")
    print("| relative poses of the kept pairs | depth agreement | translation error, median (mm) | "
          "rotation error, median (°) |")
    print("|---|---|---|---|")
    print(f"| estimate | {np.mean([e[3] for e in edges]):.3f} | {1000 * np.median(err[:, 0]):.1f} | "
          f"{np.degrees(np.median(err[:, 1])):.2f} |")
    print(f"| ICP | {np.mean([e[4] for e in edges]):.3f} | {1000 * np.median(err[:, 2]):.1f} | "
          f"{np.degrees(np.median(err[:, 3])):.2f} |")
    node_poses = np.stack([est[k] for k in nodes])
    chain = [(i, i + 1, inv(node_poses[i]) @ node_poses[i + 1], 1.0) for i in range(len(nodes) - 1)]
    node_arr = np.array(nodes)
    nearest = {t: int(np.argmin(np.abs(node_arr - np.argmin(np.abs(seq.timestamps - t))))) for t in est_traj.timestamps}
    gt_traj = seq.groundtruth
    assert gt_traj is not None
    print("\n| trajectory | ICP edge weight (chain: 1) | ATE rmse (m) | Sim(3) ATE (m) | Sim(3) scale |")
    print("|---|---|---|---|---|")
    variants = [("estimate", 0.0, False)] + [(f"pose graph, {part}", w, part == "rotation only")
                                             for part in ("full edges", "rotation only") for w in (0.3, 1.0, 3.0)]
    for label, weight, rot_only in variants:
        poses = est_traj.poses
        if weight:
            graph = chain + [(a, b, T, weight) for a, b, T, _, _ in edges]
            tw = np.r_[np.ones(len(chain)), np.full(len(edges), 0.0 if rot_only else 1.0)]
            corr = orthonormalize(optimize_pose_graph(node_poses, graph, trans_weights=tw)) @ inv(node_poses)
            poses = np.stack([corr[nearest[t]] @ T for t, T in zip(est_traj.timestamps, poses)])
        traj = Trajectory(est_traj.timestamps, orthonormalize(poses))
        sim_ate, scale = _sim3(gt_traj, traj)
        print(f"| {label} | {weight:g} | {evaluate(gt_traj, traj).ate.rmse:.4f} | {sim_ate:.4f} | {scale:.3f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sequence", required=True, help="DIR:CAMERA")
    ap.add_argument("--estimate", type=Path, help="a run's trajectory.txt (TUM format, its tracked frames)")
    ap.add_argument("--colour-focals", default="480,500,515,525,535,550,565,585,600")
    ap.add_argument("--depth-focals", default="525,555,585,615")
    ap.add_argument("--pose-graph", action="store_true", help="with --estimate: the depth-edge pose graph test")
    ap.add_argument("--node-every", type=int, default=10, help="pose-graph nodes every n frames")
    ap.add_argument("--write-registered", type=Path, help="write the registered copy of the sequence here")
    ap.add_argument("--colour-focal", type=float, default=525.0)
    ap.add_argument("--lever-x", type=float, default=0.025, help="colour camera's offset along depth x (m)")
    args = ap.parse_args()
    root, camera_name = args.sequence.rsplit(":", 1)
    seq = Sequence(Path(root), parse_camera(camera_name))
    idx, gt = seq.groundtruth_for_frames()
    poses = dict(zip(idx.tolist(), gt))
    n, cam = len(seq), seq.camera
    if args.write_registered is not None:
        write_registered(seq, args.write_registered, args.colour_focal, args.lever_x)
    frames: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def frame(i: int) -> tuple[np.ndarray, np.ndarray]:
        if i not in frames:
            f = seq[i]
            frames[i] = (cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY), f.depth)
        return frames[i]

    def K_with(focal: float) -> np.ndarray:
        return np.array([[focal, 0, cam.cx], [0, focal, cam.cy], [0, 0, 1.0]])

    orb = cv2.ORB_create(2000)  # type: ignore[attr-defined]  # (absent from OpenCV 5's stubs)
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True)
    matches = []
    for i, j in _pairs(n, poses, range(20, 41, 20), 25):
        T_ji = np.linalg.inv(poses[j]) @ poses[i]
        if np.degrees(pose_distance(poses[i], poses[j])[1]) < 3:  # the focal length shows in rotation
            continue
        (k_i, d_i), (k_j, d_j) = (orb.detectAndCompute(frame(k)[0], None) for k in (i, j))
        m = matcher.match(d_i, d_j) if d_i is not None and d_j is not None else []
        if len(m) >= 100:
            matches.append((T_ji, np.array([k_i[x.queryIdx].pt for x in m], np.float64),
                            np.array([k_j[x.trainIdx].pt for x in m], np.float64)))
    print(f"\n{seq.root.name}: colour focal length against the ground truth's relative poses "
          f"({len(matches)} frame pairs 20 and 40 apart, ORB matches)\n")
    print("| focal (px) | median Sampson distance (px), median over pairs | mean over pairs |")
    print("|---|---|---|")
    for focal in (float(x) for x in args.colour_focals.split(",")):
        per_pair = [np.median(sampson_px(T, a, b, K_with(focal))) for T, a, b in matches]
        print(f"| {focal:g} | {np.median(per_pair):.3f} | {np.mean(per_pair):.3f} |")

    depth_pairs = _pairs(n, poses, range(10, 301, 30), 25)
    print(f"\nDepth focal length against the ground truth ({len(depth_pairs)} frame pairs 10-300 apart)\n")
    print(f"| focal (px) | depth within {INLIER_M * 100:.0f} cm | median difference of those (mm) |")
    print("|---|---|---|")
    for focal in (float(x) for x in args.depth_focals.split(",")):
        rows = [depth_agreement(frame(i)[1], frame(j)[1], np.linalg.inv(poses[i]) @ poses[j], K_with(focal))
                for i, j in depth_pairs]
        share = np.array([r[0] for r in rows])
        med = np.array([r[1] for r in rows])
        print(f"| {focal:g} | {share.mean():.3f} | {1000 * np.nanmedian(med):.2f} |")

    if args.estimate is None:
        return
    est_traj = read_tum_trajectory(args.estimate)
    stamps = seq.timestamps
    est = {}
    for t, T in zip(est_traj.timestamps, est_traj.poses):
        k = int(np.argmin(np.abs(stamps - t)))
        if abs(stamps[k] - t) < 0.02:
            est[k] = T
    print(f"\nTrajectories against depth ({args.estimate}; camera's own focal {cam.fx:g})\n")
    print(f"| frames apart | pairs | depth within {INLIER_M * 100:.0f} cm: ground truth | estimate | "
          "estimate agrees better in |")
    print("|---|---|---|---|---|")
    for label, gaps, stride in (("5-15", range(5, 16, 5), 10), ("150+", range(150, n, 10), 10)):
        pairs = [(i, j) for i, j in _pairs(n, poses, gaps, stride) if i in est and j in est]
        g = np.array([depth_agreement(frame(i)[1], frame(j)[1], np.linalg.inv(poses[i]) @ poses[j], cam.K)[0]
                      for i, j in pairs])
        e = np.array([depth_agreement(frame(i)[1], frame(j)[1], np.linalg.inv(est[i]) @ est[j], cam.K)[0]
                      for i, j in pairs])
        print(f"| {label} | {len(pairs)} | {g.mean():.3f} | {e.mean():.3f} | {np.mean(e > g):.0%} |")
    if args.pose_graph:
        depth_pose_graph(seq, est_traj, est, poses, lambda i: frame(i)[1], args.node_every)


if __name__ == "__main__":
    main()
