"""A temperature logged slower than the gyro and forward-filled onto the gyro's rows (a
step-like `temperature_c`: runs of identical values broken by jumps), told apart from a
sampled ramp and reconstructed before the continuous records read it.

The continuous model reads the temperature between samples as a straight line, so a held
column's Ṫ is zero for a whole hold and a spike at each jump: `thermal_rate` (c·Ṫ) is then
seen as an impulse per jump and other thermal effects stand in for it (measured: a 60-s hold
on `continuous_dataset("thermal_rate", 0.05)` returned `thermal_lag`, `bias_temperature`
and `frequency_split`). A held value is a reading of a slow signal taken when it first
appears (the forward-fill convention): the honest reconstruction is the straight line
through the readings — knots at the jump times with the new values, plus, in a hold longer
than the logger's interval, the last (unchanged) reading one interval before the next jump.
"""

from __future__ import annotations

import warnings

import numpy as np

from .._warn import user_stacklevel
from ..data import MeasuredData
from ..pattern_noise import TEMPERATURE_TOLERANCE_C

HELD_MIN_JUMPS = 3
"""A run's temperature is held when it changes at least this many times …"""
HELD_MIN_SAMPLES = 3
"""… and the median number of rows between its changes is at least this (at least 2/3 of
the differences over the moving part exactly zero): a ramp sampled at every row changes at
every row, a sensor's noise makes every difference nonzero; a forward-filled log, a
quantised slow ramp hold their value for rows on end."""


class HeldTemperatureWarning(UserWarning):
    """`discover` read a step-like (held, forward-filled) temperature and interpolated it
    through its readings
    ([`unhold_temperature`][hrgjax.discovery.thermometer.unhold_temperature])."""


def hold_interval(t_s, temperature_c) -> float | None:
    """The hold interval [s] of one run's temperature when it is step-like — at least
    [`HELD_MIN_JUMPS`][hrgjax.discovery.thermometer.HELD_MIN_JUMPS] changes, a median of
    [`HELD_MIN_SAMPLES`][hrgjax.discovery.thermometer.HELD_MIN_SAMPLES] or more rows
    between them, and a move over the run beyond both
    [`TEMPERATURE_TOLERANCE_C`][hrgjax.pattern_noise.TEMPERATURE_TOLERANCE_C] and 2.5
    typical changes (a quantised dwell flickering over three levels is no ramp): the median
    time between changes. None otherwise (a dwell, a sampled ramp, one real step).
    `t_s` [s] and `temperature_c` [°C]: one run's rows."""
    t, temp = np.asarray(t_s, float), np.asarray(temperature_c, float)
    if temp.size < 3 or np.ptp(temp) <= TEMPERATURE_TOLERANCE_C:
        return None
    d = np.diff(temp)
    jumps = np.flatnonzero(d != 0) + 1  # the rows where a new value first appears
    if jumps.size < HELD_MIN_JUMPS or np.median(np.diff(jumps)) < HELD_MIN_SAMPLES:
        return None
    if np.ptp(temp) < 2.5 * np.median(np.abs(d[jumps - 1])):
        return None
    return float(np.median(np.diff(t[jumps])))


def unheld(t_s, temperature_c, hold_s: float) -> np.ndarray:
    """One run's held temperature [°C] interpolated through its readings: knots at the run's
    start and at each row where the value changes (the new value), and, where a hold lasts
    longer than 1.5 `hold_s` [s], the last unchanged reading `hold_s` before the change
    (the temperature stood still there); constant after the last knot."""
    t, temp = np.asarray(t_s, float), np.asarray(temperature_c, float)
    start = np.r_[0, np.flatnonzero(np.diff(temp) != 0) + 1]  # each held value's first row
    kt, kv = [], []
    for i, a in enumerate(start):
        kt.append(t[a])
        kv.append(temp[a])
        if i + 1 < start.size and t[start[i + 1]] - hold_s > t[a] + 0.5 * hold_s:
            kt.append(t[start[i + 1]] - hold_s)
            kv.append(temp[a])
    return np.interp(t, np.asarray(kt), np.asarray(kv))


def unhold_temperature(data: MeasuredData) -> MeasuredData:
    """`data` with each step-like run's `temperature_c`
    ([`hold_interval`][hrgjax.discovery.thermometer.hold_interval]) interpolated through its
    readings ([`unheld`][hrgjax.discovery.thermometer.unheld]), with one
    [`HeldTemperatureWarning`][hrgjax.discovery.thermometer.HeldTemperatureWarning] naming the
    runs and their hold interval; `data` itself when no run is step-like (dwell runs never
    are)."""
    t, temp = data["time_s"], data["temperature_c"]
    new, held = np.array(temp, dtype=float), {}
    for idx in data.run_indices():
        hold = hold_interval(t[idx], temp[idx])
        if hold is not None:
            held[int(data.run[idx[0]])] = hold
            new[idx] = unheld(t[idx], temp[idx], hold)
    if not held:
        return data
    holds = np.asarray(list(held.values()))
    span = f"{holds.min():.3g} s" if np.ptp(holds) < 1e-9 * holds.max() else (
        f"{holds.min():.3g}–{holds.max():.3g} s")  # fmt: skip
    runs = ", ".join(str(r) for r in list(held)[:8]) + (" …" if len(held) > 8 else "")
    warnings.warn(
        f"discover: temperature_c is step-like in {len(held)} run(s) ({runs}): held for "
        f"{span} between changes (a slower thermometer forward-filled); interpolated through "
        "its readings (the rows where it changes) — log the thermometer's own sample times "
        "to avoid this",
        HeldTemperatureWarning,
        stacklevel=user_stacklevel(),
    )
    return data.with_column("temperature_c", new)  # within its readings: no range re-check
