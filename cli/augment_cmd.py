"""`vtdslam augment SEQUENCE_DIR --people-from COCO_DIR OUT_DIR`: real people walking through a real sequence."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    app.command("augment")(augment_command)


def augment_command(
    sequence_dir: Annotated[Path, typer.Argument(help="Static TUM-layout RGB-D sequence with groundtruth.txt.")],
    out_dir: Annotated[Path, typer.Argument(help="Folder to write the augmented sequence and truth/ into.")],
    people_from: Annotated[Path, typer.Option(
        "--people-from", help="YOLO-seg folder (images/, labels/) whose class-0 polygons are cut out.")],
    frames: Annotated[int | None, typer.Option(help="Use the first N frames (default: all).")] = None,
    people: Annotated[int, typer.Option(help="People taking turns to walk through the view.")] = 2,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    camera: Annotated[str, typer.Option(
        help="Camera preset or JSON when the sequence has no camera.json.")] = "7scenes",
) -> None:
    """Composite COCO people as 3D billboards on the floor, occluded by and replacing the real depth."""
    from worker.slam.augment.generator import AugmentConfig, generate_augmented
    from worker.slam.augment.stats import coverage_summary
    from worker.slam.camera import parse_camera

    cfg = AugmentConfig(frames=frames, people=people, seed=seed, camera=parse_camera(camera))
    with typer.progressbar(length=frames or 0, label="compositing", hidden=frames is None) as bar:
        result = generate_augmented(sequence_dir, people_from, out_dir, cfg, progress=lambda i, n: bar.update(1))
    typer.echo(f"wrote {result.frames} frames to {result.root}; {coverage_summary(result.dynamic_fraction)}")
