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
"""Steps off the uniform step are stray stamps, left out of the step (`regular_step`), when
they are at most this fraction of a record's steps; more are the clock's own pattern, kept.
The shortest this fraction of the steps is left out of the body stalls are told from."""

STALL_GAP = 3.0
"""A longer step is a stall (`regular_step`) only beyond an empty band above the record's
typical step: a hole in its sorted steps wider than this many standard deviations of the
steps under the hole (and than 1.5 of the narrowest other hole: a tick level missing,
where the stamps count ticks)."""


def regular_step(t) -> float:
    """The record's sample step [s] from increasing time stamps `t` [s], from its regular
    steps (those strictly within half a median step of the median: a gap moves nothing, nor
    does a 1.5-step stall, as near two steps as one) about their median `c`:

    - longer steps beyond an empty band above `c` are stalls, left out: the first hole in
      the sorted steps above `c` wider than `STALL_GAP` (3) standard deviations of the steps
      under it and than 1.5 of the narrowest other hole (1.4-step stalls on a grid, or on a
      `millis()` clock of 14 or 15 ms at 20 or 21 ms; the mean of every regular step read
      1.8e-3 … 7.7e-3 fast with 0.5–2 % of them). Steps that fill the band are the clock's
      own: a `time.sleep(0.01)` or polling loop's overshoot, only ever longer (10 ms + 0.3 ms
      on average, stamped in µs, or in ms: 10, 11 or 12 ms, a ladder of ticks), jitter. One
      tick longer, evenly spread (`millis()` at 98 Hz: 10 or 11 ms, `_tick_band`), is the
      clock's own too; at random it is a stall (1.2-step stalls on a 10-ms grid);
    - steps off `c` by more than `UNIFORM_TOLERANCE` plus the stamps' rounding but not stalls
      are the clock's own pattern where they exceed `STALL_FRACTION` of the steps, and the
      step is the mean of every step but the stalls: a clock counted in crystal ticks (100 Hz
      from 32 768 Hz) steps 327 or 328 ticks, 32 % and 68 %, and only their mean is the rate
      (the 328-tick steps alone read 99.902 Hz); a sleep loop's 10.3 ms is its mean step;
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
        tick = float(np.min(off[~near]))  # the nearest other step: a tick, where stamps count them
        pattern = _tick_band(dt, centre, tick, tol) or tol
        stall = regular > _body_top(regular, centre, tol, pattern)
        if np.sum(~near & ~stall) > STALL_FRACTION * dt.size:  # the clock's own pattern
            return float(np.mean(regular[~stall]))
        return float(np.mean(regular[near]))


def _body_top(regular, centre: float, tol: float, pattern: float) -> float:
    """The longest step [s] under the first empty band (`STALL_GAP`) of the `regular` steps
    [s] more than `pattern` [s] above their median `centre` [s], inf where none is: holes
    narrower than `tol` [s] are none (the stamps' rounding)."""
    s = np.sort(regular)[int(STALL_FRACTION * regular.size) :]  # stray short steps left out
    x = s - centre
    count = np.arange(1, s.size + 1)
    var = np.cumsum(x * x) / count - (np.cumsum(x) / count) ** 2  # of the steps up to each
    at = np.flatnonzero(np.diff(s) > tol)
    hole = s[at + 1] - s[at]
    low = np.partition(np.r_[hole, np.inf, np.inf], 1)[:2]
    rung = np.where(hole == low[0], low[1], low[0])  # the narrowest other hole (a tick)
    rung = np.where(np.isfinite(rung), rung, 0.0)
    spread = np.sqrt(np.maximum(var[at], 0.0))
    wide = hole > np.maximum(STALL_GAP * np.maximum(spread, tol), 1.5 * rung)
    empty = wide & (s[at] >= centre - tol) & (s[at + 1] > centre + pattern)
    return float(s[at[np.argmax(empty)]]) if empty.any() else math.inf


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
