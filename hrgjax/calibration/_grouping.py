"""Grouping: runs of many lengths so that few compiled programs serve them (lengths padded
to a ladder of powers of two, and sorted groups split where compiling another program
costs less than running the shorter runs on); and runs by temperature and wave angle for
the accuracy tables (`session`, `evaluate`), one binning for both."""

from __future__ import annotations

import math

import numpy as np


def nearest_multiples(values, width: float) -> np.ndarray:
    """Nearest multiples of `width` (a whole-looking float, `-0.0` made `0.0`): a run's
    temperature [°C] binned to 1 °C, so measured temperatures that jitter by a few hundredths
    of a degree are one group."""
    return np.round(np.asarray(values, dtype=float) / width) * width + 0.0


def wave_angle_groups(wave_angle_deg, width: float) -> np.ndarray:
    """Wave angles [° electrical] binned to multiples of `width` and folded to [−90°, 90°)
    (the pattern's period: θ and θ + 180° are one state, −90° and +90° one group), as
    `reduce.scale_factor_vs_angle` and the MLP's periodic encoding treat them."""
    return (nearest_multiples(wave_angle_deg, width) + 90.0) % 180.0 - 90.0 + 0.0


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
