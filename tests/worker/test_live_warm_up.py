"""Before a live session is ready, every stage's `prepare` runs on a synthetic frame of the camera's size (the
first calls load compiled kernels and let TorchScript optimise), `warm_up_runs` times; stages without one are
left alone. That the run's results do not change is `test_live_feed.py`'s byte-for-byte test."""
from __future__ import annotations

from types import SimpleNamespace

from worker.live import LiveConfig, warm_up
from worker.slam.io.sequence import Frame


class Preparing:
    def __init__(self) -> None:
        self.seen: list[Frame] = []

    def prepare(self, frame: Frame) -> None:
        self.seen.append(frame)


def test_every_prepare_runs_on_a_frame_of_the_camera_size() -> None:
    a, b, plain = Preparing(), Preparing(), SimpleNamespace(name="tracking-only")
    warm_up([a, plain, b], SimpleNamespace(width=64, height=48), LiveConfig().warm_up_runs)
    assert len(a.seen) == len(b.seen) == 2
    f = a.seen[0]
    assert f.rgb.shape == (48, 64, 3) and f.depth.shape == (48, 64) and f.rgb.std() > 0 and (f.depth > 0).all()


def test_no_warm_up_when_it_is_off() -> None:
    a = Preparing()
    warm_up([a], SimpleNamespace(width=64, height=48), 0)
    assert a.seen == []
