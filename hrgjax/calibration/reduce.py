r"""Reduction of bench data to rates per window: drift and scale factor per point.

Every run is cut into windows (a static run is one window; a rotation run is cut into
windows of `window_s`, never across a time gap: `GAP_STEPS`). In each window the wave-angle
slope is fitted by least squares and turned into the **measured equivalent input rate** with
the nominal angular gain:

$$\Omega_{\rm meas} = -\frac{1}{k_{e,\rm nom}}\,\frac{d\theta_{\rm meas}}{dt}.$$

Drift is $D = \Omega_{\rm meas} - \Omega_{\rm table}$ on static windows; the scale factor is
$\mathrm{SF} = (\Omega_{\rm meas} - D(\theta, T))/\Omega_{\rm table}$ on rotation windows.
A window's rate is not the rate at its mean wave angle but its average, weighted as the
least-squares slope weighs it, over the arc the wave turns in the window: the Fourier and MLP
fits model it so (`hrgjax.calibration._window_arc`; a 2θ term counts 0.998 of its value on a
3-s window at 5 °/s, 0.805 at 50 °/s).

The table rate of a window is the least-squares slope of the table angle over the same
samples (the measured rate's estimator), so a table rate that changes within a window — a
spin-up, an oscillating table — is compared with the same average of it.

Standard errors use **batch means**: the window is split into `batches` equal parts, the slope
of each part is fitted, a linear trend over the parts is removed (a smooth change of the
rate within the window is systematic, e.g. the scale-factor ripple while the pattern turns),
and the error is the residual scatter over √batches. Per window, so runs of different noise
each get their own. Under an angle random walk its *size* is right (its mean is 0.92 of the
slopes' scatter, as √(χ²₃/3)'s is), but it is read from `batches` − 2 = 3 degrees of freedom
(`RateWindows.dof`, `static_drift()['dof']`), so the error over it is **Student-t with
`dof` degrees of freedom, not normal**: ±1 standard error holds the truth 61 % of the time
and ±2 86 % (Monte Carlo, 2000 300-s static runs of the default gyro: 59.5 % and 86.7 %, RMS
of error/stderr 1.65 against t₃'s √3; `benchmarks/coverage_stderr.py`). For 68 % / 95 %
intervals multiply it by t's quantiles (1.20 / 3.18 at 3 dof, 1.07 / 2.31 at 8), or use more
batches (`static_drift(batches=10)`: 8 dof) where the run is long enough for white angle
noise not to matter (below). **White angle noise is counted about `batches` times too
large** (4.2× with 5 batches: a least-squares slope's variance under white angle noise falls
as the cube of its length), so on a gyro whose windows are dominated by white angle noise
the error bars are conservative.
A model fitted to all the windows together was tried and withdrawn: it was right on
average but pooled runs of different noise (6.8× too large on one, 1.7× too small on the
other) and let a random walk in on pure white noise one time in six. Noise correlated over
much longer than a window (a Gauss–Markov bias with a 10-min correlation time) acts as a
slowly varying offset and shows up as scatter between runs instead.
"""

from __future__ import annotations

import numbers

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_1d, check_finite_host, concrete_value, describe, whole_number
from ..data import MeasuredData
from ..pattern_noise import STILL_RATE_DPS, TEMPERATURE_TOLERANCE_C
from ..units import K_E_NOMINAL as K_E_NOMINAL
from ..units import K_E_WANTED, group_temperatures, k_e_problem
from ..units import WINDOW_S as WINDOW_S

RAMP_WINDOW_S = 300.0
"""Window of a ramp (table at rest, temperature moving) in the physical fit and the MLP's
s_T training [s]: each window's slope is a drift at its own temperature, so a ramp is a
temperature sweep, not one number. The physical fit's windows run from the ramp's start;
the last, partial one is kept when it has ≥ 4 samples (`reduce(ramp_window_s=…)` keeps
whole windows only). The design's criterion approximates them by round(duration / 300 s)
equal windows."""


