"""Background restoration benchmark: geometry-first restoration with each fill for unseen pixels (harmonic, Telea,
PatchMatch) against OpenCV's Telea on the whole hole.

For frames of a dynamic sequence with truth (`vtdslam synth` / `vtdslam augment` output), the true dynamic mask
is the hole; references are chosen causally (past 15 frames) or both-sided (+-15 frames), plus the second-chance
references from up to 30 frames away (`--far-refs`, default as the pipeline's), with ground-truth poses and true
masks, so the figures isolate the restoration from tracking and segmentation errors. Prints RGB PSNR
(whole hole, and split into pixels a reference sees / does not see) and depth error and coverage inside the
holes, hole size and time/frame.

    .venv/bin/python bench/bench_inpainting.py SEQ_DIR [SEQ_DIR ...] [--frames 30] [--camera tum3] [--speed]
        [--references causal,both-sided] [--far-refs 2[,0]] [--align-px 0[,6]] [--refine 0[,1,0.25]]
        [--unseen-fill harmonic,telea,patchmatch] [--unseen-depth border|none]
        [--static REAL_SEQ:CAMERA [--static-every 100] [--static-max-frames N]]

`--static` uses real static frames as their own truth: artificial person-sized holes, no references, so the
unseen-pixel fill does all the work (e.g. `--static ../shared/data/7scenes_redkitchen:7scenes`).
"""
from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout's code, not the installed one's (a worktree measuring "before")

from sequence_spec import camera_of, split_spec  # noqa: E402  (bench/, the script's own folder)

from worker.slam.inpainting.references import Candidate, ReferenceSelectionConfig, select_references  # noqa: E402
from worker.slam.inpainting.refine import PoseRefinementConfig  # noqa: E402
from worker.slam.inpainting.restore import ReferenceView, RestorationConfig, restore_frame  # noqa: E402
from worker.slam.io.sequence import Sequence  # noqa: E402
from worker.slam.truth import load_truth, restoration_psnr  # noqa: E402


