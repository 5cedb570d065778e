"""The unit of a log's time column: seconds unless told, and told apart from a column whose
name or size says otherwise.

Loggers stamp in seconds, milliseconds, microseconds or nanoseconds; stamps in ms read as
seconds make a 100-Hz log a 0.1-Hz one (an Allan deviation √1000 too large, a Ferraris turn
integrating to 360 000°). A column named in a unit (`t_ms`, `Time (mS)`, `stamp_nsec`) must
be declared in that unit, and stamps that read as seconds would lie 3 000 years and more
from zero (an epoch in ms, µs or ns) are refused; the refusal names the way out, which each
caller words (`--time-unit ms` on the command line, `units={"time": "ms"}` in
`hrgjax.imu.load`).
"""

from __future__ import annotations

import re
import unicodedata
from collections.abc import Callable

import numpy as np

TIME_UNITS = {"s": 1.0, "ms": 1e3, "us": 1e6, "ns": 1e9}
"""Time-column units with how many make a second [1/s]."""

EPOCH_SECONDS = 1e11
"""Stamps that reach this many seconds (3 170 years) are not seconds."""

_NAMED = re.compile(
    r"(?:^|[^a-z0-9])(s|secs?|seconds?|ms|msecs?|millis|milliseconds?|us|usecs?|micros|"
    r"microseconds?|ns|nsecs?|nanos|nanoseconds?)[^a-z0-9]*$"
)
_SPELLINGS = {"s": "s", "mi": "ms", "ms": "ms", "micro": "us", "u": "us", "n": "ns"}
"""A spelling's unit by its beginning (the longest that matches)."""


def named_time_unit(name: str) -> str | None:
    """The unit a time column's name ends in, a key of `TIME_UNITS` (`t_ms`, `time [us]`,
    `t_μs` or `t_µs`, `stamp_nsec`, `elapsed_secs`, `Seconds`, `t_milliseconds`, `TimeMs`,
    `timeUs`; Unicode-normalised, any case: `Time (mS)` is ms), or None (`time`,
    `timestamp`). The casefolded name is matched first; a camelCase split (`TimeMs` ->
    `time_ms`) only where that finds no unit (it read `Time (mS)` as `m_s`, seconds)."""
    text = unicodedata.normalize("NFKC", str(name)).replace("\u03bc", "u").replace("\u039c", "U")
    found = _NAMED.search(text.casefold())
    if found is None:  # camelCase: TimeMs -> time_ms
        found = _NAMED.search(re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", text).casefold())
    if found is None:
        return None
    word = found[1]
    unit = _SPELLINGS[max((k for k in _SPELLINGS if word.startswith(k)), key=len)]
    assert unit in TIME_UNITS, unit
    return unit


def stamps_per_second(name: str, t, unit: str | None, way_out: Callable[[str], str]) -> float:
    """How many units of time column `name`'s stamps `t` make a second [1/s]: of `unit` (a
    key of `TIME_UNITS`), or seconds (1) when None.

    **Raises:** `ValueError` (one line; `way_out(unit)` words how to declare a unit) for a
    name ending in another unit than `unit` — or than seconds, when `unit` is None — and,
    with no unit given or named, for stamps that would reach 3 000 years as seconds (an
    epoch in ms, µs or ns: `EPOCH_SECONDS`)."""
    if unit is not None and unit not in TIME_UNITS:
        raise ValueError(f"time unit: {unit!r} is not one of {list(TIME_UNITS)}")
    named = named_time_unit(name)
    if unit is not None:
        if named is not None and named != unit:
            raise ValueError(f"{way_out(unit)} contradicts the time column {name!r}, named in "
                             f"{named}")  # fmt: skip
        return TIME_UNITS[unit]
    if named is not None and named != "s":
        raise ValueError(f"the time column {name!r} is named in {named}: give "
                         f"{way_out(named)} (stamps are read as seconds by default)")  # fmt: skip
    if named == "s":
        return 1.0
    t = np.asarray(t, dtype=float)
    largest = float(np.max(np.abs(t))) if t.size else 0.0
    if largest >= EPOCH_SECONDS:
        guess = "ms" if largest < 1e14 else "us" if largest < 1e17 else "ns"
        raise ValueError(f"time column {name!r} reaches {largest:.4g}, as seconds "
                         f"{largest / 3.15576e7:.3g} years: stamps in {guess}? give "
                         f"{way_out(guess)} (or {way_out('s')} to read them as "
                         "seconds)")  # fmt: skip
    return 1.0


def round_thousandths(t, dt) -> bool:
    """Whether every step `dt` of the stamps `t` is a whole number of thousandths (to the
    stamps' float64 rounding): what a logger stamping in ms writes — whole ms, or ms to the µs
    (a 400-Hz log's 2.5, an 800-Hz log's 1.25, a 600-Hz log's 1.667). A clock stamping in
    seconds with its own jitter (10.000 37…) does not."""
    thousandths = np.asarray(dt, dtype=float) * 1e3
    rounding = 4e3 * float(np.spacing(np.max(np.abs(t)))) + 1e-9
    return bool(np.all(np.abs(thousandths - np.round(thousandths)) <= rounding))


def seconds_look_like(t) -> str | None:
    """The unit (a key of `TIME_UNITS`) that increasing stamps `t` (two or more), read as
    seconds, look like they were written in, or None — for a note, not a refusal (a slow log
    stamped in seconds looks the same):

    - every step ≥ 1 and a round number of thousandths, the median above 1 (10, 2.5, 1.25: a
      100-, 400- or 800-Hz log in ms; a 0.1-Hz HRG drift log in whole seconds too): "ms"
      up to a median of 1000, "us" up to 10⁶, else "ns";
    - every stamp a whole number, every step ≥ 1 and the median 1 (0, 1, 2, …, a dropped
      sample's step of 2 kept): a 1-kHz log in whole milliseconds (a 1-Hz log in whole
      seconds too), "ms".

    Stamps with a median step below 1 or a clock's sub-ms jitter in their steps look like
    seconds (None)."""
    t = np.asarray(t, dtype=float)
    dt = np.diff(t)
    if dt.size == 0 or not np.all(dt >= 1.0):
        return None
    step = float(np.median(dt))
    if step > 1.0 and round_thousandths(t, dt):
        return "ms" if step <= 1e3 else "us" if step <= 1e6 else "ns"
    if step == 1.0 and np.all(t == np.round(t)):
        return "ms"
    return None