def window_slopes(t, theta, n_windows: int, batches: int = 0):
    r"""Least-squares slopes of `theta` over `n_windows` equal consecutive windows of samples.

    Traceable (JAX arrays): the physical fit applies it to simulated angles exactly as
    [`reduce`][hrgjax.calibration.reduce] applies it to measured ones.

    **Arguments:**

    - `t`, `theta`: shape (N,) sample times [s] and angles (any unit); N must be a multiple
      of `n_windows`.
    - `n_windows`: number of windows.
    - `batches`: if ≥ 3, also return batch-means standard errors of each window's slope.

    **Returns:** `(slope, t_mid, theta_mean)` each of shape (n_windows,), plus `stderr` when
    `batches ≥ 3`: a Student-t scale with `batches − 2` degrees of freedom (module docstring).
    """
    check_1d("window_slopes: t", t, "sample times [s]")
    check_1d("window_slopes: theta", theta, "angles")
    if t.shape != theta.shape:
        raise ValueError(f"window_slopes: theta must have the shape of t, {tuple(t.shape)}; got "
                         f"{tuple(theta.shape)}")  # fmt: skip
    n_windows = whole_number("window_slopes: n_windows", n_windows, "a whole number ≥ 1")
    batches = whole_number("window_slopes: batches", batches, "a whole number (≥ 3 for errors)")
    if n_windows < 1:
        raise ValueError(f"window_slopes: n_windows must be a whole number ≥ 1; got {n_windows}")
    return _window_stats(jnp, t, theta, n_windows, batches)


def _window_stats(xp, t, theta, n_windows, batches):
    n = t.shape[0] // n_windows
    if n * n_windows != t.shape[0]:
        raise ValueError(f"{t.shape[0]} samples do not split into {n_windows} equal windows")
    tw = t.reshape(n_windows, n)
    yw = theta.reshape(n_windows, n)
    slope, tm, ym = least_squares_slope(xp, tw, yw)
    if batches < 3:
        return slope, tm, ym
    nb = n // batches
    tb = tw[:, : nb * batches].reshape(n_windows, batches, nb)
    yb = yw[:, : nb * batches].reshape(n_windows, batches, nb)
    sb, _, _ = least_squares_slope(xp, tb, yb)
    # A smooth change of rate within the window (the scale-factor ripple as the pattern turns)
    # is systematic, not noise: remove a linear trend over the batches before the scatter.
    idx = xp.broadcast_to(xp.arange(batches, dtype=sb.dtype), sb.shape)
    trend, _, mean = least_squares_slope(xp, idx, sb)
    resid = sb - mean[..., None] - trend[..., None] * (idx - (batches - 1) / 2)
    stderr = xp.sqrt(xp.sum(resid**2, axis=-1) / (batches - 2) / batches)
    return slope, tm, ym, stderr


def _table_rates(t, table_angle, rate, n_windows: int) -> np.ndarray:
    """Table rate of each of `n_windows` equal windows [°/s]: the least-squares slope of the
    table angle [°] over the window's samples, the estimator (and weights) of the measured
    rate, so a rate that changes within the window (a spin-up, an oscillating table) is
    compared with the same average of it; exactly 0 where the rate is 0 throughout."""
    tw, aw = t.reshape(n_windows, -1), table_angle.reshape(n_windows, -1)
    slope = least_squares_slope(np, tw, aw)[0]
    at_rest = np.all(rate.reshape(n_windows, -1) == 0.0, axis=1)
    return np.where(at_rest, 0.0, slope)


def check_window(who: str, window_s) -> None:
    """Refuse a `window_s` that is neither `None` (the reduction's default) nor a finite
    number of seconds > 0."""
    if window_s is not None and not (
        isinstance(window_s, numbers.Real)
        and not isinstance(window_s, bool)
        and np.isfinite(window_s)
        and window_s > 0
    ):
        raise ValueError(f"{who}: window_s must be None or a finite number of seconds > 0 "
                         f"(the rotation-run window); got {window_s!r}")  # fmt: skip


