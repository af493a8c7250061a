"""TUM RGB-D list files (`timestamp path` per line) and timestamp association (as TUM's associate.py)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from worker.slam.errors import SequenceFormatError


def read_file_list(path: Path) -> list[tuple[float, str]]:
    """Read `rgb.txt` / `depth.txt`: `timestamp relative/path` per line, `#` comments skipped, time-sorted."""
    if not path.is_file():
        raise SequenceFormatError("required list file is missing", path=path)
    entries: list[tuple[float, str]] = []
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise SequenceFormatError(f"not UTF-8 text ({exc.reason})", path=path) from None
    for lineno, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        if len(parts) < 2:
            raise SequenceFormatError(f"expected 'timestamp filename', got {s!r}", path=path, line=lineno)
        try:
            t = float(parts[0])
        except ValueError:
            raise SequenceFormatError(f"timestamp {parts[0]!r} is not a number", path=path, line=lineno) from None
        if not np.isfinite(t):
            raise SequenceFormatError("timestamp is not finite", path=path, line=lineno)
        rel = parts[1]
        if Path(rel).is_absolute() or ".." in Path(rel).parts:
            raise SequenceFormatError(f"path {rel!r} must be relative and stay inside the sequence",
                                      path=path, line=lineno)
        entries.append((t, rel))
    if not entries:
        raise SequenceFormatError("lists no frames", path=path)
    entries.sort(key=lambda e: e[0])
    return entries


def associate(a: np.ndarray, b: np.ndarray, max_diff: float = 0.02, offset: float = 0.0) -> list[tuple[int, int]]:
    """Pairs (i, j) with |a[i] - (b[j] + offset)| < max_diff, each index used once, closest pairs first.

    Same result as TUM's associate.py (greedy over all candidate pairs sorted by time difference), but only
    candidates inside the window are generated, so it is O(n log n) for sorted inputs.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64) + offset
    order_b = np.argsort(b, kind="stable")
    bs = b[order_b]
    lo = np.searchsorted(bs, a - max_diff, side="left")
    hi = np.searchsorted(bs, a + max_diff, side="right")
    cand: list[tuple[float, int, int]] = []
    for i in range(len(a)):
        for k in range(lo[i], hi[i]):
            d = abs(a[i] - bs[k])
            if d < max_diff:
                cand.append((d, i, int(order_b[k])))
    cand.sort()
    used_a: set[int] = set()
    used_b: set[int] = set()
    pairs = []
    for _, i, j in cand:
        if i not in used_a and j not in used_b:
            used_a.add(i)
            used_b.add(j)
            pairs.append((i, j))
    pairs.sort()
    return pairs
