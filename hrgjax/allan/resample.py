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

**A stall keeps the samples.** A uniform clock that stalls — one interval that is not a whole
number of steps (3.5, 1.5, 0.7), the stamps after it uniform again — is not jittered: on one
grid from the first stamp every later sample would be read between two (white noise 0.50×
at τ₀ after a 3.5-step stall). So after such an interval, where a run of at least `MIN_RUN`
stamps lies on a grid of its own and its first stamp is more than `JUMP` tolerances off the
grid in use, the grid starts anew at that stamp: each piece's samples are the record's own,
the stall's sample is NaN and so is the time it lasted, to the nearest whole number of steps
(Stable32's gap convention: a 3.5-step stall is 4 NaN samples, a 1.5-step one 2, a 0.7-step
one 1); a piece's first sample sits at the sample number nearest its time. Angle data keep
the record's mean rate on each sample's nominal time (a sample up to half a step from its
stamp is moved along that rate). `Uniform.breaks` lists these intervals and
`Uniform.interpolated` counts the samples read between stamps (0 for a piecewise-uniform
clock). A phase jump within `JUMP` tolerances (4e-3 of a step at 100 Hz) is read on the old
grid: white noise at τ₀ then reads at most 1.2 % low in variance after it.

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

from .._checks import check_numbers, describe, is_finite_real
from .._timebase import UNIFORM_TOLERANCE, regular_step

MIN_RUN = 16
"""Stamps in a run, each on the run's own grid, that make a piece the grid is re-anchored
to (a chance run as long in jittered stamps is rare: at a jitter of 1e-3 steps, 5e-5 per
stamp)."""

JUMP = 4.0
"""How many tolerances (`hrgjax._timebase.UNIFORM_TOLERANCE` of a step plus the stamps'
rounding) off the grid in use a run's first stamp must lie to re-anchor the grid: a stamp
jittered by that tolerance is not a stall."""


@dataclasses.dataclass(frozen=True)
class Uniform:
    """A record on a uniform grid ([`to_uniform`][hrgjax.allan.to_uniform]): `y` the
    samples (NaN in gaps) [the record's unit], `rate_hz` [Hz], `t0` the grid's start [s],
    `step_spread` the largest |Δt − median Δt| of the stamps over the median [-], `gaps`
    the intervals taken as gaps, as `(start, end)` stamps [s], `breaks` the intervals not a
    whole number of steps after which the grid was re-anchored (stalls; their samples NaN),
    as `(start, end)` stamps [s], `interpolated` how many of the samples in `y` were read
    between stamps (0: every sample is one of the record's own, as on a uniform or
    piecewise-uniform clock)."""

    y: np.ndarray
    rate_hz: float
    t0: float
    step_spread: float
    gaps: tuple = ()
    breaks: tuple = ()
    interpolated: int = 0


def _anchors(t, dt, step, tol) -> np.ndarray:
    """The stamps (indices into `t` [s], from 0) where the grid starts anew: the first of each
    run of `MIN_RUN` or more stamps on the run's own grid (each within `tol` [s]) whose first
    stamp lies more than `JUMP`·`tol` off the grid in use (a stall of a fraction of a step);
    jittered stamps form no such runs and stay on one grid."""
    n = np.rint(dt / step)
    on = (n >= 1) & (np.abs(dt - n * step) <= tol)  # a whole number of steps
    starts = np.concatenate([[0], np.flatnonzero(~on) + 1])
    ends = np.concatenate([starts[1:], [t.size]])
    phase = t - np.concatenate([[0.0], np.cumsum(n)]) * step  # constant along a run
    spread = np.maximum.reduceat(np.abs(phase - np.repeat(phase[starts], ends - starts)), starts)
    anchors, current = [0], 0.0
    for i in np.flatnonzero((ends - starts >= MIN_RUN) & (spread <= tol) & (starts > 0)):
        k = (t[starts[i]] - current) / step
        if abs(k - math.floor(k + 0.5)) * step > JUMP * tol:
            anchors.append(int(starts[i]))
            current = float(t[starts[i]])
    return np.asarray(anchors, dtype=int)


