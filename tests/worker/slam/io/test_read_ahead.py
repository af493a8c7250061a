"""Read-ahead: frames in order and unchanged, errors at their frame, the reader stops with its consumer."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from tests.worker.slam.io.helpers import write_sequence as write_tiny_sequence
from tests.worker.slam.synthetic_room import trajectory, write_sequence
from worker.slam.camera import Camera
from worker.slam.errors import SequenceFormatError
from worker.slam.io.read_ahead import ReadAhead
from worker.slam.io.sequence import Frame, Sequence
from worker.slam.pipeline import PipelineCancelled, run_pipeline
from worker.slam.presets import get_preset

THREAD_NAME = "vtdslam-read-ahead"
CAM = Camera(50.0, 50.0, 32.0, 24.0, 5000.0, 64, 48)


def _frame(i: int) -> Frame:
    return Frame(i, float(i), np.full((2, 2, 3), i, np.uint8), np.full((2, 2), i, np.float32))


def _reader_alive() -> bool:
    return any(t.name == THREAD_NAME for t in threading.enumerate())


@pytest.mark.parametrize("depth", [0, 1, 3])
def test_frames_come_out_in_order_and_unchanged(tmp_path, depth):
    seq = Sequence(write_tiny_sequence(tmp_path, n=7), CAM)
    with ReadAhead(seq.__getitem__, range(2, 7), depth) as ahead:
        got = list(ahead)
    assert [f.index for f in got] == [2, 3, 4, 5, 6]
    for f in got:
        ref = seq[f.index]
        assert f.timestamp == ref.timestamp
        assert np.array_equal(f.rgb, ref.rgb) and np.array_equal(f.depth, ref.depth)
    assert not _reader_alive()


@pytest.mark.parametrize("depth", [0, 2])
def test_an_error_is_raised_at_its_frame(depth):
    def read(i: int) -> Frame:
        if i == 3:
            raise SequenceFormatError("not a decodable image")
        return _frame(i)

    got = []
    with pytest.raises(SequenceFormatError, match="decodable"), ReadAhead(read, range(6), depth) as ahead:
        for f in ahead:
            got.append(f.index)
    assert got == [0, 1, 2]
    assert not _reader_alive()


def test_reader_decodes_ahead_while_the_consumer_works_and_stays_bounded():
    reads: list[int] = []
    ahead_done = threading.Event()

    def read(i: int) -> Frame:
        reads.append(i)
        if len(reads) == 3:  # frame 0 taken, frames 1 and 2 decoded while the consumer holds frame 0
            ahead_done.set()
        return _frame(i)

    with ReadAhead(read, range(100), depth=2) as ahead:
        it = iter(ahead)
        assert next(it).index == 0
        assert ahead_done.wait(timeout=30), "the reader did not decode ahead of the consumer"
        # the queue holds at most 2 frames and the reader at most one more in hand
        assert len(reads) <= 4
    # leaving early stops the reader; it never ran through the sequence
    assert not _reader_alive() and len(reads) <= 4


def test_iterating_a_threaded_reader_outside_its_context_is_refused():
    with pytest.raises(RuntimeError, match="entered"):
        list(ReadAhead(_frame, range(3), depth=2))
    with pytest.raises(ValueError):
        ReadAhead(_frame, range(3), depth=-1)


@pytest.fixture(scope="module")
def room_seq(tmp_path_factory):
    return write_sequence(tmp_path_factory.mktemp("room"), trajectory(30, yaw_span_deg=20))


def test_pipeline_trajectory_is_identical_with_and_without_read_ahead(room_seq, tmp_path):
    cfg = get_preset("orb-only", {"dense.enabled": False})
    for depth in (0, 3):
        run_pipeline(Sequence(room_seq), cfg, tmp_path / str(depth), read_ahead=depth)
    sync = (tmp_path / "0" / "trajectory.txt").read_bytes()
    assert sync.count(b"\n") >= 30
    assert (tmp_path / "3" / "trajectory.txt").read_bytes() == sync


def test_cancelling_the_pipeline_stops_the_reader(room_seq):
    seen: list[int] = []
    with pytest.raises(PipelineCancelled):
        run_pipeline(Sequence(room_seq), get_preset("orb-only", {"dense.enabled": False}), read_ahead=2,
                     progress=lambda d, t, s: seen.append(d), should_cancel=lambda: len(seen) >= 3)
    assert not _reader_alive()
