"""Fingerprints of the pipeline's outputs: md5 of trajectory.txt, keyframes.txt and map.ply per sequence x preset.

For behaviour-neutral changes (refactors): run it before and after, on the same sequences, and diff the tables.
Runs go through the `vtdslam run` command of the checkout this file lives in (subprocesses, so two checkouts
can be compared from one shell), one at a time.

    .venv/bin/python bench/fingerprint.py --sequence DIR:CAMERA[:MAX_FRAMES] [--sequence ...] \
        [--presets orb-only,geometry-only,no-restoration,full] [--json OUT.json] [--keep DIR]

The standard set for a refactor (issue 56): the synthetic room (`vtdslam synth OUT --frames 200 --people 2`),
an augmented sequence (`vtdslam augment ../shared/data/7scenes_redkitchen OUT --people-from
../shared/data/coco128_seg --frames 300`), static 7-Scenes (300 frames) and `bonn_crowd_dev`.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FILES = ("trajectory.txt", "keyframes.txt", "map.ply")
PRESETS = "orb-only,geometry-only,no-restoration,full"


def _md5(path: Path) -> str:
    return hashlib.md5(path.read_bytes()).hexdigest() if path.is_file() else "missing"


def fingerprint(seq: str, camera: str, max_frames: int | None, preset: str, out: Path) -> dict[str, str]:
    """Run one sequence under one preset with this checkout's CLI; md5 of each output file."""
    cmd = [sys.executable, "-c", "from cli.main import main; main()", "run", seq, "--camera", camera,
           "--preset", preset, "--out", str(out), "--quiet"]
    if max_frames is not None:
        cmd += ["--max-frames", str(max_frames)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        return {name: f"error {done.returncode}: {done.stderr.strip().splitlines()[-1:]}" for name in FILES}
    return {name: _md5(out / name) for name in FILES}


def _parse_sequence(text: str) -> tuple[str, str, int | None]:
    parts = text.split(":")
    if len(parts) not in (2, 3):
        raise SystemExit(f"--sequence wants DIR:CAMERA[:MAX_FRAMES], got {text!r}")
    return parts[0], parts[1], int(parts[2]) if len(parts) == 3 else None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sequence", action="append", required=True, help="DIR:CAMERA[:MAX_FRAMES]")
    ap.add_argument("--presets", default=PRESETS)
    ap.add_argument("--json", type=Path, help="also write the table as JSON")
    ap.add_argument("--keep", type=Path, help="keep the run folders here (default: a temporary folder)")
    args = ap.parse_args()
    table: dict[str, dict[str, str]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        base = args.keep or Path(tmp)
        print(f"| sequence | preset | {' | '.join(FILES)} |")
        print("|---|---|" + "---|" * len(FILES))
        for text in args.sequence:
            seq, camera, max_frames = _parse_sequence(text)
            name = Path(seq).name + (f"[:{max_frames}]" if max_frames else "")
            for preset in args.presets.split(","):
                sums = fingerprint(seq, camera, max_frames, preset, base / f"{Path(seq).name}-{preset}")
                table[f"{name} {preset}"] = sums
                print(f"| {name} | {preset} | {' | '.join(s[:12] for s in sums.values())} |", flush=True)
    if args.json:
        args.json.write_text(json.dumps(table, indent=1) + "\n")


if __name__ == "__main__":
    main()