def to_uniform(
    t, y, *, data: str = "rate", rate_hz: float | None = None, max_gap: float = 2.5
) -> Uniform:
    """Samples `y` stamped `t` [s] (increasing) onto a uniform grid at `rate_hz` [Hz]
    (default: 1 / the mean regular step, `hrgjax._timebase.regular_step`: the median alone is
    quantised by stamps at an epoch), through the angle they integrate to (module docstring).
    NaN samples, and intervals longer than `max_gap` steps (module docstring), are gaps.
    After an interval that is not a whole number of steps, where a run of stamps on their own
    grid follows, the grid starts anew at that run (module docstring: a stall keeps every
    other sample as it was).

    **Returns:** a [`Uniform`][hrgjax.allan.resample.Uniform].

    **Raises:** `ValueError` naming the argument for stamps that do not increase or are not
    finite, shapes that differ, fewer than 3 samples, a bad `rate_hz`, `max_gap` or `data`.
    """
    check_numbers("t", t, "time stamps [s], 1-D")  # str, None, complex: NumPy's errors
    check_numbers("y", y, "real samples, 1-D")  # complex: its real part was resampled
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if not isinstance(data, str) or data not in ("rate", "phase"):
        raise ValueError(f"data must be 'rate' or 'phase'; got {describe(data)}")
    if t.ndim != 1 or t.shape != y.shape or t.size < 3:
        raise ValueError(f"t and y must be 1-D of one length ≥ 3; got {t.shape} and {y.shape}")
    if np.any(np.isinf(y)):  # was taken as a gap, as NaN is
        raise ValueError(f"y has an infinite value at index {int(np.argmax(np.isinf(y)))}; "
                         "mark a missing sample NaN")  # fmt: skip
    start = float(t[0])
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
    # a stamp within this of a grid point is on it (the uniform tolerance, as is_uniform's)
    tol = UNIFORM_TOLERANCE * step + 2.0 * float(np.spacing(np.max(np.abs(t))))
    t = t - start  # stamps from the first (epoch seconds keep their digits)
    dt = np.diff(t)
    anchors = _anchors(t, dt, step, tol)
    # the grid: from each anchor, whole steps up to the stamp where the next piece's stall
    # begins; each piece's first point at the sample number nearest its time (after the
    # previous piece's last: the sample between them is NaN)
    first, index, pieces = [], [], []
    for p, a in enumerate(anchors):
        end = t[anchors[p + 1] - 1] + tol if p + 1 < anchors.size else t[-1] * (1 + 1e-12)
        count = int(math.floor((end - t[a]) / step)) + 1
        k0 = 0 if p == 0 else max(index[-1][-1] + 1, int(math.floor(t[a] / step + 0.5)))
        first.append(t[a] + step * np.arange(count))
        index.append(k0 + np.arange(count))
        pieces.append(np.full(count, p))
    grid, index, piece = np.concatenate(first), np.concatenate(index), np.concatenate(pieces)
    missing = ~np.isfinite(y)
    wide = dt > max_gap * max(step, median)
    broken = np.zeros(dt.size, dtype=bool)
    broken[anchors[1:] - 1] = True  # the interval a stall ends: its sample is not one step's
    hole = wide | broken
    k = np.clip(np.searchsorted(t, grid + tol, side="right") - 1, 0, t.size - 1)
    on_stamp = np.abs(grid - t[k]) <= tol
    if data == "rate":
        # interval k (t_k, t_{k+1}] carries y_{k+1}; a missing rate or a wide interval is a hole
        hole = missing[1:] | hole
        # the angle less the mean rate's (restored after): a large constant rate integrated
        # as it is drowns the noise's digits
        centre = float(np.mean(y[1:][~hole])) if (~hole).any() else 0.0
        angle = np.concatenate([[0.0], np.cumsum(np.where(hole, 0.0, (y[1:] - centre) * dt))])
        at = np.interp(grid, t, angle)
        # a sample between two points of one piece; one touching a hole: NaN (the holes'
        # stamps, spread over the grid)
        lo = np.searchsorted(t, grid[:-1] + tol, side="right") - 1  # each start's interval
        hi = np.searchsorted(t, grid[1:] - tol, side="left") - 1  # ... and each end's
        bad = np.concatenate([[0], np.cumsum(hole)])
        touched = bad[np.minimum(hi, hole.size - 1) + 1] - bad[np.maximum(lo, 0)] > 0
        pair = (piece[1:] == piece[:-1]) & ~touched
        out = np.full(int(index[-1]), np.nan)
        out[index[:-1][pair]] = np.diff(at)[pair] / step + centre
        own = pair & (lo == hi) & on_stamp[:-1] & on_stamp[1:]  # exactly one stamp interval
        interpolated = int(np.sum(pair & ~own))
    else:
        ok = ~missing
        # the angle less the record's mean rate, restored on each point's nominal time: a
        # piece's first point is up to half a step from it, its mean rate's angle is not
        t_ok, y_ok = t[ok], y[ok]
        slope = (y_ok[-1] - y_ok[0]) / (t_ok[-1] - t_ok[0]) if t_ok.size > 1 else 0.0
        at = np.interp(grid, t_ok, y_ok - slope * t_ok) + slope * (index * step)
        # a grid point inside a hole's interval or next to a missing angle: NaN
        after = np.minimum(k + 1, t.size - 1)
        inside = missing[k] | (missing[after] | hole[np.minimum(k, t.size - 2)])
        near = np.where(on_stamp, missing[k], inside)
        out = np.full(int(index[-1]) + 1, np.nan)
        out[index] = np.where(near, np.nan, at)
        interpolated = int(np.sum(~near & ~on_stamp))

    def spans(flags):
        return tuple((start + float(t[i]), start + float(t[i + 1])) for i in np.flatnonzero(flags))

    return Uniform(
        y=out,
        rate_hz=float(rate_hz),
        t0=start,
        step_spread=float(np.max(np.abs(dt - median)) / median),
        gaps=spans(wide),
        breaks=spans(broken),
        interpolated=interpolated,
    )
