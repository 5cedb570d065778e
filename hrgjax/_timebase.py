"""The sample step of a record's time stamps, robust to the stamps' own rounding.

A float64 time stamp near an epoch (t ≈ 1.7e9 s) moves in steps of 2.4e-7 s, so a 1e-4-s
step is stored as 9.990e-5 or 1.0014e-4 s: the median step is one of the two (a 10-kHz
record read 10 010 Hz) and every step lies 0.1 % from it (a uniform record taken for a
jittered one from 5 kHz up). The step here is the mean over the record's regular steps,
and a record is uniform when every stamp lies on the grid t₀ + k·step within 1e-3 of a step
plus the stamps' own rounding.
"""

from __future__ import annotations

import math

import numpy as np

UNIFORM_TOLERANCE = 1e-3
"""A record is uniform when every stamp lies within this fraction of a step of the grid
t₀ + k·step (plus the stamps' own float64 rounding)."""


STALL_FRACTION = 0.01
"""At most this fraction of a record's steps may lie off its uniform step for them to be
taken for stalls or stray stamps (`regular_step`); more are the clock's own pattern."""


def regular_step(t) -> float:
    """The record's sample step [s] from increasing time stamps `t` [s]: the mean of the
    steps strictly within half a median step of the median (the median alone is quantised by
    the stamps' rounding; a gap does not move this mean, nor does a 1.5-step stall: half a
    step off is as near two steps as one). Where all but a few of those (at most
    `STALL_FRACTION` of the steps: stalls, stray stamps) lie within `UNIFORM_TOLERANCE` of that
    mean plus the stamps' rounding, the mean of those alone: one 1.4-step interval moved the
    wider mean by 0.4 steps over the record (1e-5 of the rate at 40 000 samples), so the
    stamps after it lay on no grid of that step. More steps off it are the clock's own
    pattern, kept: a sample clock counted in crystal ticks (100 Hz from 32 768 Hz) steps 327
    or 328 ticks, 32 % and 68 % of the steps, and only their mean is the rate (the 328-tick
    steps alone read 99.902 Hz); a tick clock whose rarer count is under 1 % of the steps
    reads the common count's step (within 1 % of a tick). A record of two step sizes in equal
    numbers (1 ms / 3 ms alternating) has no single step: the median picks one by parity."""
    with np.errstate(
        over="ignore", invalid="ignore"
    ):  # steps beyond 1.8e308 s: inf, the caller refuses
        t = np.asarray(t, dtype=float)
        dt = np.diff(t)
        median = float(np.median(dt))
        regular = dt[np.abs(dt - median) < 0.5 * median]
        if not regular.size:
            return median
        step = float(np.mean(regular))
        rounding = 2.0 * float(np.spacing(np.max(np.abs(t))))
        close = regular[np.abs(regular - step) <= UNIFORM_TOLERANCE * step + rounding]
        few = regular.size - close.size <= STALL_FRACTION * dt.size
        return float(np.mean(close)) if close.size and few else step


def is_uniform(t, step: float) -> bool:
    """Whether every stamp of `t` [s] lies on the grid t₀ + k·`step` within
    `UNIFORM_TOLERANCE` of a step plus twice the stamps' float64 spacing."""
    t = np.asarray(t, dtype=float)
    k = np.arange(t.size)
    grid = t[0] + k * step
    rounding = 2.0 * float(np.spacing(np.max(np.abs(t))))
    return bool(np.max(np.abs(t - grid)) <= UNIFORM_TOLERANCE * step + rounding)


def stamp_resolution(t) -> float:
    """The relative precision a rate read from stamps `t` [s] can have: the rounding of two
    stamps over the record's span (1e-12 for a span of 0)."""
    t = np.asarray(t, dtype=float)
    span = float(t[-1] - t[0])
    return 2.0 * float(np.spacing(np.max(np.abs(t)))) / span if span > 0 else 1e-12


def rate_from_stamps(t, step: float) -> float:
    """1/`step` [Hz] rounded to the digits the stamps resolve (`stamp_resolution`): 10 000 Hz,
    not 9 999.99996, from stamps at an epoch."""
    rel = stamp_resolution(t)
    digits = int(min(max(math.floor(-math.log10(max(rel, 1e-15))) - 1, 6), 12))
    return float(f"{1.0 / step:.{digits}g}")
