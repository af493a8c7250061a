"""`vtdslam demo`: a small synthetic dynamic sequence in the data dir, so a fresh install has something to run."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

DEMO_NAME = "demo"


def register(app: typer.Typer) -> None:
    app.command("demo")(demo_command)


def register_and_submit_demo(sequence_dir: Path, preset: str) -> str:
    """Register the demo sequence in place with the service's database and queue a job on it; returns its id.

    The running worker (`make run` / `vtdslam serve`) picks the job up, so the dashboard's first screen shows a
    run. The folder is registered where it lies (its own camera.json describes the synthetic camera).
    """
    from storage.artifacts import ArtifactStore
    from storage.db import init_db, make_engine, make_session_factory
    from storage.ingest import register_folder
    from storage.presets import check_preset, parse_camera_spec
    from storage.queue import make_enqueue, make_huey
    from storage.repositories import jobs
    from storage.settings import get_settings

    settings = get_settings(import_root=sequence_dir.resolve().parent)
    engine = make_engine(settings)
    init_db(engine)
    with make_session_factory(engine)() as session:
        seq = register_folder(session, ArtifactStore(settings.data_dir), settings, str(sequence_dir.resolve()),
                              name="demo (synthetic, walking people)", camera=parse_camera_spec("tum3"))
        job = jobs.create(session, sequence_id=seq.id, preset=check_preset(preset))
    make_enqueue(make_huey(settings))(job.id)
    engine.dispose()
    return job.id


def demo_command(
    frames: Annotated[int, typer.Option(help="Number of frames (30 Hz).")] = 150,
    out: Annotated[Path | None, typer.Option(help="Output folder (default: <VTD_DATA_DIR>/demo).")] = None,
    people: Annotated[int, typer.Option(help="Number of walking figures.")] = 2,
    force: Annotated[bool, typer.Option(help="Regenerate even if the demo sequence exists.")] = False,
    preset: Annotated[str, typer.Option(help="Pipeline preset of the submitted job.")] = "full",
    submit: Annotated[bool, typer.Option(help="Register the sequence and queue a job for the service's worker.")]
    = True,
) -> None:
    """Generate the demo sequence (real TUM camera path when ../shared has it, else a built-in one), register it
    with the service and queue a job, so the dashboard opens on a run."""
    from storage.settings import get_settings
    from worker.slam.synth.generator import SynthConfig, generate_synthetic
    from worker.slam.truth import load_truth

    settings = get_settings()
    target = out or settings.data_dir / DEMO_NAME
    existing = load_truth(target) if target.is_dir() else None
    if existing is not None and len(existing) == frames and not force:
        typer.echo(f"demo sequence already at {target} ({frames} frames); --force regenerates it")
    else:
        cfg = SynthConfig(frames=frames, people=people, shared_dir=settings.shared_dir)
        with typer.progressbar(length=frames, label="rendering demo") as bar:
            result = generate_synthetic(target, cfg, progress=lambda i, n: bar.update(1))
        typer.echo(f"wrote demo sequence: {result.frames} frames at {result.root} (camera path: {result.source})")
    if not submit:
        typer.echo(f"next: vtdslam run {target} --out {target.parent / (target.name + '_run')}")
        return
    job = register_and_submit_demo(target, preset)
    typer.echo(f"registered the demo sequence and queued job {job} ({preset}); "
               f"open http://{settings.host}:{settings.port}/ (the worker of `vtdslam serve` runs it)")