def least_squares_slope(xp, t, y, mask=None):
    """Least-squares slope, mean time and mean value along the last axis; with `mask`, over
    the samples where it is 1 only (a window without 2 of them gets slope 0)."""
    if mask is None:
        tm = xp.mean(t, axis=-1, keepdims=True)
        ym = xp.mean(y, axis=-1, keepdims=True)
        dt = t - tm
        slope = xp.sum(dt * (y - ym), axis=-1) / xp.sum(dt * dt, axis=-1)
        return slope, tm[..., 0], ym[..., 0]
    count = xp.sum(mask, axis=-1, keepdims=True)
    safe = xp.maximum(count, 1.0)
    tm = xp.sum(mask * t, axis=-1, keepdims=True) / safe
    ym = xp.sum(mask * y, axis=-1, keepdims=True) / safe
    dt = (t - tm) * mask
    ok = count[..., 0] >= 2
    den = xp.where(ok, xp.sum(dt * dt, axis=-1), 1.0)
    slope = xp.where(ok, xp.sum(dt * (y - ym), axis=-1) / den, 0.0)
    return slope, tm[..., 0], ym[..., 0]


class RateWindows(eqx.Module):
    """Reduced bench data: one entry per window (static run = one window).

    All fields have shape (W,). Angles are electrical [°], rates [°/s], temperatures [°C].

    - `run`: run id of the window; `start`, `stop`: sample index range in the run.
    - `t_mid`: mean time of the window [s]; `duration`: its length [s]. With `stop − start`
      they give the fits the arc the wave turns over the window's evenly spaced samples
      (`hrgjax.calibration._window_arc`); a hand-built window of `duration` 0 is a point
      value (no arc).
    - `temperature_c`: window mean.
    - `table_rate_dps`: least-squares slope of the table angle over the window [°/s] (the
      column `table_angle_deg`, or the rate's integral), the same estimator as `rate_dps`;
      exactly 0 where the table rate is 0 throughout the window.
    - `wave_angle_deg`: mean measured wave angle over the window.
    - `rate_dps`: measured equivalent input rate −(dθ/dt)/k_e,nom.
    - `stderr_dps`: batch-means standard error of `rate_dps` (module docstring: its size right
      for an angle random walk, ≈ `batches` times too large for white angle noise).
    - `dof`: its degrees of freedom (batches − 2; 3 by default): (rate − truth)/stderr is
      Student-t with `dof` degrees of freedom, so ±1 `stderr_dps` covers 61 % at 3 dof, not
      68 % (None when the windows were built by hand).
    - `k_e`: the nominal angular gain used.
    - `temperature_rate_cps`: least-squares slope of the temperature over the window [°C/s]
      (None when the windows were built by hand).
    """

    run: np.ndarray
    start: np.ndarray
    stop: np.ndarray
    t_mid: np.ndarray
    duration: np.ndarray
    temperature_c: np.ndarray
    table_rate_dps: np.ndarray
    wave_angle_deg: np.ndarray
    rate_dps: np.ndarray
    stderr_dps: np.ndarray
    k_e: float = eqx.field(static=True)
    temperature_rate_cps: np.ndarray | None = None
    dof: np.ndarray | None = None

    @property
    def static(self) -> np.ndarray:
        """Mask of windows with the table at rest: |table rate| within
        [`STILL_RATE_DPS`][hrgjax.units.STILL_RATE_DPS] (a rate table's readback
        jitter is not a rotation; the window's table rate is subtracted all the same)."""
        return np.abs(self.table_rate_dps) <= STILL_RATE_DPS

    @property
    def drift_dph(self) -> np.ndarray:
        """Measured rate minus table rate [°/h] (the drift on static windows)."""
        return (self.rate_dps - self.table_rate_dps) * 3600.0

    def __check_init__(self):
        check_k_e(self.k_e, "RateWindows.k_e")
        n = None
        for name in _WINDOW_FIELDS:
            x = getattr(self, name)
            if x is None and name in ("temperature_rate_cps", "dof"):
                continue
            shape = check_1d(f"RateWindows.{name}", x, "one value per window")
            if n is None:
                n = shape[0]
            elif shape[0] != n:
                raise ValueError(f"RateWindows.{name} must have one value per window, shape "
                                 f"({n},) as RateWindows.run; got shape {shape}")  # fmt: skip
            check_finite_host(f"RateWindows.{name}", x)

    def select(self, mask) -> RateWindows:
        """The windows where `mask` (bool, one per window) is true."""
        shape = np.shape(mask)
        if shape != (len(self),) or np.asarray(mask).dtype.kind not in "bi":
            raise ValueError(f"RateWindows.select: mask must be {len(self)} bools, one per "
                             f"window; got {describe(mask)}")  # fmt: skip
        mask = np.asarray(mask, bool)
        return jax.tree_util.tree_map(lambda x: np.asarray(x)[mask], self)

    def __len__(self) -> int:
        return int(np.asarray(self.run).shape[0])


