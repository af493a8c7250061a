"""The paper's ablation on dynamic sequences: presets side by side, with the truth-based scores of each stage.

    .venv/bin/python bench/bench_dynamic.py --sequence DIR[:CAMERA] [--sequence ...] [--presets a,b] \
        [--max-frames N] [--config JSON] [--summary] [--teacher TFLITE] [--starts 0,2,4,6]
    .venv/bin/python bench/bench_dynamic.py --table tum-walking|bonn-crowd --data DIR [...]

`--table` runs a named table on the sequences `vtdslam fetch` put in DIR (`vtdslam fetch tum-walking --to DIR`):
`tum-walking` the paper's four TUM fr3 walking sequences (xyz, static, rpy, halfsphere), `bonn-crowd` Bonn's
crowd, crowd2 and crowd3, each with its own camera; a sequence not fetched is skipped with a message.

`--teacher` adds, for each preset that segments, the same run with that TFLite model as its segmenter (e.g.
the DeepLabV3 teacher), so MSNET and the teacher are compared in one table (`marked area`: the mean share of
each frame's pixels the segmenter marks potentially dynamic).

For each sequence × preset: ATE/RPE, frames tracked, static features used per frame, features removed,
dynamic-feature precision/recall, the dynamic keypoints kept although segmentation marked them (culling's misses)
and never marked (segmentation's), mask IoU (when the sequence has `truth/`), restoration PSNR and depth
error, ms per frame of culling and restoration, and end-to-end fps. Benchmarks print figures; they assert nothing.

`--summary` adds each preset's mean, min and max over the sequences: give it several sequences of one kind
(`vtdslam augment --seed 1`, `--seed 2`, ...). One 300-frame run's ATE swings by tens of percent with small
changes (which features happen to survive), so presets and settings are compared on such means. `--starts
0,2,4,6` runs each sequence from each of those first frames (the rows say `@k`): the same footage started a
frame or two later, a run-to-run spread for a single real sequence.

`--references` adds two rows per sequence with truth, both run on the truth's background frames (the same
frames without people): `people-free` (`orb-only`), the denominator of "within 1.2x of the ATE without
people", and `masks removed` (`no-restoration` with every truth segment cut out, no motion test), what a
perfect culler would get: the static scene behind the people is lost to tracking either way, and only
restoration can bring it back. The summary then gives each preset's mean as a multiple of both.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sequence_spec import camera_of, split_spec  # noqa: E402  (bench/, the script's own folder)

from cli.fetch.catalog import TABLES, table_sequences  # noqa: E402
from worker.slam.io.sequence import Sequence  # noqa: E402
from worker.slam.pipeline import run_pipeline  # noqa: E402
from worker.slam.presets import get_preset  # noqa: E402
from worker.slam.truth import load_truth, write_background_sequence  # noqa: E402

#: Reference rows (`--references`): label -> (preset, overrides), run on the truth's background frames.
REFERENCES = {
    "people-free": ("orb-only", {}),
    # every truth segment judged moving (a threshold no score is below) and cut out
    "masks removed": ("no-restoration", {"segmentation": {"source": "truth"},
                                         "culling": {"culling": {"threshold": {"fixed": -1.0}}}}),
}


def _fmt(v, nd=3, scale=1.0):
    return "–" if v is None else f"{v * scale:.{nd}f}"


def row(seq_dir: str, camera: str | None, preset: str, max_frames: int | None, overrides: dict | None,
        label: str | None = None, name: str | None = None, extra: dict | None = None, start: int = 0) -> dict:
    """One bench row; `label` names the row instead of the preset, `name` the sequence instead of its folder,
    `extra` overrides applied after `overrides` (a reference's own settings), `start` the first frame."""
    seq = Sequence(seq_dir, camera_of(camera))
    config = get_preset(preset, overrides)
    if extra:
        config = config.with_overrides(extra)
    with tempfile.TemporaryDirectory() as out:
        m = run_pipeline(seq, config, out, start=start, max_frames=max_frames).metrics
    cull, rest = m.get("culling", {}), m.get("restoration", {})
    ct, rt = cull.get("truth", {}), rest.get("truth", {})
    info = m.get("stage_info", {})
    return {
        "sequence": (name or Path(seq_dir).name) + (f" @{start}" if start else ""), "preset": label or preset,
        "frames": m["frames"],
        "tracked": m["tracked"], "marked": info.get("potentially_dynamic_fraction"),
        "ate": m.get("ate", {}).get("rmse"), "rpe_t": m.get("rpe", {}).get("trans", {}).get("rmse"),
        "rpe_r": m.get("rpe", {}).get("rot_deg", {}).get("rmse"),
        "ate_corr": m.get("ate_corrected", {}).get("rmse"),
        "rpe_ft": m.get("rpe_frame", {}).get("trans", {}).get("rmse"),
        "rpe_fr": m.get("rpe_frame", {}).get("rot_deg", {}).get("rmse"),
        "kept": info.get("features_kept"), "removed": info.get("features_removed"),
        "restored_feats": info.get("restored_features"),
        "precision": ct.get("feature_precision"), "recall": ct.get("feature_recall"), "iou": ct.get("mask_iou"),
        "missed_cull": ct.get("feature_missed_by_culling"), "missed_seg": ct.get("feature_missed_by_segmentation"),
        "psnr": rt.get("restoration_psnr"), "depth_err": rt.get("restoration_depth_median_m"),
        "seg_ms": m["timings_ms"].get("segmentation"), "cull_ms": m["timings_ms"].get("culling"),
        "rest_ms": m["timings_ms"].get("restoration"), "fps": m.get("fps"),
        "decision_ms": cull.get("decision_ms_median"),
        "guided": _guided_cell(cull),
    }


def _guided_cell(cull: dict) -> str:
    """Guided frames / frames compared, with the frames not judged and without objects when there are any."""
    if "frames_compared" not in cull:
        return "–"
    notes = [f" ({cull[key]} {what})" for key, what in (("frames_not_judged", "not judged"),
                                                        ("frames_without_objects", "without objects"),
                                                        ("frames_marks_trusted", "marks trusted"))
             if cull.get(key)]
    return f"{cull['guided_matching_frames']}/{cull['frames_compared']}" + "".join(notes)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sequence", action="append", default=[],
                    help="DIR[:CAMERA]: CAMERA a preset or JSON; left out, the folder's camera.json")
    ap.add_argument("--table", default=None, choices=sorted(TABLES),
                    help="a named table: its sequences as `vtdslam fetch` unpacked them into --data")
    ap.add_argument("--data", default=None, metavar="DIR", help="where `vtdslam fetch` put the --table's sequences")
    ap.add_argument("--presets", default="orb-only,geometry-only,no-restoration,full")
    ap.add_argument("--max-frames", type=int, default=None)
    ap.add_argument("--config", default=None, help="JSON overrides applied to every preset")
    ap.add_argument("--summary", action="store_true", help="also print each preset's mean over the sequences")
    ap.add_argument("--teacher", default=None, metavar="TFLITE",
                    help="also run each preset that segments with this model as its segmenter (`tflite-teacher`)")
    ap.add_argument("--starts", default="0", metavar="K,K,...",
                    help="run each sequence from each of these first frames (a run-to-run spread: one run's ATE "
                         "swings with small changes)")
    ap.add_argument("--references", action="store_true",
                    help="also run `people-free` and `masks removed` on each sequence's truth backgrounds")
    args = ap.parse_args()
    if args.table:
        args.sequence += table_specs(args.table, args.data or ap.error("--table needs --data DIR"))
    if not args.sequence:
        ap.error("give --sequence DIR[:CAMERA] or --table NAME --data DIR")
    overrides = json.loads(args.config) if args.config else None
    try:
        starts = [int(k) for k in args.starts.split(",")]
    except ValueError:
        ap.error(f"--starts takes comma-separated frame indices, not {args.starts!r}")
    if any(k < 0 for k in starts):
        ap.error("--starts must be >= 0")
    print("| sequence | preset | frames | tracked | marked area | ATE rmse (m) | ATE corrected (m) | RPE t (m/s) "
          "| RPE r (°/s) | RPE t (m/frame) | RPE r (°/frame) | static feats/frame | removed/frame "
          "| restored feats/frame | dyn. precision | dyn. recall "
          "| dyn. missed: culling / segmentation | mask IoU "
          "| restore PSNR (dB) | restore depth err (cm) | seg ms | cull ms (with ORB) | cull decision ms "
          "| guided frames | restore ms | fps |")
    print("|" + "---|" * 26)
    rows = []
    for spec in args.sequence:
        seq_dir, camera = split_spec(spec)
        with tempfile.TemporaryDirectory() as tmp:
            runs: list[tuple[str, str, dict | None, str | None]] = [
                (seq_dir, preset, None, None) for preset in args.presets.split(",")]
            if args.teacher:
                runs += [(seq_dir, preset, teacher_overrides(args.teacher), f"{preset} (tflite-teacher)")
                         for preset in args.presets.split(",") if "segmentation" in get_preset(preset).stages]
            truth = load_truth(seq_dir) if args.references else None
            if truth is not None:
                if truth.layout.depth_scale != Sequence(seq_dir, camera_of(camera)).camera.depth_scale:
                    raise SystemExit(f"{seq_dir}: the truth's depth scale is not its camera's "
                                     f"({camera or 'camera.json'})")
                bg = str(write_background_sequence(seq_dir, Path(tmp) / "bg"))
                runs += [(bg, preset, extra, label) for label, (preset, extra) in REFERENCES.items()]
            for start in starts:
                for run_dir, preset, extra, label in runs:
                    rows.append(row(run_dir, camera, preset, args.max_frames, overrides, label,
                                    Path(seq_dir).name, extra, start))
                    print_row(rows[-1])
    if args.summary:
        print_summary(rows)


