"""`vtdslam import-bag BAG OUT`: a ROS 1 .bag or ROS 2 .db3/.mcap recording to a TUM-layout sequence folder."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    app.command("import-bag")(import_bag_command)


def import_bag_command(
    bag: Annotated[Path, typer.Argument(help="ROS 1 .bag file, ROS 2 .db3/.mcap file or ROS 2 bag folder.")],
    out: Annotated[Path, typer.Argument(help="New sequence folder to write (must not exist).")],
    rgb: Annotated[str | None, typer.Option("--rgb", help="Colour image topic (default: found).")] = None,
    depth: Annotated[str | None, typer.Option("--depth", help="Depth image topic (default: found).")] = None,
    info: Annotated[str | None, typer.Option("--info", help="CameraInfo topic (default: the colour one's).")] = None,
    gt: Annotated[str | None, typer.Option(
        "--gt", help="Ground-truth topic: PoseStamped, TransformStamped or tf (default: a pose topic named "
                     "groundtruth/vicon/mocap, if any).")] = None,
    gt_frames: Annotated[str | None, typer.Option(
        "--gt-frames", help="PARENT:CHILD transform to take from a tf topic (default: the first one seen).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
) -> None:
    """Colour, depth (16-bit PNG, 5000 per metre), rgb.txt/depth.txt, camera.json and groundtruth.txt."""
    from storage.errors import InvalidInput
    from storage.ingest.bag import import_bag

    frames: tuple[str, str] | None = None
    if gt_frames is not None:
        parent, sep, child = gt_frames.partition(":")
        if not sep or not parent or not child:
            raise InvalidInput(f"--gt-frames wants PARENT:CHILD, got {gt_frames!r}")
        frames = (parent, child)
    result = import_bag(bag, out, rgb=rgb, depth=depth, info=info, gt=gt, gt_frames=frames)
    if as_json:
        typer.echo(json.dumps(result.as_dict(), indent=2))
        return
    typer.echo(f"{out}: {result.frames} colour/depth pairs from a {result.bag_format.upper()} bag")
    typer.echo(f"  colour  {result.rgb_topic} ({result.rgb_frames} images)")
    typer.echo(f"  depth   {result.depth_topic} ({result.depth_frames} images)")
    typer.echo(f"  camera  {result.info_topic or '-'}" + ("  -> camera.json" if result.camera else ""))
    typer.echo(f"  truth   {result.gt_topic or '-'}" + (f"  ({result.gt_poses} poses)" if result.gt_topic else ""))
    for note in result.notes:
        typer.echo(f"  note: {note}")
