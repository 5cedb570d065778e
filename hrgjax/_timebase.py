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
"""Steps a fraction of a step off the uniform step (stalls, stray stamps) are left out of
the step (`regular_step`) when they are at most this fraction of a record's steps; more,
nearer than `STALL_OFF`, are the clock's own pattern and kept."""

STALL_OFF = 0.05
"""A step more than this fraction of a step longer than the record's typical step is a
stall, not the clock's own pattern (`regular_step`), unless as many are as far shorter
(jitter) or the stamps count ticks of more than this (`millis()` at 70 Hz: 14 or 15 ms)."""


def regular_step(t) -> float:
    """The record's sample step [s] from increasing time stamps `t` [s], from its regular
    steps (those strictly within half a median step of the median: a gap moves nothing, nor
    does a 1.5-step stall, as near two steps as one) about their median `c`:

    - a step more than `STALL_OFF` (5 %) of `c` longer is a stall, always left out (the mean
      of every regular step read 1.8e-3 … 7.7e-3 fast with 0.5–2 % of 1.4-step stalls and the
      record was interpolated) — unless more than `STALL_FRACTION` of the steps are as far
      shorter (a stall is never shorter): jitter (stamps ±30 %, a logger loop's ±1 ms),
      where a stall is a step longer by 5 % more than the shortest is short; or the stamps
      count ticks of over 5 % of a step and the longer steps are one tick long (`millis()`
      at 70 Hz: 14 or 15 ms, a one-tick pattern, `_tick_band`);
    - steps off `c` by more than `UNIFORM_TOLERANCE` plus the stamps' rounding but within
      that are the clock's own pattern where they exceed `STALL_FRACTION` of the steps, and
      the step is the mean of every step but the stalls: a clock counted in crystal ticks
      (100 Hz from 32 768 Hz) steps 327 or 328 ticks, 32 % and 68 %, and only their mean is
      the rate (the 328-tick steps alone read 99.902 Hz); jittered stamps likewise;
    - else the step is the mean of the steps within `UNIFORM_TOLERANCE` of `c` (the mean of
      the few others moved the step: one 1.4-step interval moved it 1e-5 of the rate at
      40 000 samples, and no stamp after it lay on its grid). A tick clock whose rarer count
      is under 1 % of the steps reads the common count's step (within 1 % of a tick).

    A record of two step sizes in equal numbers (1 ms / 3 ms alternating) has no single step:
    the median picks one by parity."""
    with np.errstate(
        over="ignore", invalid="ignore"
    ):  # steps beyond 1.8e308 s: inf, the caller refuses
        t = np.asarray(t, dtype=float)
        dt = np.diff(t)
        median = float(np.median(dt))
        regular = dt[np.abs(dt - median) < 0.5 * median]
        if not regular.size:
            return median
        centre = float(np.median(regular))
        rounding = 2.0 * float(np.spacing(np.max(np.abs(t))))
        tol = UNIFORM_TOLERANCE * centre + rounding
        off = np.abs(regular - centre)
        near = off <= tol
        if near.all():
            return float(np.mean(regular))
        band = STALL_OFF * centre
        short = off[regular < centre - band]  # far shorter steps: never stalls
        tick = float(np.min(off[~near]))  # the nearest other step: a tick, where stamps count them
        if short.size > STALL_FRACTION * dt.size:  # jitter: a stall is only beyond its reach
            band = float(np.max(short)) + band
        elif tick > band:  # coarse ticks (their own pattern, not stalls), or stalls alone?
            band = _tick_band(dt, centre, tick, tol) or band
        stall = off > band
        if np.sum(~near & ~stall) > STALL_FRACTION * dt.size:  # the clock's own pattern
            return float(np.mean(regular[~stall]))
        return float(np.mean(regular[near]))


def _tick_band(dt, centre: float, tick: float, tol: float) -> float | None:
    """How far [s] from the typical step `centre` [s] longer steps `dt` [s] are a tick
    clock's own pattern, or None where they are not one: every regular step a whole number
    of `tick` [s] (within `tol` [s]), at least 2 ticks a step, and the one-tick steps evenly
    spread (the grid rounded to ticks: the gaps between them, within runs of such steps,
    differ by at most one step) — stalls of one size at random are not; nor are stalls of
    1.4 steps on a 0.01-s grid (no tick)."""
    off = np.abs(dt - centre)
    regular = off < 0.5 * centre
    ticks = dt[regular] / tick
    if tick > 0.5 * centre or np.max(np.abs(ticks - np.round(ticks))) * tick > tol:
        return None
    one = (off > tol) & (off <= tick + tol)
    where = np.flatnonzero(one)
    outside = np.concatenate([[0], np.cumsum(off > tick + tol)])
    span = outside[where[1:]] - outside[where[:-1]] == 0  # no stall or gap between the two
    gaps = np.diff(where)[span]
    return tick + tol if gaps.size >= 2 and int(np.ptp(gaps)) <= 1 else None


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
