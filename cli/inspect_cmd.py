"""`vtdslam inspect SEQUENCE_DIR`: what a sequence folder holds, before running anything on it."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    app.command("inspect")(inspect_command)


def inspect_command(
    sequence_dir: Annotated[Path, typer.Argument(help="TUM-layout folder (rgb.txt, depth.txt, ...).")],
    camera: Annotated[str | None, typer.Option(
        help="Camera preset (tum1, tum2, tum3, bonn, 7scenes) or JSON intrinsics; camera.json in the folder wins."
    )] = None,
    samples: Annotated[int, typer.Option(help="Depth frames sampled for the validity figure.")] = 10,
    as_json: Annotated[bool, typer.Option("--json", help="Print as JSON.")] = False,
) -> None:
    """Frames, duration, depth validity, ground-truth coverage and the camera used."""
    from worker.slam.inspect import inspect_sequence

    report = inspect_sequence(sequence_dir, camera, samples)
    if as_json:
        typer.echo(json.dumps(report, indent=2))
        return
    for key, value in report.items():
        typer.echo(f"{key:<22}{value}")