def table_specs(table: str, data: str) -> list[str]:
    """The `--sequence` specs of a named table's fetched sequences; the missing ones are named on stderr."""
    present, missing = table_sequences(table, Path(data))
    for ds in missing:
        print(f"skipping {ds.name}: no {Path(data) / ds.folder} (`vtdslam fetch {ds.name} --to {data}`)",
              file=sys.stderr)
    if not present:
        raise SystemExit(f"--table {table}: none of its sequences is in {data}")
    return [f"{folder}:{ds.camera}" for ds, folder in present]


def teacher_overrides(model: str) -> dict:
    """The preset's segmenter replaced by a TFLite model (the DeepLabV3 teacher), one thread like MSNET."""
    if not Path(model).is_file():
        raise SystemExit(f"--teacher: no such file {model}")
    return {"segmentation": {"segmenter": {"backend": "tflite-teacher", "model_path": str(Path(model).resolve())}}}


def print_row(r: dict) -> None:
    marked = "–" if r["marked"] is None else f"{100 * r['marked']:.1f} %"
    print(f"| {r['sequence']} | {r['preset']} | {r['frames']} | {r['tracked']} | {marked} | {_fmt(r['ate'], 4)} | "
          f"{_fmt(r['ate_corr'], 4)} | {_fmt(r['rpe_t'], 4)} | {_fmt(r['rpe_r'], 2)} | {_fmt(r['rpe_ft'], 4)} | "
          f"{_fmt(r['rpe_fr'], 3)} | {_fmt(r['kept'], 0)} | {_fmt(r['removed'], 1)} | "
          f"{_fmt(r['restored_feats'], 1)} | {_fmt(r['precision'], 2)} | {_fmt(r['recall'], 2)} | "
          f"{_missed(r)} | {_fmt(r['iou'], 2)} | {_fmt(r['psnr'], 1)} | {_fmt(r['depth_err'], 1, 100)} | "
          f"{_fmt(r['seg_ms'], 1)} | {_fmt(r['cull_ms'], 1)} | {_fmt(r['decision_ms'], 1)} | {r['guided']} | "
          f"{_fmt(r['rest_ms'], 1)} | {_fmt(r['fps'], 1)} |", flush=True)


