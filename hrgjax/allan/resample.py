r"""Records with non-uniform time stamps onto a uniform grid, by the angle they integrate to.

The Allan family needs samples every τ₀. A logger's time stamps jitter, drift or skip; a rate
sample $y_k$ stamped $t_k$ is the mean rate over $(t_{k-1}, t_k]$ (an increment over its
interval, as a gyro's output is), so the angle

$$\theta(t_k) = \theta(t_{k-1}) + y_k\,(t_k - t_{k-1})$$

is known at every stamp and linear between them. It is read at $t_0 + j\,\Delta t$ and
differenced: the uniform rate $\bar y_j = (\theta(t_0 + j\Delta t) - \theta(t_0 + (j-1)\Delta t))/\Delta t$
keeps the record's angle exactly (no rate is invented or lost between stamps). Angle samples
(`data="phase"`) are read at the grid directly.

The first sample's interval precedes the first stamp: in rate data it is not used.

An interval longer than `max_gap` steps is a gap (steps of the stamps' median, or of the
grid where that is longer: a finer grid does not make every interval a gap). The uniform
samples whose interval touches it are NaN, which [`deviation`][hrgjax.allan.deviation]
treats as missing (its windows across them are left out).

**What resampling costs.** Between stamps the angle is a straight line: the noise inside one
step is smoothed. Where the grid does not fall on the stamps (any jitter, after a few
samples), white rate noise N loses its Brownian bridge between stamps — N²·E[Δt²]/(6E[Δt])
at each of the three angles of a second difference, the stamps' intervals length-biased —
so its Allan variance at τ = mτ₀ reads (1 − κ/(2m)) of N²/τ, κ = E[Δt²]/τ₀² (1 for a
regular clock off the grid, 1.03 for ±30 % jitter): the deviation 0.70× at τ₀, 0.93× at
4τ₀, 0.98× at 16τ₀ (`tests/test_allan_stats.py`). A rate random walk and slower noise are
not changed. Read the short τ of a resampled record with that in mind, or log on a uniform
clock.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .._checks import describe, is_finite_real
from .._timebase import regular_step


@dataclasses.dataclass(frozen=True)
class Uniform:
    """A record on a uniform grid ([`to_uniform`][hrgjax.allan.to_uniform]): `y` the
    samples (NaN in gaps) [the record's unit], `rate_hz` [Hz], `t0` the grid's start [s],
    `step_spread` the largest |Δt − median Δt| of the stamps over the median [-], `gaps`
    the intervals taken as gaps, as `(start, end)` stamps [s]."""

    y: np.ndarray
    rate_hz: float
    t0: float
    step_spread: float
    gaps: tuple = ()


def to_uniform(
    t, y, *, data: str = "rate", rate_hz: float | None = None, max_gap: float = 2.5
) -> Uniform:
    """Samples `y` stamped `t` [s] (increasing) onto a uniform grid at `rate_hz` [Hz]
    (default: 1 / the mean regular step, `hrgjax._timebase.regular_step`: the median alone is
    quantised by stamps at an epoch), through the angle they integrate to (module docstring).
    NaN samples, and intervals longer than `max_gap` steps (module docstring), are gaps.

    **Returns:** a [`Uniform`][hrgjax.allan.resample.Uniform].

    **Raises:** `ValueError` naming the argument for stamps that do not increase or are not
    finite, shapes that differ, fewer than 3 samples, a bad `rate_hz`, `max_gap` or `data`.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    start = float(t[0]) if t.size else 0.0
    if not isinstance(data, str) or data not in ("rate", "phase"):
        raise ValueError(f"data must be 'rate' or 'phase'; got {describe(data)}")
    if t.ndim != 1 or t.shape != y.shape or t.size < 3:
        raise ValueError(f"t and y must be 1-D of one length ≥ 3; got {t.shape} and {y.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"t has a non-finite time stamp at index {int(np.argmin(np.isfinite(t)))}")
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0))
        raise ValueError(f"t must increase; t[{i + 1}] = {t[i + 1]!r} follows t[{i}] = {t[i]!r}")
    if not (is_finite_real(max_gap) and max_gap > 1):
        raise ValueError(f"max_gap must be > 1 step; got {describe(max_gap)}")
    median = float(np.median(dt))
    if rate_hz is None:
        rate_hz = 1.0 / regular_step(t)  # the median alone is quantised by stamps at an epoch
    if not (is_finite_real(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be a positive sample rate [Hz]; got {describe(rate_hz)}")
    step = 1.0 / float(rate_hz)
    t = t - start  # stamps from the first (epoch seconds keep their digits)
    grid = step * np.arange(int(math.floor(t[-1] / step * (1 + 1e-12))) + 1)
    tol = max(1e-9 * step, 4 * float(np.spacing(t[-1])))  # a grid point on a stamp is on it
    missing = ~np.isfinite(y)
    wide = dt > max_gap * max(step, median)
    if data == "rate":
        # interval k (t_k, t_{k+1}] carries y_{k+1}; a missing rate or a wide interval is a hole
        hole = missing[1:] | wide
        # the angle less the mean rate's (restored after): a large constant rate integrated
        # as it is drowns the noise's digits
        centre = float(np.mean(y[1:][~hole])) if (~hole).any() else 0.0
        angle = np.concatenate([[0.0], np.cumsum(np.where(hole, 0.0, (y[1:] - centre) * dt))])
        at = np.interp(grid, t, angle)
        out = np.diff(at) / step + centre
        # a grid interval touching a hole: NaN (the holes' stamps, spread over the grid)
        lo = np.searchsorted(t, grid[:-1] + tol, side="right") - 1  # each start's interval
        hi = np.searchsorted(t, grid[1:] - tol, side="left") - 1  # ... and each end's
        bad = np.concatenate([[0], np.cumsum(hole)])
        touched = bad[np.minimum(hi, hole.size - 1) + 1] - bad[np.maximum(lo, 0)] > 0
        out = np.where(touched, np.nan, out)
    else:
        ok = ~missing
        at = np.interp(grid, t[ok], y[ok])
        # a grid point inside a wide interval or next to a missing angle: NaN
        k = np.clip(np.searchsorted(t, grid + tol, side="right") - 1, 0, t.size - 1)
        exact = np.abs(grid - t[k]) <= tol
        after = np.minimum(k + 1, t.size - 1)
        inside = missing[k] | (missing[after] | wide[np.minimum(k, t.size - 2)])
        near = np.where(exact, missing[k], inside)
        out = np.where(near, np.nan, at)
    gaps = tuple((start + float(t[i]), start + float(t[i + 1])) for i in np.flatnonzero(wide))
    return Uniform(
        y=out,
        rate_hz=float(rate_hz),
        t0=start,
        step_spread=float(np.max(np.abs(dt - median)) / median),
        gaps=gaps,
    )
