"""The live feed: frames taken in arrival order as they arrive, one or more ahead of the run, loaded on the feed thread;
the drop rule applied when a frame is taken; errors, the end and a cancel reach the run at their frame; and a live
run of a stream it keeps up with is the offline run of the same frames, bit for bit."""
from __future__ import annotations

import shutil
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from formats.association import associate
from formats.tum_lists import read_list
from storage.live import LiveSpool, SpooledFrame
from worker.live import LiveConfig, run_live_slam
from worker.live_feed import Follower, LiveFeed, StreamEnded


def _spool(tmp_path: Path) -> LiveSpool:
    spool = LiveSpool(tmp_path / "seq")
    spool.create()
    return spool


def _add(spool: LiveSpool, i: int) -> None:
    spool.append(SpooledFrame(i, float(i), time.time(), f"rgb/{i}.png", f"depth/{i}.png"))


def _wait(cond: Callable[[], bool], timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.002)


def _follower(spool: LiveSpool, max_behind: int = 3) -> Follower:
    return Follower(spool, max_behind, poll_s=0.001, idle_timeout_s=30.0)


def test_frames_are_loaded_on_the_feed_thread_in_order_as_they_arrive(tmp_path: Path) -> None:
    spool = _spool(tmp_path)
    loaded: list[tuple[int, str]] = []

    def load(ref: SpooledFrame) -> int:
        loaded.append((ref.index, threading.current_thread().name))
        return ref.index

    with LiveFeed(_follower(spool), load, poll_s=0.01) as feed:
        _add(spool, 0)
        assert feed.get() == 0
        _add(spool, 1)
        _wait(lambda: len(loaded) == 2)  # loaded when it arrives, before it is asked for
        assert [i for i, _ in loaded] == [0, 1]
        assert feed.get() == 1
        spool.end("client ended the stream", 2)
        with pytest.raises(StreamEnded, match="client ended"):
            feed.get()
    assert all(name == "vtdslam-live-feed" for _, name in loaded)
    assert not any(t.name == "vtdslam-live-feed" for t in threading.enumerate())


def test_one_frame_is_taken_ahead_and_the_oldest_waiting_are_dropped(tmp_path: Path) -> None:
    """While the run is busy the feed holds one frame; of those that wait behind it, the newest `max_behind`
    are kept when the next is taken."""
    spool = _spool(tmp_path)
    follower = _follower(spool, max_behind=2)
    with LiveFeed(follower, lambda ref: ref.index, poll_s=0.01) as feed:
        _add(spool, 0)
        assert feed.get() == 0  # the run is now busy with frame 0
        _add(spool, 1)
        _wait(lambda: follower.taken == 2)  # frame 1 is taken ahead as it arrives
        for i in range(2, 7):  # 2..6 wait behind it
            _add(spool, i)
        time.sleep(0.05)
        assert follower.taken == 2
        got = [feed.get(), feed.get(), feed.get()]
        spool.end("client ended the stream", 7)
        with pytest.raises(StreamEnded):
            feed.get()
    assert got == [1, 5, 6]  # 2, 3 and 4 were more than 2 behind when frame 5 was taken
    assert follower.dropped == 3 and follower.counts(4) == {
        "frames_received": 7, "frames_processed": 4, "frames_dropped": 3, "max_behind": 2}


def test_two_frames_are_taken_ahead_when_asked_and_the_rest_wait_to_be_dropped(tmp_path: Path) -> None:
    """`ahead=2` (the live runner's default): while the run is busy two frames are taken and loaded, the others
    wait in the spool where the drop rule applies; one more is taken as soon as the run takes one."""
    spool = _spool(tmp_path)
    follower = _follower(spool, max_behind=2)
    with LiveFeed(follower, lambda ref: ref.index, poll_s=0.01, ahead=2) as feed:
        _add(spool, 0)
        assert feed.get() == 0  # the run is now busy with frame 0
        _add(spool, 1)
        _add(spool, 2)
        _wait(lambda: follower.taken == 3)  # frames 1 and 2 taken ahead as they arrive
        for i in range(3, 8):  # 3..7 wait behind them
            _add(spool, i)
        time.sleep(0.05)
        assert follower.taken == 3 and follower.dropped == 0
        assert feed.get() == 1
        _wait(lambda: follower.taken == 4)  # room for one more: 6 (3, 4, 5 were more than 2 behind)
        got = [feed.get(), feed.get(), feed.get()]
        spool.end("client ended the stream", 8)
        with pytest.raises(StreamEnded):
            feed.get()
    assert got == [2, 6, 7] and follower.dropped == 3
    with pytest.raises(ValueError, match="at least 1"):
        LiveFeed(follower, lambda ref: ref.index, ahead=0)


def test_a_load_error_is_raised_at_its_frame(tmp_path: Path) -> None:
    spool = _spool(tmp_path)

    def load(ref: SpooledFrame) -> int:
        if ref.index == 1:
            raise ValueError("frame 1 is not an image")
        return ref.index

    with LiveFeed(_follower(spool), load, poll_s=0.01) as feed:
        _add(spool, 0)
        _add(spool, 1)
        assert feed.get() == 0
        with pytest.raises(ValueError, match="frame 1"):
            feed.get()


def test_a_cancel_is_checked_on_the_waiting_thread(tmp_path: Path) -> None:
    spool = _spool(tmp_path)
    seen: list[str] = []

    def cancel() -> None:
        seen.append(threading.current_thread().name)
        raise KeyboardInterrupt("cancelled")

    with LiveFeed(_follower(spool), lambda ref: ref.index, poll_s=0.01) as feed, \
            pytest.raises(KeyboardInterrupt, match="cancelled"):
        feed.get(cancel)
    assert seen == [threading.current_thread().name]


def test_a_live_run_that_keeps_up_is_the_offline_run(tmp_path: Path, bonn_dev: Path) -> None:
    """Thirty Bonn frames (people: segmentation, culling and its refills all work) spooled before the run with room
    for all of them: nothing is dropped, and the trajectory and keyframes are those of `run_pipeline` (read and
    prepared ahead) on the same frames, byte for byte."""
    from worker.slam.camera import parse_camera
    from worker.slam.io.sequence import Sequence
    from worker.slam.pipeline import run_pipeline
    from worker.slam.presets import get_preset

    n = 30
    spool = _spool(tmp_path)
    rgb, depth = read_list(bonn_dev / "rgb.txt"), read_list(bonn_dev / "depth.txt")
    pairs = associate([e.timestamp for e in rgb], [e.timestamp for e in depth])[:n]
    for k, (i, j) in enumerate(pairs):
        r, d = rgb[i], depth[j]
        shutil.copy(bonn_dev / r.path, spool.folder / r.path)
        shutil.copy(bonn_dev / d.path, spool.folder / d.path)
        spool.append(SpooledFrame(k, r.timestamp, time.time(), r.path, d.path))
    spool.end("client ended the stream", n)

    camera = parse_camera("bonn")
    live = run_live_slam(spool.folder, {"preset": "bonn"}, "no-restoration", {}, tmp_path / "live",
                         progress=lambda *a: None, should_cancel=lambda: False, live=LiveConfig(max_behind=n))
    assert live.metrics["live_frames_processed"] == n and live.metrics["live_frames_dropped"] == 0
    offline = run_pipeline(Sequence(spool.folder, camera), get_preset("no-restoration"), tmp_path / "offline")
    assert offline.metrics["frames"] == n
    for name in ("trajectory.txt", "keyframes.txt"):
        assert (tmp_path / "live" / name).read_bytes() == (tmp_path / "offline" / name).read_bytes(), name
