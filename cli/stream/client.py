"""The streaming client: create a live session (`POST /api/v1/live`), send the frames over its WebSocket at
the recorded (or a given) rate, end it; the message format is `backend.api.live_frames`'s."""
from __future__ import annotations

import json
import struct
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

from cli.stream.source import StreamSource
from storage.errors import InvalidInput


def encode_frame(timestamp: float, rgb: bytes, depth: bytes) -> bytes:
    """One frame message: uint32 BE header length, JSON header, colour bytes, depth bytes."""
    head = json.dumps({"timestamp": timestamp, "rgb": len(rgb), "depth": len(depth)}).encode()
    return struct.pack(">I", len(head)) + head + rgb + depth


@dataclass
class StreamReport:
    job_id: str
    sequence_id: str
    sent: int = 0
    sent_at: list[float] = field(default_factory=list)
    """Unix time each frame was sent."""
    ended: dict[str, Any] | None = None
    """The server's last message ("ended" or "error")."""


class StreamError(InvalidInput):
    """The server refused the session or a frame."""


def create_session(base: str, token: str | None, camera: str | dict[str, Any], preset: str,
                   name: str | None = None) -> dict[str, Any]:
    import httpx

    body: dict[str, Any] = {"camera": camera, "preset": preset}
    if name:
        body["name"] = name
    r = httpx.post(f"{base.rstrip('/')}/api/v1/live", json=body, headers=_auth(token), timeout=30)
    if r.status_code != 201:
        raise StreamError(f"the server refused the session ({r.status_code}): {_message(r)}")
    return r.json()


READY_STAGE = "waiting for frames"
"""The job stage of a live runner ready for frames (worker.live.READY_STAGE; the CLI never imports the worker's
module for a string)."""


def wait_ready(base: str, job_id: str, timeout_s: float = 300.0) -> None:
    """Wait until a worker runs the session's job and waits for frames (a recording sent before would be mostly
    dropped: the frames of the worker's start-up are stale by the time it is ready)."""
    import httpx

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        job = httpx.get(f"{base.rstrip('/')}/api/v1/jobs/{job_id}", timeout=30).json()
        if job["status"] != "queued" and job["stage"] not in ("", "starting"):
            if job["status"] != "running":
                raise StreamError(f"the session's job ended before the stream: {job.get('error') or job['status']}")
            return
        time.sleep(0.2)
    raise StreamError(f"no worker took the session's job in {timeout_s:g} s (is `vtdslam worker` running?)")


def send(base: str, session: dict[str, Any], source: StreamSource, *, token: str | None = None,
         rate: float | None = None, on_frame: Callable[[int, float], None] | None = None) -> StreamReport:
    """Stream `source` into `session`: at the recorded timing, or `rate` frames per second when given."""
    return send_frames(base, session, _paced(source, rate), source.groundtruth, token=token, on_frame=on_frame)


def _paced(source: StreamSource, rate: float | None) -> Iterator[tuple[float, bytes, bytes]]:
    """The source's frames, each read when it is due."""
    t0_src, t0 = source.frames[0][0], time.monotonic()
    for i, (t, rgb, depth) in enumerate(source.frames):
        due = t0 + (i / rate if rate else t - t0_src)
        time.sleep(max(0.0, due - time.monotonic()))
        yield t, rgb.read_bytes(), depth.read_bytes()


def send_frames(base: str, session: dict[str, Any], frames: Iterable[tuple[float, bytes, bytes]],
                groundtruth: str | None = None, *, token: str | None = None,
                on_frame: Callable[[int, float], None] | None = None) -> StreamReport:
    """Send `frames` ((timestamp s, colour bytes, depth bytes), each as soon as the iterable gives it: a source
    paces itself) into `session`, then the ground truth if any, then the end. Ctrl-C ends the stream early: the
    frames sent are kept by the session."""
    from websockets.sync.client import connect

    ws_url = base.rstrip("/").replace("http://", "ws://", 1).replace("https://", "wss://", 1) + session["stream_url"]
    report = StreamReport(session["job_id"], session["sequence_id"])
    # no per-message deflate: the images are compressed already (deflating a 210 kB Bonn frame again cost 7 ms of
    # CPU on each side, bench/bench_live.py)
    with connect(ws_url, additional_headers=_auth(token), max_size=2**24, open_timeout=30, compression=None) as ws:
        hello = json.loads(ws.recv(timeout=30))
        if hello.get("type") != "ready":
            raise StreamError(f"the server refused the stream: {hello.get('error', hello)}")
        try:
            for i, (t, rgb, depth) in enumerate(frames):
                ws.send(encode_frame(t, rgb, depth))
                report.sent += 1
                report.sent_at.append(time.time())
                if on_frame is not None:
                    on_frame(i, t)
                if (early := _poll(ws)) is not None:  # refused a frame or ended by the server
                    report.ended = early
                    return report
        except KeyboardInterrupt:
            pass  # the end below keeps what was sent
        if groundtruth:
            ws.send(json.dumps({"type": "groundtruth", "text": groundtruth}))
        ws.send(json.dumps({"type": "end"}))
        report.ended = json.loads(ws.recv(timeout=60))
    return report


def _poll(ws: Any) -> dict[str, Any] | None:
    try:
        return json.loads(ws.recv(timeout=0))
    except TimeoutError:
        return None


def _auth(token: str | None) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"} if token else {}


def _message(r: Any) -> str:
    try:
        return str(r.json()["error"]["message"])
    except Exception:  # noqa: BLE001 - not our error body: the raw text says what happened
        return r.text[:300]