_WINDOW_FIELDS = (
    "run",
    "start",
    "stop",
    "t_mid",
    "duration",
    "temperature_c",
    "table_rate_dps",
    "wave_angle_deg",
    "rate_dps",
    "stderr_dps",
    "temperature_rate_cps",
    "dof",
)
"""`RateWindows`' per-window fields, checked to one value per window."""


def check_data(who: str, data) -> None:
    """Refuse `data` that is not an [`hrgjax.MeasuredData`][] in one line naming `who`."""
    if not isinstance(data, MeasuredData):
        raise TypeError(f"{who}: data must be hrgjax.MeasuredData (hg.MeasuredData(columns) or "
                        f"hg.load(path)); got {type(data).__name__}")  # fmt: skip


def _seconds(who: str, name: str, value, none: bool = True) -> None:
    """Refuse a window length that is not a finite number of seconds > 0 (or None)."""
    if value is None and none:
        return
    v = concrete_value(value) if hasattr(value, "dtype") else value
    ok = (isinstance(v, numbers.Real | np.ndarray) and not isinstance(v, bool)
          and np.ndim(v) == 0 and np.asarray(v).dtype.kind in "iuf" and np.isfinite(v) and v > 0)  # fmt: skip
    if not ok:
        form = "None or a finite number > 0" if none else "a finite number > 0"
        raise ValueError(f"{who}: {name} must be {form} [s]; got {describe(value)}")


def check_k_e(k_e, name: str = "k_e") -> float:
    """`k_e` as a float, or a one-line error naming `name`: `TypeError` for a non-number,
    `ValueError` outside [`K_E_RANGE`][hrgjax.units.K_E_RANGE], (0, 1]."""
    try:
        value = np.asarray(k_e)
    except Exception:  # a tracer under jit: nothing to check here
        return k_e
    if isinstance(k_e, bool) or value.shape != () or value.dtype.kind not in "iuf":
        raise TypeError(f"{name} must be a number, {K_E_WANTED}; got {type(k_e).__name__}")
    problem = k_e_problem(float(value))
    if problem:
        raise ValueError(f"{name} must be {problem}")
    return float(value)


GAP_STEPS = 2.5
"""A step between samples longer than this many of the run's median step is a time gap:
windows of moving runs and ramps never straddle one (`_window_layout`). A window's rate is
the average of the rate over the arc the wave turns in it, weighted as its samples are
(`hrgjax.calibration._window_arc`); a window over a gap weighs its two sides as no evenly
sampled window would (a 20-s gap in a 5 °/s run at 2 Hz made one 22-s window of six
samples)."""


