"""The live runner: a session's frames through the pipeline as they arrive (``storage.live`` is the spool the
api fills), then the same finish and outputs as an offline run.

It has the signature of ``worker.runner.PipelineFn`` (plus the snapshot writer), so ``worker.tasks`` runs a
live session as any job: claim, heartbeat, progress, results. The run never waits on more than
``LiveConfig.max_behind`` unprocessed frames: when the pipeline falls behind, the oldest unprocessed frames are
skipped (dropped: counted in the metrics as ``live_frames_dropped``; their files stay in the sequence). After the
stream ended, a ground truth the client sent (``groundtruth.txt`` in the folder) scores the trajectory as in an
offline run.
"""
from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from storage.live import FINISHING_STAGE, STREAMING_STAGE, LiveSpool, SpooledFrame
from worker.live_feed import Follower, LiveFeed, StreamEnded
from worker.runner import CancelFn, Cancelled, ProgressFn, RunOutput
from worker.snapshots import PartialWriter

log = logging.getLogger("worker.live")


@dataclass(frozen=True)
class LiveConfig:
    """How a live session is followed."""

    max_behind: int = 3
    """Unprocessed frames the run may fall behind by; older ones are dropped (30 Hz: 0.1 s)."""
    poll_s: float = 0.005
    """How often the spool is checked while no frame is waiting."""
    idle_timeout_s: float = 120.0
    """A stream that sent nothing (and did not end) for this long is ended by the worker (an api that died)."""
    frames_ahead: int = 3
    """Frames taken, decoded and queued for their stages' `prepare` ahead of the one the pipeline steps (at least
    1): the network and the ORB thread work on the next frames while the pipeline thread tracks, so neither idles
    waiting for a frame to be decoded. Bonn at 30 Hz through the whole service (bench/bench_live.py, 2026-12-06):
    with 1, 8.6-13.7 % of frames dropped (5 runs); with 2, 7.3-10.8 % (8 runs); with 3, 5.4-7.6 % (5 runs), the
    median delay from arrival to pose on the page 211-244 ms against 207-217 ms with 2. A frame ahead can add a
    frame's time to the delay while the run is behind (docs/results/realtime.md)."""
    warm_up_runs: int = 2
    """Runs of every stage's `prepare` (pure: the run's results do not change) on a synthetic frame of the camera's
    size before the session is ready (0: none). The first calls load numba's cached kernels and let TorchScript
    optimise MSNET: the first two frames took 454 and 100 ms instead of ~37 (Bonn, `no-restoration`), half a
    second in which a 30 Hz stream has a dozen frames dropped; TorchScript optimises on its second run."""


READY_STAGE = "waiting for frames"
"""The job's stage once the live runner is ready (a client streaming a recording may wait for it)."""


def run_live_slam(sequence_dir: Path, camera: dict[str, Any], preset: str, overrides: dict[str, Any], out_dir: Path,
                  *, progress: ProgressFn, should_cancel: CancelFn, snapshot: PartialWriter | None = None,
                  live: LiveConfig | None = None) -> RunOutput:
    """Follow the session in ``sequence_dir`` until its stream ends, then finish the run and write its files to
    ``out_dir`` (as ``worker.runner.run_slam``). Raises ``Cancelled`` when ``should_cancel`` says so and
    ``worker.slam.errors.SlamError`` (with the reason) when no frame came or none could be tracked."""
    from formats.frame_stats import FrameStats
    from worker.slam.camera import Camera, camera_from_preset
    from worker.slam.catalog import shipped_catalog
    from worker.slam.errors import SequenceFormatError
    from worker.slam.io.sequence import Sequence
    from worker.slam.presets import get_preset
    from worker.slam.run.outputs import write_outputs
    from worker.slam.run.pipeline_run import PipelineRun

    live = live or LiveConfig()
    cam = camera_from_preset(camera["preset"]) if "preset" in camera else Camera.from_dict(camera)
    # a stream has no frames after the latest: restoration takes its references from the past (its "causal"
    # mode, meant for streaming input) unless the session's config says otherwise
    config = get_preset(preset, {"restoration.references": "causal", **(overrides or {})})
    # the stages (the segmentation network) are built before the first frame is waited for: loading them
    # takes seconds, during which a stream would fall behind; rebuilt only if the frames are of another size
    stages = shipped_catalog().build_stages(config, cam)
    warm_up(stages, cam, live.warm_up_runs)
    follower = Follower(LiveSpool(sequence_dir), live.max_behind, live.poll_s, live.idle_timeout_s)
    follower.skip_waiting()  # frames that came while the worker started are stale: counted as dropped

    def check_cancel() -> bool:
        if should_cancel():
            raise Cancelled(f"cancelled after {follower.taken} frames of the live session")
        return False

    progress(0, 0, READY_STAGE)
    try:
        first = follower.next(check_cancel)
    except StreamEnded as exc:
        raise SequenceFormatError(f"the live session received no frame ({exc})") from None
    reader = _FrameReader(sequence_dir, cam)
    frame = reader.read(first)
    if reader.camera is not cam:
        stages = shipped_catalog().build_stages(config, reader.camera)
    with PipelineRun(reader.camera, config, stages, on_step=snapshot) as run:
        processed = _follow(run, follower, reader, (first, frame), snapshot, progress, check_cancel,
                            live.frames_ahead)
        progress(processed, follower.received, FINISHING_STAGE)
        run.sequence = Sequence(sequence_dir, reader.camera)  # complete now: its ground truth scores the run
        result = run.finish()
    counts = follower.counts(processed)
    result.metrics.update({f"live_{k}": v for k, v in counts.items()})
    result.metrics["live_end"] = follower.end.reason if follower.end else "unknown"
    write_outputs(result, config, Path(out_dir))
    log.info("live session: %s", counts)
    return RunOutput(metrics=result.metrics, config=config.to_dict(),
                     frame_stats=[FrameStats.from_row(r) for r in result.frame_stats])


