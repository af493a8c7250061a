"""Wall-clock time per named step of a run (stages, tracking, mapping...), for `metrics['timings_ms']`."""
from __future__ import annotations

import time
from collections import defaultdict

import numpy as np


class StageTimer:
    """Laps on one thread: `mark()` starts a lap, `lap(name)` records the time since the last mark or lap under
    `name` (one entry per call) and starts the next. `ms[name]` lists the entries, in milliseconds."""

    def __init__(self) -> None:
        self.ms: dict[str, list[float]] = defaultdict(list)
        self._t = time.perf_counter()

    def mark(self) -> None:
        self._t = time.perf_counter()

    def lap(self, name: str, extra_ms: float = 0.0) -> None:
        """Record the lap under `name`, plus `extra_ms` spent on it elsewhere (e.g. on another thread)."""
        t1 = time.perf_counter()
        self.ms[name].append((t1 - self._t) * 1000 + extra_ms)
        self._t = t1

    def means(self) -> dict[str, float]:
        """Mean ms per name, in the order the names were first recorded."""
        return {k: round(float(np.mean(v)), 3) for k, v in self.ms.items()}
