"""`vtdslam run SEQUENCE_DIR --camera PRESET --out DIR`: run the SLAM pipeline on a sequence folder."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    app.command("run")(run_command)


def run_command(
    sequence: Annotated[Path, typer.Argument(help="TUM-layout sequence folder (rgb.txt, depth.txt, ...).")],
    out: Annotated[Path, typer.Option("--out", help="Output folder (created).")],
    camera: Annotated[str | None, typer.Option(
        help="Camera preset (tum1, tum2, tum3, bonn, 7scenes) or intrinsics JSON; "
             "the folder's camera.json wins.")] = None,
    preset: Annotated[str | None, typer.Option(help="Pipeline preset (default: the most complete one).")] = None,
    max_frames: Annotated[int | None, typer.Option(help="Process at most this many frames.")] = None,
    start: Annotated[int, typer.Option(help="Index of the first frame.")] = 0,
    config: Annotated[str | None, typer.Option(
        help='Config overrides as JSON, e.g. \'{"loop.enabled": false}\' or a path to a JSON file.')] = None,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
) -> None:
    """Track the sequence and write trajectory.txt, keyframes.txt, map.ply, metrics.json and config.json."""
    from tqdm import tqdm

    from worker.slam.camera import parse_camera
    from worker.slam.errors import ConfigError
    from worker.slam.io.sequence import Sequence
    from worker.slam.pipeline import run_pipeline
    from worker.slam.presets import default_preset, get_preset

    overrides = None
    if config:
        text = Path(config).read_text() if Path(config).is_file() else config
        try:
            overrides = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ConfigError(f"--config is not valid JSON: {exc}") from exc
    cfg = get_preset(preset or default_preset(), overrides)
    seq = Sequence(sequence, parse_camera(camera) if camera else None)
    bar = None

    def progress(done: int, total: int, stage: str) -> None:
        nonlocal bar
        if quiet:
            return
        if bar is None:
            bar = tqdm(total=total, unit="frame", desc=stage, dynamic_ncols=True)
        if bar.desc != stage:
            bar.set_description(stage)
        bar.update(done - bar.n)

    try:
        result = run_pipeline(seq, cfg, out, start=start, max_frames=max_frames, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    m = result.metrics
    typer.echo(f"frames {m['frames']}  tracked {m['tracked']}  lost {m['lost']}  "
               f"relocalisations {m['relocalisations']}  keyframes {m['keyframes']}  fps {m['fps']}")
    if "ate" in m:
        typer.echo(f"ATE rmse {m['ate']['rmse']:.4f} m  (matched {m['matched_poses']})")
        if m.get("groundtruth_frame", "camera") != "camera" and "ate_corrected" in m:
            typer.echo(f"  against {m.get('ate_against')}; {m['ate_corrected']['rmse']:.4f} m against "
                       f"{m.get('ate_corrected_against')}")
    for key, per in (("rpe", "s"), ("rpe_frame", "frame")):
        if isinstance(m.get(key), dict):
            r = m[key]
            typer.echo(f"RPE rmse {r['trans']['rmse']:.4f} m  {r['rot_deg']['rmse']:.3f} deg per {per}"
                       f"  (against {m.get('rpe_against', 'the ground truth')})")
    typer.echo(f"outputs in {out}")