def warm_up(stages: list[Any], camera: Any, runs: int) -> None:
    """Every stage's `prepare` `runs` times on a textured frame (noise, depth 1.5 m) of `camera`'s size."""
    import numpy as np

    from worker.slam.io.sequence import Frame

    if runs <= 0:
        return
    rng = np.random.default_rng(0)
    h, w = camera.height, camera.width
    frame = Frame(-1, 0.0, rng.integers(0, 256, (h, w, 3), dtype=np.uint8), np.full((h, w), 1.5, np.float32))
    for stage in stages:
        prepare = getattr(stage, "prepare", None)
        if callable(prepare):
            for _ in range(runs):
                prepare(frame)


def _follow(run: Any, follower: Follower, reader: _FrameReader, first: tuple[SpooledFrame, Any],
            snapshot: PartialWriter | None, progress: ProgressFn, check_cancel: Callable[[], object],
            ahead: int) -> int:
    """Step `run` through the session until the stream ends. A feed thread takes the next frame as soon as it
    has arrived and the run has room for it (`worker.live_feed`), decodes it and queues its stages' `prepare`
    work (the segmentation network, the ORB features), each stage's on its own thread, as the offline driver
    overlaps them (`worker.slam.run.driver`); each thread works in frame order, so results are those of running
    the frames one after the other. Returns how many frames it stepped."""
    from worker.slam.io.prepare_ahead import PrepareAhead

    with PrepareAhead(run.stages.preparers()) as prep, \
            LiveFeed(follower, lambda ref: (ref, prep.submit(reader.read(ref))), ahead=ahead) as feed:
        ref, item = first[0], prep.submit(first[1])
        processed = 0
        while True:
            if snapshot is not None:
                snapshot.arrival(ref.index, ref.arrival)
                snapshot.counts.update(follower.counts(processed + 1))
            run.step(item)
            processed += 1
            progress(processed, follower.received, STREAMING_STAGE)
            check_cancel()
            try:
                ref, item = feed.get(check_cancel)
            except StreamEnded:
                return processed


class _FrameReader:
    """Decodes spooled frames; the camera is rescaled to the first frame's size (as ``Sequence`` does)."""

    def __init__(self, folder: Path, camera: Any) -> None:
        self.folder, self.camera = folder, camera
        self.size: tuple[int, int] | None = None

    def read(self, ref: SpooledFrame) -> Any:
        from worker.slam.errors import SequenceFormatError
        from worker.slam.io.images import read_depth, read_rgb
        from worker.slam.io.sequence import Frame

        rgb = read_rgb(self.folder / ref.rgb)
        depth = read_depth(self.folder / ref.depth, self.camera.depth_scale)
        h, w = depth.shape
        if self.size is None:
            self.size = (w, h)
            if (w, h) != (self.camera.width, self.camera.height):
                self.camera = self.camera.scaled(w, h)
        if rgb.shape[:2] != depth.shape or (w, h) != self.size:
            raise SequenceFormatError(f"frame {ref.index}: size differs from the session's first frame",
                                      path=self.folder / ref.rgb)
        return Frame(ref.index, ref.timestamp, rgb, depth)
