"""Work handed behind the pipeline thread completes in submission order, bounded, and fails loudly."""
from __future__ import annotations

import threading
import time

import pytest

from worker.slam.io.work_behind import THREAD_NAME, WorkBehind


def test_done_steps_run_in_order_on_the_calling_thread():
    done: list[tuple[int, str, str]] = []
    with WorkBehind(max_pending=2) as behind:
        for i in range(6):
            # later work finishes first: completion order must still follow submission
            def work(i: int = i) -> tuple[int, str]:
                time.sleep(0.02 * (6 - i))
                return i, threading.current_thread().name

            behind.submit(work, lambda r: done.append((r[0], r[1], threading.current_thread().name)))
            assert len(behind._pending) <= 2  # a third one waits for the oldest
        behind.finish()
    assert [d[0] for d in done] == list(range(6))
    assert all(d[1].startswith(THREAD_NAME) for d in done)
    assert {d[2] for d in done} == {threading.current_thread().name}


def test_disabled_runs_in_line():
    out: list[int] = []
    with WorkBehind(enabled=False) as behind:
        here = threading.current_thread().name
        behind.submit(lambda: threading.current_thread().name, lambda name: out.append(name == here))
        assert out == [True] and not behind.enabled


def test_a_failure_in_the_work_is_raised_on_the_pipeline_thread():
    def boom() -> None:
        raise ValueError("restoration failed")

    with pytest.raises(ValueError, match="restoration failed"), WorkBehind() as behind:
        behind.submit(boom, lambda _: None)
        behind.finish()