def bench_sequence(root: Path, camera: str | None, n_frames: int, both_sided: bool, config: RestorationConfig,
                   sel_cfg: ReferenceSelectionConfig = ReferenceSelectionConfig()) -> dict:
    seq = Sequence(root, camera_of(camera))
    truth = load_truth(root)
    if truth is None:
        raise SystemExit(f"{root} has no truth/ folder")
    gt_idx, gt_poses = seq.groundtruth_for_frames()
    pose = dict(zip(gt_idx.tolist(), gt_poses))
    orb = cv2.ORB_create(1000)  # type: ignore[attr-defined]  # (absent from OpenCV 5's stubs)
    cache: dict[int, tuple] = {}

    def frame(i):
        if i not in cache:
            f = seq[i]
            desc = orb.detectAndCompute(cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY), None)[1]
            cache[i] = (f, truth.mask(i), desc)
        return cache[i]

    candidates = [i for i in range(15, len(seq) - 15) if i in pose and truth.mask(i).mean() > 0.02]
    picks = candidates[:: max(1, len(candidates) // n_frames)][:n_frames]
    rows: dict[str, list[float]] = {"pm_psnr": [], "telea_psnr": [], "pm_depth_med": [], "depth_valid": [],
                                    "hole": [], "ms": [],
            "refs": [], "refined": [], "seen": [], "seen_psnr": [], "unseen_psnr": []}
    depth_errors: list[np.ndarray] = []
    window = range(-sel_cfg.reach, sel_cfg.reach + 1 if both_sided else 0)
    for i in picks:
        f, hole, desc = frame(i)
        cands = [Candidate(i + k, pose[i + k], frame(i + k)[2]) for k in window if k and i + k in pose]
        sel = select_references(Candidate(i, pose[i], desc), cands, sel_cfg, both_sided)
        refs = [ReferenceView(frame(j)[0].rgb, frame(j)[0].depth, pose[j], frame(j)[1]) for j in sel.indices]
        t0 = time.perf_counter()
        out = restore_frame(f.rgb, f.depth, hole, pose[i], refs, seq.camera.K, config)
        rows["ms"].append((time.perf_counter() - t0) * 1000)
        bg_rgb, bg_depth = truth.background_rgb(i), truth.background_depth(i)
        telea = cv2.inpaint(f.rgb, hole.astype(np.uint8), 3, cv2.INPAINT_TELEA)
        rows["pm_psnr"].append(restoration_psnr(out.rgb, bg_rgb, hole))
        rows["telea_psnr"].append(restoration_psnr(telea, bg_rgb, hole))
        has = hole & (bg_depth > 0)
        ok = has & (out.depth > 0)
        rows["depth_valid"].append(ok.sum() / max(has.sum(), 1))
        # pooled over all frames' restored pixels: a frame with a handful of bad pixels must not outweigh
        # one with tens of thousands of good ones (as a mean of per-frame medians would)
        depth_errors.append(np.abs(out.depth[ok] - bg_depth[ok]))
        rows["hole"].append(hole.mean())
        rows["refs"].append(len(refs))
        rows["refined"].append(out.poses_refined)
        seen = out.seen_by_reference
        rows["seen"].append(seen.sum() / max(hole.sum(), 1))
        rows["seen_psnr"].append(restoration_psnr(out.rgb, bg_rgb, seen) if seen.any() else np.nan)
        rows["unseen_psnr"].append(restoration_psnr(out.rgb, bg_rgb, hole & ~seen) if (hole & ~seen).any()
                                   else np.nan)
    err = np.concatenate(depth_errors) if depth_errors else np.zeros(0)
    depth = {"pm_depth_med": float(np.median(err)) if len(err) else np.nan,
             "depth_p90": float(np.percentile(err, 90)) if len(err) else np.nan,
             "depth_bad": float(np.mean(err > 0.10)) if len(err) else np.nan}
    means = {k: float(np.nanmean(v)) if np.isfinite(np.asarray(v, float)).any() else np.nan for k, v in rows.items()}
    return means | depth | {"frames": len(picks)}


def bench_speed(root: Path, camera: str | None, config: RestorationConfig, index: int = 60) -> None:
    """Time per frame against hole size: a person-like ellipse at the image centre of one frame, restored with
    three past references (geometry covers what they see) and with none (PatchMatch from the frame itself, the
    worst case). CPU time of the process (numba runs on one thread), so the figures hold on a loaded machine
    too; PSNR against the true background inside the hole."""
    seq, truth = Sequence(root, camera_of(camera)), load_truth(root)
    if truth is None:
        raise SystemExit(f"{root} has no truth/ folder")
    gt_idx, gt_poses = seq.groundtruth_for_frames()
    pose = dict(zip(gt_idx.tolist(), gt_poses))
    f = seq[index]
    h, w = f.depth.shape
    refs = [ReferenceView(seq[j].rgb, seq[j].depth, pose[j], truth.mask(j))
            for j in (index - 15, index - 10, index - 5)]
    print(f"\n| {root.name} frame {index}, unseen: {config.unseen_fill}, depth: {config.unseen_depth} | hole % | "
          "refs | seen by refs % | CPU ms/frame | PSNR (dB) | depth restored % | depth median err (cm) |")
    print("|---|---|---|---|---|---|---|---|")
    for frac in (0.05, 0.10, 0.15, 0.25):
        a = np.sqrt(frac * h * w / np.pi / 2.5)
        hole = cv2.ellipse(np.zeros((h, w), np.uint8), (w // 2, h // 2), (int(a), int(2.5 * a)),
                           0, 0, 360, 1, -1) > 0
        for rr in (refs, []):
            ts = []
            for _ in range(3):
                t0 = time.process_time()
                out = restore_frame(f.rgb, f.depth, hole, pose[index], rr, seq.camera.K, config)
                ts.append(time.process_time() - t0)
            bg = truth.background_depth(index)
            has = hole & (bg > 0)
            ok = has & (out.depth > 0)
            err = float(np.median(np.abs(out.depth[ok] - bg[ok]))) if ok.any() else np.nan
            print(f"| | {100 * hole.mean():.1f} | {len(rr)} | "
                  f"{100 * out.seen_by_reference.sum() / hole.sum():.0f} | {1000 * np.median(ts):.0f} | "
                  f"{restoration_psnr(out.rgb, truth.background_rgb(index), hole):.2f} | "
                  f"{100 * ok.sum() / max(has.sum(), 1):.0f} | {100 * err:.2f} |", flush=True)


def bench_static(spec: str, fills: list[str], every: int, max_frames: int | None) -> None:
    """Real static frames are their own truth: person-like ellipses (5, 15, 25 % of the image, left, centre,
    right) restored with no reference, so every hole pixel is filled by the unseen-pixel fill; `spec` is
    SEQ_DIR[:CAMERA]. Mean whole-hole PSNR and median CPU ms per fill."""
    root, camera = split_spec(spec)
    seq = Sequence(Path(root), camera_of(camera))
    n = min(len(seq), max_frames) if max_frames else len(seq)
    frames = range(every // 2, n, every)
    res: dict[tuple[float, str], list[tuple[float, float]]] = {}
    for i in frames:
        f = seq[i]
        h, w = f.depth.shape
        for frac in (0.05, 0.15, 0.25):
            a = np.sqrt(frac * h * w / np.pi / 2.5)
            for cx in (w // 4, w // 2, 3 * w // 4):
                hole = cv2.ellipse(np.zeros((h, w), np.uint8), (cx, h // 2), (int(a), int(2.5 * a)),
                                   0, 0, 360, 1, -1) > 0
                for fill in fills:
                    t0 = time.process_time()
                    out = restore_frame(f.rgb, f.depth, hole, np.eye(4), [], seq.camera.K,
                                        RestorationConfig(unseen_fill=fill))
                    res.setdefault((frac, fill), []).append((restoration_psnr(out.rgb, f.rgb, hole),
                                                             1000 * (time.process_time() - t0)))
    print(f"\n| {Path(root).name}, frames {frames.start}-{frames.stop - 1} every {every}, no references | hole % | "
          + " | ".join(f"{fill} PSNR (dB) | {fill} CPU ms" for fill in fills) + " |")
    print("|---|---|" + "---|---|" * len(fills))
    for frac in (0.05, 0.15, 0.25):
        cells = [f"{np.mean([r[0] for r in res[(frac, f)]]):.2f} | {np.median([r[1] for r in res[(frac, f)]]):.0f}"
                 for f in fills]
        print(f"| | {100 * frac:.0f} | " + " | ".join(cells) + " |", flush=True)


def _refinement(value: str) -> PoseRefinementConfig:
    """`--refine` value: "0" off, "1" the default, another number the scale the alignment runs at."""
    if value in ("0", "1"):
        return PoseRefinementConfig(enabled=value == "1")
    return PoseRefinementConfig(enabled=True, scale=float(value))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequences", nargs="*", type=Path)
    ap.add_argument("--static", action="append", default=[], metavar="SEQ_DIR[:CAMERA]",
                    help="also fill artificial holes in a real static sequence's frames with no references "
                         "(the frame is the truth); repeatable")
    ap.add_argument("--static-every", type=int, default=100, help="every n-th frame of a --static sequence")
    ap.add_argument("--static-max-frames", type=int, default=None,
                    help="only the first n frames of a --static sequence (e.g. the people-free start)")
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--camera", default="tum3", help="preset when the sequence has no camera.json")
    ap.add_argument("--speed", action="store_true", help="also time restoration against hole size")
    ap.add_argument("--unseen-fill", default="harmonic,telea,patchmatch",
                    help="fills to compare for pixels no reference sees (comma-separated)")
    ap.add_argument("--references", default="causal,both-sided",
                    help="reference windows to compare (comma-separated): causal = the past 15 frames, "
                         "both-sided = +-15 frames")
    ap.add_argument("--far-refs", default=str(ReferenceSelectionConfig().far_refs),
                    help="second-chance references (restoration.selection.far_refs) to compare, comma-separated")
    ap.add_argument("--align-px", default=str(RestorationConfig().align_px),
                    help="restoration.restoration.align_px values to compare, comma-separated (0: off)")
    ap.add_argument("--blend-refs", default=str(RestorationConfig().blend_refs),
                    help="restoration.restoration.blend_refs values to compare, comma-separated (1: first only)")
    ap.add_argument("--refine", default="1" if RestorationConfig().refine.enabled else "0",
                    help="reference pose refinement to compare, comma-separated: 0 (the references' poses as "
                         "given), 1 (photometrically refined first, restoration.restoration.refine), or the scale "
                         "the refinement runs at (e.g. 0.25)")
    ap.add_argument("--unseen-depth", default="border", help="depth of pixels no reference sees: border|none")
    args = ap.parse_args()
    if not args.sequences and not args.static:
        ap.error("give sequences with truth, --static SEQ_DIR[:CAMERA], or both")
    fills = args.unseen_fill.split(",")
    for spec in args.static:
        bench_static(spec, fills, args.static_every, args.static_max_frames)
    if not args.sequences:
        return
    print("| sequence | mode | frames | hole % | refs | hole seen by refs % | PSNR all (dB) | PSNR seen | "
          "PSNR unseen | Telea PSNR | depth median err (cm) | depth p90 err (cm) | depth err > 10 cm % | "
          "depth restored % | ms/frame |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    windows = args.references.split(",")
    for root, window, fill, far, align, blend, refine in itertools.product(
            args.sequences, windows, fills, args.far_refs.split(","), args.align_px.split(","),
            args.blend_refs.split(","), args.refine.split(",")):
        config = RestorationConfig(unseen_fill=fill, unseen_depth=args.unseen_depth, align_px=int(align),
                                   blend_refs=int(blend), refine=_refinement(refine))
        sel_cfg = ReferenceSelectionConfig(far_refs=int(far))
        r = bench_sequence(root, args.camera, args.frames, window == "both-sided", config, sel_cfg)
        print(f"| {root.name} | {window}, far refs: {far}, align: {align}, blend: {blend}, refine: {refine}, "
              f"unseen: {fill}, "
              f"depth: {args.unseen_depth} | {r['frames']} | {100 * r['hole']:.1f} | "
              f"{r['refs']:.1f} ({r['refined']:.1f} refined) | {100 * r['seen']:.0f} | {r['pm_psnr']:.2f} | "
              f"{r['seen_psnr']:.2f} | "
              f"{r['unseen_psnr']:.2f} | {r['telea_psnr']:.2f} | {100 * r['pm_depth_med']:.2f} | "
              f"{100 * r['depth_p90']:.2f} | {100 * r['depth_bad']:.1f} | {100 * r['depth_valid']:.0f} | "
              f"{r['ms']:.0f} |", flush=True)
    if args.speed:
        for root in args.sequences:
            for fill, refine in itertools.product(fills, args.refine.split(",")):
                bench_speed(root, args.camera, RestorationConfig(unseen_fill=fill, unseen_depth=args.unseen_depth,
                                                                 refine=_refinement(refine)))


if __name__ == "__main__":
    main()
