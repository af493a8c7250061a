"""Segmentation tests run torch on one thread: tiny tensors gain nothing from more, and on a busy shared CPU
multi-threaded kernels wait for each other (tests got 30x slower)."""
from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def one_torch_thread():
    torch = pytest.importorskip("torch")
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