def _window_layout(
    r: MeasuredData, window_s: float | None, ramp_window_s: float | None = None
) -> tuple[np.ndarray, int]:
    """(first sample of each window, samples per window) of one run; a static run is one
    window (a ramp — at rest, temperature moving — windows of `ramp_window_s` when given).
    Windows of moving runs and ramps are laid out in each stretch between time gaps
    (`GAP_STEPS`) from its start, and samples past a stretch's last whole window are left
    out of the windows (not of the data); a run with no whole window is one window."""
    t = r["time_s"]
    if len(t) < 4:
        raise ValueError(
            f"run {int(r.run[0])} has {len(t)} samples; reduction needs at least 4 per window"
        )
    whole = np.zeros(1, dtype=int), len(t)
    if bool(np.all(np.abs(r["table_rate_dps"]) <= STILL_RATE_DPS)):  # at rest (readback jitter)
        if ramp_window_s is None or np.ptp(r["temperature_c"]) <= TEMPERATURE_TOLERANCE_C:
            return whole
        window_s = ramp_window_s
    elif window_s is None:
        return whole
    step = np.diff(t)
    median = float(np.median(step))
    n = max(int(round(window_s / median)), 4)
    cuts = np.flatnonzero(step > GAP_STEPS * median) + 1
    edges = np.concatenate([[0], cuts, [len(t)]])
    starts = [a + n * np.arange((b - a) // n) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    starts = np.concatenate(starts).astype(int)
    return whole if starts.size == 0 else (starts, n)


def check_whole_angle(data: MeasuredData) -> None:
    """Refuse data a whole-angle calibration cannot read: force-to-rebalance output (the wave
    held: a `rebalance_rate_dps` column, with `rebalance_on` absent or 1 somewhere — an FTR
    gyro's record with its loop off throughout is whole-angle data) or runs with a
    commanded precession (the wave turned by a force, not by the case; nonzero
    `precession_dps`) — `hrgjax self-calibrate` reads those."""
    held = "rebalance_rate_dps" in data and np.any(  # held wherever rebalance_on is absent or 1
        data["rebalance_on"] != 0 if "rebalance_on" in data else True
    )
    if held:
        raise ValueError(
            "these data are force-to-rebalance output (a rebalance_rate_dps column: the wave is "
            "held, its angle does not measure the rate); this calibration reads whole-angle "
            "data — for FTR holds use hrgjax self-calibrate"
        )
    if "precession_dps" in data and np.any(data["precession_dps"] != 0):
        raise ValueError(
            "these data have a commanded precession (precession_dps ≠ 0: the wave was turned "
            "by a force, not by the case); this calibration reads runs without one — for "
            "virtual-precession sweeps use hrgjax self-calibrate"
        )


def reduce(
    data: MeasuredData,
    k_e: float = K_E_NOMINAL,
    window_s: float | None = WINDOW_S,
    batches: int = 5,
    ramp_window_s: float | None = None,
) -> RateWindows:
    """Reduce bench data to windows (see the module docstring).

    **Arguments:**

    - `data`: [`hrgjax.MeasuredData`][]; each run is either static (table rate 0 throughout)
      or moving.
    - `k_e`: nominal angular gain used for the conversion to input rate.
    - `window_s`: window length for moving runs [s] (see
      [`WINDOW_S`][hrgjax.calibration.reduce.WINDOW_S]); `None` keeps each run whole.
    - `batches`: batch count for the standard errors (≥ 3); they have `batches − 2` degrees
      of freedom (fewer where a window has under 2·`batches` samples: `RateWindows.dof`).
    - `ramp_window_s`: window length for ramps — runs at rest whose temperature moves [s]
      (e.g. `RAMP_WINDOW_S`, 300 s); `None` (default) keeps each ramp one window,
      as every static run.

    **Returns:** [`RateWindows`][hrgjax.calibration.RateWindows].

    **Raises:** `ValueError` for `k_e` outside (0, 1], `batches < 3`, `window_s ≤ 0`, a run
    too short, or
    force-to-rebalance or virtual-precession data
    ([`check_whole_angle`][hrgjax.calibration.reduce.check_whole_angle]).
    """
    check_data("reduce", data)
    check_k_e(k_e)
    check_whole_angle(data)
    batches = whole_number("batches", batches, "a whole number ≥ 3 (for a standard error)")
    if batches < 3:
        raise ValueError(f"batches must be ≥ 3 for a standard error; got {batches}")
    for name, value in (("window_s", window_s), ("ramp_window_s", ramp_window_s)):
        _seconds("reduce", name, value)
    cols: dict[str, list] = {k: [] for k in RateWindows.__dataclass_fields__ if k != "k_e"}
    for r in data.runs():
        t, th = r["time_s"], r["wave_angle_deg"]
        temp, rate = r["temperature_c"], r["table_rate_dps"]
        starts, n = _window_layout(r, window_s, ramp_window_s)
        n_win = starts.size
        nb = min(batches, n // 2)
        if nb < 3:
            raise ValueError(f"run {int(r.run[0])}: windows of {n} samples are too short")
        take = (starts[:, None] + np.arange(n)).ravel()  # the windows' samples, in order
        t, th, temp, rate = t[take], th[take], temp[take], rate[take]
        slope, tm, ym, se = _window_stats(np, t, th, n_win, nb)
        cols["run"].append(np.full(n_win, int(r.run[0])))
        cols["start"].append(starts)
        cols["stop"].append(starts + n)
        cols["t_mid"].append(tm)
        cols["duration"].append(t[n - 1 :: n] - t[::n])
        cols["temperature_c"].append(temp.reshape(n_win, n).mean(axis=1))
        cols["table_rate_dps"].append(_table_rates(t, r.table_angle_deg[take], rate, n_win))
        cols["wave_angle_deg"].append(ym)
        cols["rate_dps"].append(-slope / k_e)
        cols["stderr_dps"].append(se / k_e)
        cols["dof"].append(np.full(n_win, nb - 2))
        cols["temperature_rate_cps"].append(least_squares_slope(np, t.reshape(n_win, n),
                                                   temp.reshape(n_win, n))[0])  # fmt: skip
    arrays = {k: np.concatenate(v) for k, v in cols.items()}
    return RateWindows(**arrays, k_e=float(k_e))


def static_drift(data: MeasuredData, k_e: float = K_E_NOMINAL, batches: int = 5):
    """Drift of each static run as equivalent input rate [°/h]: −(wave-angle slope)/k_e minus
    the table rate; with the run's temperature [°C] and mean wave angle [°].

    `batches` (≥ 3) sets the standard error's degrees of freedom, `batches − 2`: the error
    (drift − truth)/`stderr_dph` is Student-t with `dof` degrees of freedom, so ±1
    `stderr_dph` holds the truth 61 % of the time at the default 3 dof (t₃'s 68 % / 95 %
    quantiles are 1.20 / 3.18), 65 % with `batches=10` (8 dof; 1.07 / 2.31). More batches
    are right on long static runs, where an angle random walk dominates the drift's error;
    where white angle noise does, each batch counts it ≈ `batches` times too large
    (conservative: the module docstring).

    **Returns:** dict of arrays `temperature_c`, `wave_angle_deg`, `drift_dph`,
    `stderr_dph`, `dof`, `run`.
    """
    check_data("static_drift", data)
    w = reduce(data, k_e, window_s=None, batches=batches)
    w = w.select(w.static)
    return {
        "temperature_c": w.temperature_c,
        "wave_angle_deg": w.wave_angle_deg,
        "drift_dph": w.drift_dph,
        "stderr_dph": w.stderr_dps * 3600.0,
        "dof": w.dof,
        "run": w.run,
    }


def scale_factor_vs_angle(
    data: MeasuredData, k_e: float = K_E_NOMINAL, window_s: float = 2.0, bin_deg: float = 10.0
):
    r"""Local scale factor of rotation runs vs wave angle (folded to [−90°, 90°)), binned.

    $\mathrm{SF} = -\Delta\theta_{\rm meas} / (k_e\,\Delta\alpha_{\rm table})$ over intervals
    of `window_s`: the measured equivalent input rate over the table rate, relative to the
    nominal gain `k_e` (1 is nominal; the definition of the scale-factor targets the
    compensators fit to [`reduce`][hrgjax.calibration.reduce]'s windows, with the sign of
    its measured rate), so runs at different temperatures keep their different levels.
    Δα is the increment of the table angle (the column `table_angle_deg`, or the rate's
    integral) over the same samples as Δθ. Only intervals over which the table turns
    throughout — |table rate| above
    [`STILL_RATE_DPS`][hrgjax.units.STILL_RATE_DPS], one sign, at every sample —
    count: a spin-up, a stop or an at-rest stretch of a run is left out, and a run with no
    such interval (a static run, readback jitter included) gives no row. The drift is not
    removed (at 5 °/s a drift of 1 °/h is 5.6·10⁻⁵ of the rate).

    **Returns:** dict `temperature_c` (T,), `wave_angle_deg` (B,), `rate_dps` (the median
    |table rate| of the turning samples [°/s]; NaN without any), `scale_factor` (T, B):
    one row per temperature (the mean temperatures of the runs' turning samples, grouped by
    [`group_temperatures`][hrgjax.units.group_temperatures]); NaN in bins no interval's
    mid-angle falls in.
    """
    check_data("scale_factor_vs_angle", data)
    k_e = check_k_e(k_e)
    _seconds("scale_factor_vs_angle", "window_s", window_s, none=False)
    ok = isinstance(bin_deg, numbers.Real) and not isinstance(bin_deg, bool)
    if not (ok and 0 < bin_deg <= 180):
        raise ValueError(f"scale_factor_vs_angle: bin_deg must be a number in (0, 180] [° of "
                         f"wave angle]; got {describe(bin_deg)}")  # fmt: skip
    edges = np.arange(-90.0, 90.0 + bin_deg / 2, bin_deg)
    centres = 0.5 * (edges[1:] + edges[:-1])
    run_temps, run_parts, run_rates = [], [], []
    for r in data.runs():
        t, th, rate = r["time_s"], r["wave_angle_deg"], r["table_rate_dps"]
        step = max(int(round(window_s / float(np.median(np.diff(t))))), 1) if len(t) > 1 else 1
        if len(t) <= step:
            continue
        sign = np.where(rate > STILL_RATE_DPS, 1, 0) - np.where(rate < -STILL_RATE_DPS, 1, 0)
        ok = np.zeros(len(t) - step, bool)
        for s in (1, -1):  # samples i … i + step all turning one way
            count = np.concatenate([[0], np.cumsum(sign == s)])
            ok |= count[step + 1 :] - count[: -step - 1] == step + 1
        d_table = r.table_angle_deg[step:] - r.table_angle_deg[:-step]
        ok &= d_table != 0.0
        if not np.any(ok):
            continue
        sf = -(th[step:] - th[:-step])[ok] / (k_e * d_table[ok])
        mid = 0.5 * (th[step:] + th[:-step])[ok]
        folded = (mid + 90.0) % 180.0 - 90.0
        run_temps.append(float(np.mean(r["temperature_c"][sign != 0])))
        run_parts.append((folded, sf))
        run_rates.append(np.abs(rate[sign != 0]))
    by_temp: dict[float, list] = {}  # one row per temperature, last-bit differences merged
    for temp, part in zip(group_temperatures(run_temps), run_parts, strict=True):
        by_temp.setdefault(float(temp), []).append(part)
    temps, rows = [], []
    for temp, parts in sorted(by_temp.items()):
        ang = np.concatenate([p[0] for p in parts])
        sf = np.concatenate([p[1] for p in parts])
        idx = np.digitize(ang, edges) - 1
        rows.append(
            [np.mean(sf[idx == b]) if np.any(idx == b) else np.nan for b in range(len(centres))]
        )
        temps.append(temp)
    return {
        "temperature_c": np.asarray(temps, dtype=float),
        "wave_angle_deg": centres,
        "scale_factor": np.asarray(rows, dtype=float).reshape(len(temps), len(centres)),
        "rate_dps": float(np.median(np.concatenate(run_rates))) if run_rates else np.nan,
    }


__all__ = [
    "K_E_NOMINAL",
    "RAMP_WINDOW_S",
    "RateWindows",
    "reduce",
    "scale_factor_vs_angle",
    "static_drift",
    "window_slopes",
]