def _missed(r: dict) -> str:
    """The dynamic keypoints kept although segmentation marked them (culling's misses) / never marked (its own),
    as shares of all dynamic keypoints; "–" without truth or segmentation."""
    if r["missed_cull"] is None:
        return "–"
    return f"{100 * r['missed_cull']:.1f} % / {100 * r['missed_seg']:.1f} %"


def print_summary(rows: list[dict]) -> None:
    """Per preset over the sequences: ATE mean (min–max), RPE means (1 s and 1 frame apart: drift and jitter),
    frames tracked, dynamic precision/recall means, and
    (when `--references` ran) the ATE mean as a multiple of each reference's, both over the sequences that
    have that reference."""
    refs = [label for label in REFERENCES if any(r["preset"] == label for r in rows)]
    print()
    print("| preset | sequences | ATE mean (m) | ATE min–max (m) | RPE 1 s mean (m) | RPE 1 frame mean (m) | tracked "
          "| dyn. precision | dyn. recall |" + "".join(f" × {label} |" for label in refs))
    print("|---|---|---|---|---|---|---|---|---|" + "---|" * len(refs))
    for preset in dict.fromkeys(r["preset"] for r in rows):
        rs = [r for r in rows if r["preset"] == preset]
        ate = [r["ate"] for r in rs if r["ate"] is not None]
        mean = lambda k, rs=rs: _mean([r[k] for r in rs])  # noqa: E731
        spread = f"{min(ate):.4f}–{max(ate):.4f}" if ate else "–"
        print(f"| {preset} | {len(rs)} | {_fmt(_mean(ate), 4)} | {spread} | {_fmt(mean('rpe_t'), 4)} | "
              f"{_fmt(mean('rpe_ft'), 4)} | {sum(r['tracked'] for r in rs)}/{sum(r['frames'] for r in rs)} | "
              f"{_fmt(mean('precision'), 2)} | "
              f"{_fmt(mean('recall'), 2)} |" + "".join(f" {_fmt(_ratio(rows, preset, label), 2)} |" for label in refs))


def _ratio(rows: list[dict], preset: str, reference: str) -> float | None:
    """Mean ATE of `preset` over the sequences that have a `reference` row, divided by the reference's mean."""
    ate = {(r["sequence"], r["preset"]): r["ate"] for r in rows if r["ate"] is not None}
    seqs = [s for s, p in ate if p == reference and (s, preset) in ate]
    if not seqs:
        return None
    num, den = _mean([ate[s, preset] for s in seqs]), _mean([ate[s, reference] for s in seqs])
    return num / den if num is not None and den else None


def _mean(values: list) -> float | None:
    values = [v for v in values if v is not None]
    return sum(values) / len(values) if values else None


if __name__ == "__main__":
    main()
