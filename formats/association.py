"""Pairing two timestamp lists like TUM's associate.py, in O(N log N).

TUM's script takes every candidate pair with |a - b| < max_diff, sorts them by difference and keeps a pair when
neither side is used yet. Here ties are broken by (i, j), the lists' indices. The same matching is built
without listing the candidates (3000 equal timestamps would be 9 million pairs):

1. Equal values pair first (difference 0): within one value, the k-th smallest index of ``a`` with the k-th
   smallest of ``b``, as the greedy order (0, i, j) does.
2. Each value then holds indices of one list only. Of the values still holding indices, a closest pair is
   always between neighbours in value order (anything between them is nearer to one of the two), so a heap
   holds only neighbouring values of different lists, keyed (difference, smallest index of each). Taking a
   pair empties a value at times, which makes its two neighbours adjacent: one new heap entry. A stale key
   (its smallest index was taken since) is pushed back with the current one; keys only grow, so the heap
   still yields the greedy order.

Exact when the differences of timestamps closer than ``max_diff`` are exact in float64 (any two of the same
sign within a factor 2, e.g. every UNIX time or any time above ``max_diff``); otherwise ties that rounding
creates between non-neighbouring values may be broken differently.
"""

from __future__ import annotations

import heapq
from collections import deque
from collections.abc import Sequence

import numpy as np

MAX_DIFF_S = 0.02
"""TUM associate.py's default: colour and depth closer than this are one frame."""


def associate(
    a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray, max_diff: float = MAX_DIFF_S, offset: float = 0.0
) -> list[tuple[int, int]]:
    """Pairs (i, j) with |a[i] - (b[j] + offset)| < max_diff, each index used once, closest pairs first
    (ties by i, then j); sorted by i."""
    av = [float(x) for x in np.asarray(a, dtype=np.float64)]
    bv = [float(x) for x in np.asarray(b, dtype=np.float64) + offset]
    groups: dict[float, tuple[list[int], list[int]]] = {}
    for i, t in enumerate(av):
        groups.setdefault(t, ([], []))[0].append(i)
    for j, t in enumerate(bv):
        groups.setdefault(t, ([], []))[1].append(j)

    pairs: list[tuple[int, int]] = []
    values: list[float] = []  # values left holding indices of one list, ascending
    side: list[int] = []  # 0: the value holds indices of a, 1: of b
    left: list[deque[int]] = []  # the value's indices not yet paired, ascending
    for t in sorted(groups):
        ia, ib = groups[t]
        n = min(len(ia), len(ib))
        pairs.extend(zip(ia[:n], ib[:n]))
        rest = ia[n:] or ib[n:]
        if rest:
            values.append(t)
            side.append(0 if ia[n:] else 1)
            left.append(deque(rest))

    count = len(values)
    prev = list(range(-1, count - 1))
    nxt = list(range(1, count + 1))  # count: no neighbour
    heap: list[tuple[float, int, int, int, int]] = []  # (difference, i, j, value of i, value of j)

    def push(u: int, v: int) -> None:
        """Offer the neighbouring values u < v when they hold different lists and are close enough."""
        if u < 0 or v >= count or side[u] == side[v] or not left[u] or not left[v]:
            return
        d = abs(values[u] - values[v])
        if d < max_diff:
            ua, vb = (u, v) if side[u] == 0 else (v, u)
            heapq.heappush(heap, (d, left[ua][0], left[vb][0], ua, vb))

    for u in range(count - 1):
        push(u, u + 1)
    while heap:
        _d, i, j, ua, vb = heapq.heappop(heap)
        if not left[ua] or not left[vb]:
            continue  # a value emptied since; its neighbours were offered then
        if left[ua][0] != i or left[vb][0] != j:
            push(min(ua, vb), max(ua, vb))  # stale smallest index: back with the current key
            continue
        pairs.append((left[ua].popleft(), left[vb].popleft()))
        push(min(ua, vb), max(ua, vb))  # both may hold more indices; other entries of theirs are stale now
        for u in (ua, vb):
            if not left[u]:  # unlink the emptied value; its neighbours become adjacent
                p, n = prev[u], nxt[u]
                if p >= 0:
                    nxt[p] = n
                if n < count:
                    prev[n] = p
                push(p, n)
    pairs.sort()
    return pairs
