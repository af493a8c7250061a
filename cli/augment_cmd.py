"""`vtdslam augment SEQUENCE_DIR --people-from COCO_DIR OUT_DIR [--movers animal,chair] [--static N]`: real people
(or animals, vehicles, objects people move) walking through a real sequence."""
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
        "--people-from", help="YOLO-seg folder (images/, labels/, COCO-80 ids) whose polygons of the --movers "
                              "classes are cut out.")],
    frames: Annotated[int | None, typer.Option(help="Use the first N frames (default: all).")] = None,
    people: Annotated[int, typer.Option(help="Movers (people by default) taking turns to cross the view.")] = 2,
    movers: Annotated[str, typer.Option(
        help="Classes that move: comma-separated groups (person, animal, vehicle, object) or COCO names (dog, "
             "suitcase, teddy bear ...). Other than person, truth/classes/ holds each pasted pixel's COCO id + 1.")
    ] = "person",
    static: Annotated[int, typer.Option(
        help="Instances of the --movers classes that stand still all sequence (a parked chair): part of the static "
             "scene and its truth background, never in truth/masks; their ids are in truth/static/.")] = 0,
    static_classes: Annotated[str | None, typer.Option(
        help="Classes of the --static instances, as --movers (default: the --movers classes).")] = None,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    camera: Annotated[str, typer.Option(
        help="Camera preset or JSON when the sequence has no camera.json.")] = "7scenes",
) -> None:
    """Composite COCO people (or other movers) as 3D billboards on the floor, occluded by and replacing the real
    depth."""
    from worker.slam.augment.generator import AugmentConfig, generate_augmented
    from worker.slam.augment.stats import coverage_summary
    from worker.slam.camera import parse_camera

    cfg = AugmentConfig(frames=frames, people=people, seed=seed, camera=parse_camera(camera), movers=movers,
                        static=static, static_classes=static_classes)
    with typer.progressbar(length=frames or 0, label="compositing", hidden=frames is None) as bar:
        result = generate_augmented(sequence_dir, people_from, out_dir, cfg, progress=lambda i, n: bar.update(1))
    what = "people" if movers.strip().lower() == "person" else "movers"
    typer.echo(f"wrote {result.frames} frames to {result.root}; {coverage_summary(result.dynamic_fraction, what=what)}")
