"""`vtdslam stream SOURCE --to URL`: a TUM folder or ROS bag into a live session, at its recorded rate."""
from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    app.command("stream")(stream_command)


def stream_command(
    source: Annotated[Path, typer.Argument(help="TUM-layout folder, or ROS 1 .bag / ROS 2 .db3/.mcap bag.")],
    to: Annotated[str, typer.Option("--to", help="The api's base URL, e.g. http://127.0.0.1:8000.")],
    token: Annotated[str | None, typer.Option("--token", envvar="VTD_API_TOKEN",
                                              help="API token, when the server sets one.")] = None,
    rate: Annotated[float | None, typer.Option("--rate", min=0.1, max=1000.0,
                                               help="Frames per second (default: the recorded timing).")] = None,
    camera: Annotated[str | None, typer.Option(
        "--camera",
        help="Camera preset (default: the source's camera.json; a bag's comes from its CameraInfo).")] = None,
    preset: Annotated[str, typer.Option("--preset", help="Pipeline preset.")] = "no-restoration",
    name: Annotated[str | None, typer.Option("--name", help="Name of the session's sequence.")] = None,
    max_frames: Annotated[int | None, typer.Option("--max-frames", min=1, help="Send only the first N.")] = None,
    wait: Annotated[bool, typer.Option("--wait/--no-wait", help="Start sending once a worker is ready for the "
                                       "session (else the frames of its start-up are dropped as stale).")] = True,
) -> None:
    """Start a live session and send the frames; the job page shows the run while it streams. Ends the
    session after the last frame (sending the source's ground truth first, so the job reports ATE)."""
    from cli.stream.client import create_session, send, wait_ready
    from cli.stream.source import open_source
    from storage.errors import InvalidInput

    with tempfile.TemporaryDirectory(prefix="vtdslam-stream-") as scratch, \
            open_source(source, Path(scratch), max_frames) as src:
        cam = camera or src.camera
        if cam is None:
            raise InvalidInput("the source has no camera.json: give --camera PRESET")
        session = create_session(to, token, cam, preset, name)
        typer.echo(f"live session: job {session['job_id']}  page {to.rstrip('/')}/jobs/{session['job_id']}")
        if wait:
            wait_ready(to, session["job_id"])
        report = send(to, session, src, token=token, rate=rate)
    end = report.ended or {}
    if end.get("type") == "error":
        raise InvalidInput(f"the server ended the stream after {report.sent} frames: {end['error']['message']}")
    typer.echo(f"sent {report.sent} frames; the server kept {end.get('frames', '?')} "
               f"({end.get('reason', 'no reason given')}); the job finishes with them")
