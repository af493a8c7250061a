"""`vtdslam synth OUT_DIR`: a synthetic dynamic RGB-D sequence with exact truth (masks, background)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    app.command("synth")(synth_command)


def synth_command(
    out_dir: Annotated[Path, typer.Argument(help="Folder to write the TUM-layout sequence and truth/ into.")],
    frames: Annotated[int, typer.Option(help="Number of frames (30 Hz).")] = 300,
    people: Annotated[int, typer.Option(help="Number of walking figures.")] = 2,
    trajectory: Annotated[str, typer.Option(
        help="auto (TUM walking_xyz ground truth from VTD_SHARED_DIR if present, else walk), circle, walk, "
             "or a TUM trajectory file (z-up world, floor at z = 0).")] = "auto",
    seed: Annotated[int, typer.Option(help="Random seed (textures, walkers, path, sensor noise).")] = 0,
) -> None:
    """Render a textured room with walking people from a real or procedural camera path (Kinect-like depth)."""
    from storage.settings import get_settings
    from worker.slam.synth.generator import SynthConfig, generate_synthetic

    cfg = SynthConfig(frames=frames, people=people, trajectory=trajectory, seed=seed,
                      shared_dir=get_settings().shared_dir)
    with typer.progressbar(length=frames, label="rendering") as bar:
        result = generate_synthetic(out_dir, cfg, progress=lambda i, n: bar.update(1))
    fr = result.dynamic_fraction
    typer.echo(f"wrote {result.frames} frames to {result.root} (camera path: {result.source}); "
               f"people cover {100 * sum(fr) / len(fr):.1f} % of the image on average")
