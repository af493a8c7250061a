"""The run's history of past frames: bounded, poses set once, and views that never change afterwards."""
from __future__ import annotations

import numpy as np

from worker.slam.history import FrameHistory, HistoryView, PastFrame


def _frame(i: int) -> PastFrame:
    return PastFrame(i, i / 30, np.zeros((4, 5, 3), np.uint8), np.ones((4, 5), np.float32))


def pose(x: float) -> np.ndarray:
    T = np.eye(4)
    T[0, 3] = x
    return T


def test_holds_the_last_length_frames_oldest_first():
    h = FrameHistory(3)
    for i in range(5):
        h.append(_frame(i))
    view = h.view()
    assert len(h) == len(view) == 3 and [f.index for f in view.frames] == [2, 3, 4]
    assert [f.index for f in view.recent(2)] == [3, 4] and [f.index for f in view.recent(10)] == [2, 3, 4]
    assert view.recent(0) == ()
    assert view.get(3) is view.frames[1] and view.get(1) is None
    assert [f.index for f in view.between(3, 9)] == [3, 4]
    assert len(FrameHistory(0).view()) == 0 and HistoryView().recent(3) == ()


def test_a_pose_is_set_once_copied_and_never_changes_an_earlier_view():
    h = FrameHistory(4)
    h.append(_frame(0))
    h.append(_frame(1))
    before = h.view()
    T = pose(0.5)
    h.set_pose(1, T)
    T[0, 3] = 9.0  # the tracker's array is not the record's
    after = h.view()
    assert before.get(1).T_WC is None  # a view is a snapshot: a deferred reader sees what it saw
    assert after.get(1).T_WC[0, 3] == 0.5 and after.get(0).T_WC is None
    h.set_pose(1, pose(2.0))  # a frame's pose is the one it got when tracked
    h.set_pose(7, pose(3.0))  # not held: ignored
    assert h.view().get(1).T_WC[0, 3] == 0.5


def test_moving_pixels_default_to_none():
    f = _frame(0)
    assert f.moving().shape == (4, 5) and not f.moving().any()
    m = np.zeros((4, 5), bool)
    m[1, 2] = True
    assert PastFrame(0, 0.0, f.rgb, f.depth, dynamic=m).moving() is m
