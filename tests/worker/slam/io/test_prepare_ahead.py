"""Prepare-ahead: work queued per frame runs on one background thread, in order, timed; errors reach the
consumer at their frame; the thread stops when the consumer leaves."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from worker.slam.io.prepare_ahead import THREAD_NAME, PrepareAhead
from worker.slam.io.read_ahead import ReadAhead
from worker.slam.io.sequence import Frame


def _frame(i: int) -> Frame:
    return Frame(i, float(i), np.full((2, 2, 3), i, np.uint8), np.full((2, 2), i, np.float32))


def _alive() -> bool:
    return any(t.name.startswith(THREAD_NAME) for t in threading.enumerate())


def test_results_come_with_their_frame_computed_on_one_other_thread() -> None:
    threads: set[str] = set()

    def mean_red(f: Frame) -> float:
        threads.add(threading.current_thread().name)
        return float(f.rgb[..., 0].mean())

    with PrepareAhead({"seg": mean_red}) as prep, ReadAhead(lambda i: prep.submit(_frame(i)), range(8), 2) as ahead:
        got = [(p.frame.index, *p.pending["seg"].result()) for p in ahead]
        assert prep.names == ["seg"]
    assert [(i, v) for i, v, _ in got] == [(i, float(i)) for i in range(8)]
    assert all(ms >= 0 for _, _, ms in got)
    assert len(threads) == 1 and next(iter(threads)).startswith(THREAD_NAME)
    assert not _alive()


def test_nothing_to_prepare_starts_no_thread() -> None:
    with PrepareAhead({}) as prep:
        p = prep.submit(_frame(3))
        assert p.frame.index == 3 and not p.pending and not _alive()


def test_an_error_is_raised_when_its_result_is_asked_for() -> None:
    def fail_on_2(f: Frame) -> int:
        if f.index == 2:
            raise ValueError("bad frame")
        return f.index

    with PrepareAhead({"x": fail_on_2}) as prep:
        pending = [prep.submit(_frame(i)) for i in range(4)]
        assert pending[1].pending["x"].result()[0] == 1
        with pytest.raises(ValueError, match="bad frame"):
            pending[2].pending["x"].result()
        assert pending[3].pending["x"].result()[0] == 3


def test_leaving_early_cancels_what_has_not_started() -> None:
    started = threading.Event()
    release = threading.Event()
    ran: list[int] = []

    def slow(f: Frame) -> int:
        started.set()
        release.wait(timeout=30)
        ran.append(f.index)
        return f.index

    with PrepareAhead({"slow": slow}) as prep:
        for i in range(5):
            prep.submit(_frame(i))
        assert started.wait(timeout=30)
        threading.Timer(0.2, release.set).start()  # frame 0 finishes while leaving waits for it
    assert ran == [0] and not _alive()
