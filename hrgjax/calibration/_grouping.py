"""Grouping runs of many lengths so that few compiled programs serve them: lengths padded
to a ladder of powers of two, and sorted groups split where compiling another program
costs less than running the shorter runs on."""

from __future__ import annotations

import math


def ladder(n: int) -> int:
    """Smallest power of two ≥ n."""
    return 1 << max(int(n) - 1, 0).bit_length()


def partition(count: int, cost) -> list[tuple[int, int]]:
    """The cheapest split of `count` items (in their order) into contiguous runs `[i, j)`,
    by dynamic programming on `cost(i, j)` (`math.inf`: not allowed; a single item's cost
    must be finite). Groups of sorted run lengths: each run of them shares one compiled
    program."""
    best, cut = [0.0] + [math.inf] * count, [0] * (count + 1)
    for j in range(1, count + 1):
        for i in range(j):
            c = best[i] + cost(i, j)
            if c < best[j]:
                best[j], cut[j] = c, i
    out, j = [], count
    while j > 0:
        out.append((cut[j], j))
        j = cut[j]
    return out[::-1]
