"""Augmented sequences with movers of other classes next to the people ones: ATE per preset against the same
frames without movers, and culling per instance (moving vs static instances of potentially dynamic classes).

    .venv/bin/python bench/bench_movers.py --sequence AUG_DIR:7scenes [--sequence ...] \
        [--presets orb-only,geometry-only,no-restoration] [--max-frames 300] [--config JSON] [--oracle] \
        [--json FILE]
    .venv/bin/python bench/bench_movers.py --from-json FILE [FILE ...]

AUG_DIR comes from `vtdslam augment` (`--movers animal --static 2`, or the people of the default). Each
sequence also gets a `mover-free` row: `orb-only` on its truth backgrounds (the same frames without the movers,
static instances included), the denominator of the issue's "ATE <= 1.2x people-free". With per-instance truth
(movers other than people, or `--static`), the rows add the shares of keypoints culling removed on moving
instances, on static instances and on the source scene (`worker.slam.augment.instance_scores`), and which
classes' movers it caught. `--oracle` adds `no-restoration` with a segmentation that marks every pasted pixel
(moving and static instances), the bound a multi-class network could reach. The summary gives, per kind of
movers and preset, the mean ATE, the ratio of means to `mover-free`, the worst sequence's ratio and the mean
shares. Benchmarks print figures; they assert nothing.
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

from worker.slam.augment.instance_scores import InstanceScoreStage, InstanceTruth  # noqa: E402
from worker.slam.catalog import shipped_catalog  # noqa: E402
from worker.slam.io.sequence import Sequence  # noqa: E402
from worker.slam.pipeline import run_pipeline  # noqa: E402
from worker.slam.presets import get_preset  # noqa: E402
from worker.slam.truth import load_truth, write_background_sequence  # noqa: E402

REFERENCE = "mover-free"
ORACLE = "no-restoration, class oracle"
#: The oracle row: segmentation replaced by the truth (here: every pasted pixel, moving or static).
ORACLE_CONFIG = {"segmentation": {"source": "truth"}}


def oracle_copy(seq_dir: str, out: Path) -> str:
    """A view of `seq_dir` whose truth masks mark every pasted pixel (moving and static instances): what a
    segmenter that knew every mover class would mark potentially dynamic. Frames and backgrounds are linked."""
    import cv2

    src = Path(seq_dir)
    out.mkdir(parents=True)
    for p in src.iterdir():
        if p.name != "truth":
            (out / p.name).symlink_to(p.resolve())
    (out / "truth").mkdir()
    for p in (src / "truth").iterdir():
        if p.name != "masks":
            (out / "truth" / p.name).symlink_to(p.resolve())
    (out / "truth" / "masks").mkdir()
    inst = InstanceTruth.of(src)
    assert inst is not None, f"{src} has no per-instance truth"
    for i in range(len(inst.truth)):
        cv2.imwrite(str(out / "truth" / inst.truth.layout.mask.format(index=i)), inst[i].classes)
    return str(out)


def run_row(run_dir: str, camera: str | None, preset: str, max_frames: int | None, overrides: dict | None,
            instances: InstanceTruth | None) -> dict:
    """One run of `preset` on `run_dir`, with the instance scores appended when `instances` is given."""
    seq = Sequence(run_dir, camera_of(camera))
    config = get_preset(preset, overrides)
    seq[0]  # fixes the camera size before the stages are built (as run_pipeline does)
    stages = shipped_catalog().build_stages(config, seq.camera)
    if instances is not None and "culling" in config.stages:
        stages.append(InstanceScoreStage(instances))
    with tempfile.TemporaryDirectory() as out:
        m = run_pipeline(seq, config, out, max_frames=max_frames, stages=stages).metrics
    ct = m.get("culling", {}).get("truth", {})
    return {"preset": preset, "frames": m["frames"], "tracked": m["tracked"], "ate": m.get("ate", {}).get("rmse"),
            "precision": ct.get("feature_precision"), "recall": ct.get("feature_recall"),
            "missed_seg": ct.get("feature_missed_by_segmentation"),
            "marked": m.get("stage_info", {}).get("potentially_dynamic_fraction"),
            "inst": m.get(InstanceScoreStage.name)}


def sequence_rows(spec: str, presets: list[str], max_frames: int | None, overrides: dict | None,
                  oracle: bool = False, reference: bool = True) -> list[dict]:
    """The preset rows and the mover-free row of one `DIR[:CAMERA]` (and the class oracle's, with per-instance
    truth and `oracle`)."""
    seq_dir, camera = split_spec(spec)
    truth = load_truth(seq_dir)
    if truth is None:
        raise SystemExit(f"{seq_dir}: no truth/ (make it with `vtdslam augment`)")
    kind = truth.layout.generator.get("movers_spec", "person")
    instances = InstanceTruth.of(seq_dir)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        bg = str(write_background_sequence(seq_dir, Path(tmp) / "bg"))
        refs = [(bg, "orb-only", REFERENCE)] if reference else []
        for run_dir, preset, label in refs + [(seq_dir, p, p) for p in presets]:
            r = run_row(run_dir, camera, preset, max_frames, overrides, instances if run_dir == seq_dir else None)
            rows.append({**r, "preset": label, "sequence": Path(seq_dir).name, "movers": kind})
            print_row(rows[-1], rows)
        if oracle and instances is not None:
            r = run_row(oracle_copy(seq_dir, Path(tmp) / "oracle"), camera, "no-restoration",
                        max_frames, {**(overrides or {}), **ORACLE_CONFIG}, instances)
            # its truth scores are against every pasted pixel: only the per-instance shares mean what they say
            rows.append({**r, "precision": None, "recall": None, "missed_seg": None, "preset": ORACLE,
                         "sequence": Path(seq_dir).name, "movers": kind})
            print_row(rows[-1], rows)
    return rows


def _fmt(v, nd=3, pct=False) -> str:
    if v is None:
        return "–"
    return f"{100 * v:.{nd}f} %" if pct else f"{v:.{nd}f}"


def _ref_ate(rows: list[dict], sequence: str) -> float | None:
    return next((r["ate"] for r in rows if r["sequence"] == sequence and r["preset"] == REFERENCE), None)


def _static_cell(share: float | None, interior: float | None) -> str:
    """Static keypoints removed, and of those 8+ px inside the silhouette (when measured)."""
    return _fmt(share, 1, True) + ("" if interior is None else f" ({_fmt(interior, 1, True)} inside)")


def print_header() -> None:
    print("| sequence | movers | preset | tracked | ATE rmse (m) | × mover-free | dyn. precision | dyn. recall "
          "| moving kp removed | static kp removed (8+ px inside) | scene kp removed | static kp "
          "| moving removed by class "
          "| marked area | dyn. kp never marked |")
    print("|" + "---|" * 15)


def print_row(r: dict, rows: list[dict]) -> None:
    inst = r["inst"] or {}
    ref = _ref_ate(rows, r["sequence"])
    ratio = r["ate"] / ref if r["ate"] is not None and ref else None
    by_class = ", ".join(f"{k} {_fmt(v['removed'], 0, True)} of {v['keypoints']}"
                         for k, v in inst.get("moving_by_class", {}).items()) or "–"
    print(f"| {r['sequence']} | {r['movers']} | {r['preset']} | {r['tracked']}/{r['frames']} | {_fmt(r['ate'], 4)} | "
          f"{_fmt(ratio, 2)} | {_fmt(r['precision'], 2)} | {_fmt(r['recall'], 2)} | "
          f"{_fmt(inst.get('moving_removed'), 1, True)} | "
          f"{_static_cell(inst.get('static_removed'), inst.get('static_interior_removed'))} | "
          f"{_fmt(inst.get('scene_removed'), 1, True)} | {inst.get('keypoints', {}).get('static', '–')} | "
          f"{by_class} | {_fmt(r.get('marked'), 1, True)} | {_fmt(r.get('missed_seg'), 1, True)} |", flush=True)


def print_summary(rows: list[dict]) -> None:
    """Per kind of movers and preset: ATE mean, ratio of means to mover-free and the worst sequence's ratio,
    tracked frames, mean precision/recall and instance shares."""
    print("\n| movers | preset | sequences | ATE mean (m) | × mover-free (ratio of means) | worst sequence × | "
          "tracked | dyn. precision | dyn. recall | moving kp removed | static kp removed (8+ px inside) "
          "| scene kp removed |")
    print("|" + "---|" * 12)
    for kind, preset in dict.fromkeys((r["movers"], r["preset"]) for r in rows):
        rs = [r for r in rows if r["movers"] == kind and r["preset"] == preset]
        refs = [_ref_ate(rows, r["sequence"]) for r in rs]
        pairs = [(r["ate"], f) for r, f in zip(rs, refs) if r["ate"] is not None and f]
        ratio = sum(a for a, _ in pairs) / sum(f for _, f in pairs) if pairs else None
        worst = max((a / f for a, f in pairs), default=None)
        inst = lambda k, rs=rs: _mean([(r["inst"] or {}).get(k) for r in rs])  # noqa: E731
        print(f"| {kind} | {preset} | {len(rs)} | {_fmt(_mean([r['ate'] for r in rs]), 4)} | {_fmt(ratio, 2)} | "
              f"{_fmt(worst, 2)} | {sum(r['tracked'] for r in rs)}/{sum(r['frames'] for r in rs)} | "
              f"{_fmt(_mean([r['precision'] for r in rs]), 2)} | {_fmt(_mean([r['recall'] for r in rs]), 2)} | "
              f"{_fmt(inst('moving_removed'), 1, True)} | "
              f"{_static_cell(inst('static_removed'), inst('static_interior_removed'))} | "
              f"{_fmt(inst('scene_removed'), 1, True)} |")


def _mean(values: list) -> float | None:
    values = [v for v in values if v is not None]
    return sum(values) / len(values) if values else None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sequence", action="append", default=[], help="DIR[:CAMERA] of an augmented sequence")
    ap.add_argument("--presets", default="orb-only,geometry-only,no-restoration")
    ap.add_argument("--max-frames", type=int, default=None)
    ap.add_argument("--config", default=None, help="JSON overrides applied to every run")
    ap.add_argument("--oracle", action="store_true",
                    help=f"also run `{ORACLE}`: no-restoration with every pasted pixel (moving or static) as its "
                         "segmentation, what a network that knew every mover class would give")
    ap.add_argument("--no-reference", action="store_true",
                    help="skip the mover-free row (an --oracle run read with --from-json beside one that ran it)")
    ap.add_argument("--json", default=None, metavar="FILE", help="also write the rows to FILE")
    ap.add_argument("--from-json", nargs="+", default=None, metavar="FILE",
                    help="print the table and summary of rows saved by earlier --json runs instead of running")
    args = ap.parse_args()
    if args.from_json:
        rows = [r for f in args.from_json for r in json.loads(Path(f).read_text())]
        print_header()
        for r in rows:
            print_row(r, rows)
        print_summary(rows)
        return
    if not args.sequence:
        ap.error("give --sequence DIR[:CAMERA] or --from-json FILE")
    overrides = json.loads(args.config) if args.config else None
    print_header()
    rows = []
    for spec in args.sequence:
        rows += sequence_rows(spec, [p for p in args.presets.split(",") if p], args.max_frames, overrides,
                              args.oracle, not args.no_reference)
    print_summary(rows)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
