"""The samples a compensator's `fit` is given beside windows (`raw=`): checked to be the
session the windows were reduced from, so that one fit never reads two sessions (the grey
box fitted `raw` and dropped the windows; the MLP trained stage one on the windows and end
to end on `raw`)."""

from __future__ import annotations

import numpy as np

from ..data import MeasuredData
from .reduce import RateWindows

SAME_MEAN_RTOL = 1e-12
"""A window's mean time, temperature and wave angle agree with the mean of `raw`'s samples
over its sample range to this share of the largest |value| there: the same samples give the
same mean to rounding (≈ 1e-15), another session's differ by its noise at least (1″ of white
angle noise over a 600-sample window is 1e-5° on a wave angle of 10⁴°: 1e-9 of it)."""

_MEANS = (
    ("t_mid", "time_s", "mean time", "s"),
    ("temperature_c", "temperature_c", "mean temperature", "°C"),
    ("wave_angle_deg", "wave_angle_deg", "mean wave angle", "°"),
)


def check_raw(who: str, data, raw, windows: bool = True) -> None:
    """Refuse a `raw` that is not the samples behind `data` (the `fit` of every compensator,
    `who` its name): given beside `MeasuredData` (the samples twice — one was read, the other
    dropped), not `MeasuredData`, or, beside windows, another session than theirs. The
    windows' runs must be `raw`'s runs, each window's sample range inside its run, and its
    mean time, temperature and wave angle those of `raw`'s samples there (what `reduce`
    computed them from; a window of `RateWindows.select` passes, `raw`'s runs without a
    window do not). `None` passes. `windows`: whether `who` takes windows (the message's
    remedy). **Raises:** `ValueError` (`TypeError` for a `raw` that is not `MeasuredData`),
    one line naming `who` and the first difference."""
    if raw is None:
        return
    if isinstance(data, MeasuredData):
        other = ", or fit(windows, raw=data) with windows = reduce(data)" if windows else ""
        raise ValueError(f"{who}: data are the samples (MeasuredData) and raw= gives samples "
                         f"too; pass the samples once: fit(data){other}")  # fmt: skip
    if not isinstance(raw, MeasuredData):
        raise TypeError(f"{who}: raw must be hrgjax.MeasuredData, the samples the windows were "
                        f"reduced from; got {type(raw).__name__}")  # fmt: skip
    if isinstance(data, RateWindows) and (problem := _mismatch(data, raw)):
        raise ValueError(f"{who}: raw is not the session the windows were reduced from "
                         f"({problem}); pass the samples behind them: fit(windows, raw=data) "
                         "with windows = reduce(data)")  # fmt: skip


def _mismatch(windows: RateWindows, raw: MeasuredData) -> str | None:
    """The first way `windows` were not reduced from `raw`, in words; None when none."""
    rows = {int(raw.run[idx[0]]): idx for idx in raw.run_indices()}
    runs = np.asarray(windows.run)
    ids = {int(r) for r in np.unique(runs)}
    if missing := sorted(ids - rows.keys()):
        return f"the windows have run {missing[0]}, which raw has not"
    if extra := sorted(rows.keys() - ids):
        return f"raw has run {extra[0]}, which has no window"
    start, stop = np.asarray(windows.start, dtype=int), np.asarray(windows.stop, dtype=int)
    for run_id in sorted(ids):
        idx = rows[run_id]
        at = np.flatnonzero(runs == run_id)
        outside = (start[at] < 0) | (stop[at] > idx.size) | (stop[at] - start[at] < 1)
        if outside.any():
            i = at[np.argmax(outside)]
            return (f"run {run_id}'s window over samples [{start[i]}, {stop[i]}) does not lie "
                    f"in its {idx.size} samples in raw")  # fmt: skip
        for length in np.unique(stop[at] - start[at]):
            same = at[stop[at] - start[at] == length]
            take = idx[start[same][:, None] + np.arange(length)]  # (windows, samples) of raw
            for field, column, what, unit in _MEANS:
                x = np.asarray(raw[column], dtype=float)[take]
                mean, want = x.mean(axis=1), np.asarray(getattr(windows, field))[same]
                bad = np.abs(mean - want) > SAME_MEAN_RTOL * np.max(np.abs(x), axis=1) + 1e-300
                if bad.any():
                    j = int(np.argmax(bad))
                    return (f"run {run_id}'s window over samples [{start[same][j]}, "
                            f"{stop[same][j]}) has {what} {want[j]:.10g} {unit}, raw's samples "
                            f"there {mean[j]:.10g} {unit}")  # fmt: skip
    return None
