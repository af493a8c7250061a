"""A live session's spool: the frames a client streams, kept as an ordinary TUM-layout sequence as they arrive.

The api (:mod:`backend.api.live`) is the only writer; the worker's live runner (:mod:`worker.live`) reads.
Everything lives in the session's sequence folder, so whatever was received is a sequence at any moment:

    rgb/<t>.png|jpg, depth/<t>.png, rgb.txt, depth.txt   the frames (TUM layout, like an upload)
    .live/frames.jsonl   one line per frame, appended after its files are in place: index, timestamp, arrival
                         (the api's clock, Unix seconds), rgb and depth paths relative to the folder
    .live/client         exists while (or once) a client streamed: a second client is refused
    .live/ended.json     the end of the stream (reason, frames): the runner finishes after the last frame

The spool is bounded where it matters: the runner never holds more than a few unprocessed frames (it skips
the oldest when behind and reads a frame's images only when it runs it); the disk keeps every frame
because the session becomes a sequence.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from storage.errors import Conflict

SPOOL = ".live"
FRAMES = "frames.jsonl"
CLIENT = "client"
ENDED = "ended.json"
LIVE_RECEIVING = "receiving"
"""``Sequence.meta['live']`` while a client may stream; the worker then runs the job as a live session."""
LIVE_JOB = "live_job"
"""``Sequence.meta`` key naming the session's own job: its end ends the stream (another job queued on the sequence
while it receives follows the stream too, and leaves the session alone when it ends)."""
LIVE_ENDED = "ended"
"""``Sequence.meta['live']`` after the stream ended: an ordinary sequence (a retried job runs it offline)."""
STREAMING_STAGE = "live"
"""A live job's stage while its stream is open: ``frames_done`` of ``frames_total`` received so far, which
grows (caught up when they are equal: it waits for frames, it is not finishing)."""
FINISHING_STAGE = "finishing"
"""A live job's stage once its stream ended: the run's finish (dense map, evaluation, saving)."""


@dataclass(frozen=True)
class SpooledFrame:
    """One received frame: ``index`` in arrival order, ``timestamp`` the client's (seconds), ``arrival`` the
    api's receipt time (Unix seconds), ``rgb``/``depth`` paths relative to the sequence folder."""

    index: int
    timestamp: float
    arrival: float
    rgb: str
    depth: str


@dataclass(frozen=True)
class StreamEnd:
    """Why and when the stream ended, and how many frames it had."""

    reason: str
    frames: int
    at: float


class LiveSpool:
    """The spool of the session sequence in ``folder`` (see the module docstring)."""

    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder)
        self.dir = self.folder / SPOOL
        self._offset = 0  # reader: bytes of frames.jsonl already parsed
        self._buffer = b""
        self._read: list[SpooledFrame] = []

    # -- writer (the api) ------------------------------------------------------------------------------

    def create(self) -> None:
        """An empty session folder (rgb/, depth/, empty lists, the spool)."""
        for sub in ("rgb", "depth", SPOOL):
            (self.folder / sub).mkdir(parents=True, exist_ok=True)
        for name in ("rgb.txt", "depth.txt"):
            (self.folder / name).write_text(f"# {name[:-4]} images of a live session\n# timestamp filename\n")
        (self.dir / FRAMES).touch()

    def claim_client(self) -> None:
        """Mark that a client streams; :class:`Conflict` when one already did (or does): a session has one
        client, from its first frame to its end. Atomic across api processes (O_EXCL)."""
        if self.ended() is not None:
            raise Conflict("this live session has ended; start a new one", {"reason": "ended"})
        try:
            fd = os.open(self.dir / CLIENT, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            raise Conflict("this live session already has a client; one client streams a session",
                           {"reason": "busy"}) from None
        os.write(fd, f"{time.time():.6f}\n".encode())
        os.close(fd)

    def append(self, frame: SpooledFrame) -> None:
        """Record a frame whose files are in place: the lists first, the spool line last (what the runner sees)."""
        with open(self.folder / "rgb.txt", "a", encoding="utf-8") as fh:
            fh.write(f"{frame.timestamp:.6f} {frame.rgb}\n")
        with open(self.folder / "depth.txt", "a", encoding="utf-8") as fh:
            fh.write(f"{frame.timestamp:.6f} {frame.depth}\n")
        with open(self.dir / FRAMES, "a", encoding="utf-8") as fh:
            fh.write(json.dumps(asdict(frame)) + "\n")

    def end(self, reason: str, frames: int) -> StreamEnd:
        """Mark the stream ended (once: a second call keeps the first reason)."""
        done = self.ended()
        if done is not None:
            return done
        end = StreamEnd(reason, frames, time.time())
        tmp = self.dir / f".{ENDED}.tmp"
        tmp.write_text(json.dumps(asdict(end)))
        os.replace(tmp, self.dir / ENDED)
        return end

    # -- reader (the worker) ---------------------------------------------------------------------------

    def ended(self) -> StreamEnd | None:
        try:
            data: dict[str, Any] = json.loads((self.dir / ENDED).read_text())
        except FileNotFoundError:
            return None
        return StreamEnd(str(data["reason"]), int(data["frames"]), float(data["at"]))

    def count(self) -> int:
        """Frames received so far (reads the new spool lines)."""
        self._poll()
        return len(self._read)

    def frame(self, index: int) -> SpooledFrame:
        self._poll()
        return self._read[index]

    def _poll(self) -> None:
        path = self.dir / FRAMES
        with open(path, "rb") as fh:
            fh.seek(self._offset)
            chunk = fh.read()
        self._offset += len(chunk)
        data = self._buffer + chunk
        lines = data.split(b"\n")
        self._buffer = lines.pop()  # a line still being written waits for its newline
        for line in lines:
            if line.strip():
                self._read.append(SpooledFrame(**json.loads(line)))


def finalize(session: Any, store: Any, sequence_id: str) -> None:
    """Record what an ended session's sequence holds (frames, duration, size) and mark it an ordinary sequence
    (``meta['live'] = 'ended'``); idempotent: the api calls it when the stream ends, the worker after the run."""
    from storage.repositories import sequences

    seq = sequences.get(session, sequence_id)
    folder = store.resolve(seq.path)
    spool = LiveSpool(folder)
    n = spool.count()
    end = spool.ended()
    duration = spool.frame(n - 1).timestamp - spool.frame(0).timestamp if n else 0.0
    size = sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())
    sequences.set_recorded(session, sequence_id, frames=n, duration_s=round(duration, 6), size_bytes=size,
                           has_groundtruth=(folder / "groundtruth.txt").is_file(),
                           meta={"live": LIVE_ENDED, "live_end": end.reason if end else "unknown"})
