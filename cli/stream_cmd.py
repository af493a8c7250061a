"""`vtdslam stream SOURCE --to URL`: a TUM folder or ROS bag into a live session at its recorded rate, or an RGB-D
camera attached to this machine (`camera:INDEX`, through OpenCV's OpenNI2 backends) as it gives frames."""
from __future__ import annotations

import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

if TYPE_CHECKING:
    from cli.stream.camera import OpenCapture


def register(app: typer.Typer) -> None:
    app.command("stream")(stream_command)


def stream_command(
    source: Annotated[str, typer.Argument(
        help="TUM-layout folder, ROS 1 .bag / ROS 2 .db3/.mcap bag, or camera:INDEX (an RGB-D camera through "
             "OpenCV's OpenNI2 backends, e.g. camera:0).")],
    to: Annotated[str, typer.Option("--to", help="The api's base URL, e.g. http://127.0.0.1:8000.")],
    token: Annotated[str | None, typer.Option("--token", envvar="VTD_API_TOKEN",
                                              help="API token, when the server sets one.")] = None,
    rate: Annotated[float | None, typer.Option("--rate", min=0.1, max=1000.0,
                                               help="Frames per second (default: the recorded timing; a camera "
                                                    "sends at its own rate).")] = None,
    camera: Annotated[str | None, typer.Option(
        "--camera",
        help="Camera preset (default: the source's camera.json; a bag's comes from its CameraInfo; a camera's "
             "from its focal length).")] = None,
    preset: Annotated[str, typer.Option("--preset", help="Pipeline preset.")] = "no-restoration",
    name: Annotated[str | None, typer.Option("--name", help="Name of the session's sequence.")] = None,
    max_frames: Annotated[int | None, typer.Option("--max-frames", min=1, help="Send only the first N "
                                                   "(a camera: stop after N; else Ctrl-C ends the stream).")] = None,
    wait: Annotated[bool, typer.Option("--wait/--no-wait", help="Start sending once a worker is ready for the "
                                       "session (else the frames of its start-up are dropped as stale).")] = True,
) -> None:
    """Start a live session and send the frames; the job page shows the run while it streams. Ends the
    session after the last frame (sending the source's ground truth first, so the job reports ATE)."""
    from cli.stream.camera import camera_index
    from cli.stream.client import create_session, send, wait_ready
    from cli.stream.source import open_source
    from storage.errors import InvalidInput

    index = camera_index(source)
    if index is not None:
        if rate is not None:
            raise InvalidInput("--rate is for recordings: a camera sends frames as it gives them")
        stream_camera(index, to, token=token, camera=camera, preset=preset, name=name, max_frames=max_frames,
                      wait=wait)
        return
    with tempfile.TemporaryDirectory(prefix="vtdslam-stream-") as scratch, \
            open_source(Path(source), Path(scratch), max_frames) as src:
        cam = camera or src.camera
        if cam is None:
            raise InvalidInput("the source has no camera.json: give --camera PRESET")
        session = create_session(to, token, cam, preset, name)
        typer.echo(f"live session: job {session['job_id']}  page {to.rstrip('/')}/jobs/{session['job_id']}")
        if wait:
            wait_ready(to, session["job_id"])
        report = send(to, session, src, token=token, rate=rate)
    _done(report)


def stream_camera(index: int, to: str, *, token: str | None = None, camera: str | None = None,
                  preset: str = "no-restoration", name: str | None = None, max_frames: int | None = None,
                  wait: bool = True, open_capture: OpenCapture | None = None) -> None:
    """Stream camera `index` (opened by `open_capture`, `cv2.VideoCapture` by default) into a new live session
    until it stops giving frames, `max_frames` were sent or Ctrl-C. The camera is opened and checked first."""
    from cli.stream.camera import open_rgbd_camera
    from cli.stream.client import create_session, send_frames, wait_ready
    from storage.errors import InvalidInput

    cam = open_rgbd_camera(index, open_capture)
    try:
        spec: str | dict[str, Any] | None = camera or cam.camera_spec()
        if spec is None:
            raise InvalidInput(f"camera {index} reports no focal length: give --camera PRESET")
        typer.echo(f"camera {index}: {cam.width}x{cam.height} through {cam.backend}")
        session = create_session(to, token, spec, preset, name or f"camera {index}")
        typer.echo(f"live session: job {session['job_id']}  page {to.rstrip('/')}/jobs/{session['job_id']}")
        if wait:
            wait_ready(to, session["job_id"])
        report = send_frames(to, session, cam.frames(max_frames), token=token)
    finally:
        cam.close()
    _done(report)


def _done(report: Any) -> None:
    from storage.errors import InvalidInput

    end = report.ended or {}
    if end.get("type") == "error":
        raise InvalidInput(f"the server ended the stream after {report.sent} frames: {end['error']['message']}")
    typer.echo(f"sent {report.sent} frames; the server kept {end.get('frames', '?')} "
               f"({end.get('reason', 'no reason given')}); the job finishes with them")
