r"""Reduction of bench data to rates per window: drift and scale factor per point.

Every run is cut into windows (a static run is one window; a rotation run is cut into
windows of `window_s`). In each window the wave-angle slope is fitted by least squares and
turned into the **measured equivalent input rate** with the nominal angular gain:

$$\Omega_{\rm meas} = -\frac{1}{k_{e,\rm nom}}\,\frac{d\theta_{\rm meas}}{dt}.$$

Drift is $D = \Omega_{\rm meas} - \Omega_{\rm table}$ on static windows; the scale factor is
$\mathrm{SF} = (\Omega_{\rm meas} - D(\theta, T))/\Omega_{\rm table}$ on rotation windows.

The table rate of a window is the least-squares slope of the table angle over the same
samples (the measured rate's estimator), so a table rate that changes within a window — a
spin-up, an oscillating table — is compared with the same average of it.

Standard errors come from **one noise model for all the windows**: white angle noise σ_w
(per sample) and an angle random walk N, fitted to two statistics of every window — the
scatter of its first differences (white noise mostly) and the scatter of its `batches`
batch slopes about a linear trend (a smooth change of the rate within the window, e.g. the
scale-factor ripple while the pattern turns, is systematic, not noise) — by weighted least
squares on their expectations; N enters only where the data show it (`RANDOM_WALK_Z`). Each
window's error is then the exact least-squares slope error of its samples under that model
([`slope_variance`][hrgjax.pattern_noise.slope_variance]). The batch scatter alone (earlier
versions) is right for a random walk but counts white angle noise `batches` times over (4.2×
on 60-s runs of 1″ noise); on Monte Carlo sets of 200 windows both are now within 3 % of the
slopes' scatter, and on 20 windows within 10 %. Where the walk's share of a window's error is
comparable to the white noise's (it hardly shows in the batch scatter) the error can be low
by up to ≈ 20 %; a single window (one static run reduced alone) leaves the model noisy.
Noise correlated over much longer than a window (a Gauss–Markov bias with a 10-min
correlation time) acts as a slowly varying offset and shows up as scatter between runs.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..data import MeasuredData
from ..pattern_noise import slope_variance
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
      of `n_windows`; the samples of a window equally spaced.
    - `n_windows`: number of windows.
    - `batches`: if ≥ 3, also return the standard errors of each window's slope (module
      docstring: white angle noise and a random walk fitted to all the windows together).

    **Returns:** `(slope, t_mid, theta_mean)` each of shape (n_windows,), plus `stderr`
    [unit of `theta` per s] when `batches ≥ 3`.
    """
    out = _window_stats(jnp, t, theta, n_windows, batches)
    if batches < 3:
        return out
    slope, tm, ym, stats = out
    return slope, tm, ym, slope_errors(jnp, [stats])


def _window_stats(xp, t, theta, n_windows, batches):
    n = t.shape[0] // n_windows
    if n * n_windows != t.shape[0]:
        raise ValueError(f"{t.shape[0]} samples do not split into {n_windows} equal windows")
    tw = t.reshape(n_windows, n)
    yw = theta.reshape(n_windows, n)
    slope, tm, ym = least_squares_slope(xp, tw, yw)
    if batches < 3:
        return slope, tm, ym
    return slope, tm, ym, _noise_statistics(xp, tw, yw, batches)


def _noise_statistics(xp, tw, yw, batches: int) -> dict:
    """Two quadratic statistics of each window's angles (rows of `tw`, `yw`: n equally spaced
    samples) and the coefficients of their expectations in (σ_w², N²), white angle noise
    [angle² per sample] and the random walk's density [angle²/s]:

    - `a`: the first differences' squares about a straight line in sample number (a rate
      changing linearly is not noise); E = a_w σ_w² + a_r N², a_w = tr(P D Dᵀ), a_r = Δt(m−2);
    - `q`: the batch slopes' squares about a straight line in batch number (the batch means
      of earlier versions); E = (B − 2)(v_w σ_w² + v_r N²), v the variance of one batch's
      least-squares slope ([`slope_variance`][hrgjax.pattern_noise.slope_variance]).
    """
    n = tw.shape[-1]
    dt = (tw[:, -1] - tw[:, 0]) / (n - 1)
    m = n - 1
    d = xp.diff(yw, axis=-1)
    i = xp.arange(m, dtype=d.dtype) - (m - 1) / 2
    s2 = m * (m**2 - 1) / 12.0
    i = i[None, :]
    r = d - xp.mean(d, axis=-1, keepdims=True) - xp.sum(d * i, axis=-1, keepdims=True) / s2 * i
    a_w = 2.0 * m - 2.0 / m - (2.0 * ((m - 1) / 2) ** 2 + (m - 1)) / s2
    nb = n // batches
    tb = tw[:, : nb * batches].reshape(-1, batches, nb)
    yb = yw[:, : nb * batches].reshape(-1, batches, nb)
    sb, _, _ = least_squares_slope(xp, tb, yb)
    # A smooth change of rate within the window (the scale-factor ripple as the pattern turns)
    # is systematic, not noise: remove a linear trend over the batches before the scatter.
    idx = xp.broadcast_to(xp.arange(batches, dtype=sb.dtype), sb.shape)
    trend, _, mean = least_squares_slope(xp, idx, sb)
    resid = sb - mean[..., None] - trend[..., None] * (idx - (batches - 1) / 2)
    ones = xp.ones_like(dt)
    return {
        "n": n * ones,
        "dt": dt,
        "a": xp.sum(r * r, axis=-1),
        "a_w": a_w * ones,
        "a_r": dt * (m - 2),
        "a_dof": 2.0 * (m - 2) / 3.0 * ones,  # first differences of white noise: MA(1)
        "q": xp.sum(resid**2, axis=-1),
        "q_w": (batches - 2) * slope_variance(1.0, 0.0, nb, dt),
        "q_r": (batches - 2) * slope_variance(0.0, 1.0, nb, dt),
        "q_dof": (batches - 2.0) * ones,
    }


RANDOM_WALK_Z = 1.0
"""Significance (in σ of its own estimate) a random walk's fitted density must reach to
enter the standard errors; below it the windows' scatter is white angle noise alone. A
density consistent with zero would add the fluctuation of the batch slopes (several times
the white-noise error) to every window; a higher bar would miss a walk whose share of a
window's error is comparable to the white noise's. 1σ balances the two (module docstring)."""


def slope_errors(xp, stats: list[dict], iterations: int = 3):
    """Standard error of each window's least-squares slope [angle/s] under white angle noise
    σ_w and an angle random walk N fitted to the statistics of every window
    (`_noise_statistics`) together: weighted least squares on their expectations, each
    statistic weighted by its degrees of freedom over its expectation², `iterations` times;
    σ_w², N² ≥ 0, and N² = 0 unless `RANDOM_WALK_Z` σ from zero. Traceable."""
    st = {k: xp.concatenate([s[k] for s in stats]) for k in stats[0]}
    y = xp.concatenate([st["a"], st["q"]])
    cw = xp.concatenate([st["a_w"], st["q_w"]])
    cr = xp.concatenate([st["a_r"], st["q_r"]])
    dof = xp.concatenate([st["a_dof"], st["q_dof"]])
    # each statistic divided by its size were all of A white noise plus all of A a walk
    # (an equation and its coefficients scaled alike: the same fit, and every term O(≤ 1))
    a_sum = xp.sum(st["a"])
    noisy = a_sum > 0.0
    a_sum = xp.where(noisy, a_sum, 1.0)
    norm = cw * a_sum / xp.sum(st["a_w"]) + cr * a_sum / xp.sum(st["a_r"])
    y, cw, cr = y / norm, cw / norm, cr / norm
    weight = dof / (y * y + 1e-12)  # a first pass weighted by the statistics themselves

    def solve(weight):
        sww, swr, srr = (xp.sum(weight * u * v) for u, v in ((cw, cw), (cw, cr), (cr, cr)))
        yw, yr = xp.sum(weight * cw * y), xp.sum(weight * cr * y)
        det = sww * srr - swr * swr
        good = det > 1e-12 * sww * srr
        det = xp.where(good, det, 1.0)
        both_w = (srr * yw - swr * yr) / det
        both_r = (sww * yr - swr * yw) / det
        # Var(statistic) = 2 E² / dof = 2 / weight: Cov(σ_w², N²) = 2 (CᵀWC)⁻¹
        walk = good & (both_r > RANDOM_WALK_Z * xp.sqrt(2.0 * sww / det))
        only_w = xp.maximum(yw / sww, 0.0)
        only_r = xp.maximum(yr / srr, 0.0)
        w2 = xp.where(walk, xp.where(both_w >= 0.0, both_w, 0.0), only_w)
        r2 = xp.where(walk, xp.where(both_w >= 0.0, both_r, only_r), 0.0)
        return w2, r2

    for _ in range(iterations):
        w2, r2 = solve(weight)
        expect = cw * w2 + cr * r2
        weight = dof / (expect * expect + 1e-12)
    w2, r2 = solve(weight)
    w2, r2 = (xp.where(noisy, v, 0.0) for v in (w2, r2))
    return xp.sqrt(slope_variance(xp.sqrt(w2), xp.sqrt(r2), st["n"], st["dt"]))


def _table_rates(t, table_angle, rate, n_windows: int) -> np.ndarray:
    """Table rate of each of `n_windows` equal windows [°/s]: the least-squares slope of the
    table angle [°] over the window's samples, the estimator (and weights) of the measured
    rate, so a rate that changes within the window (a spin-up, an oscillating table) is
    compared with the same average of it; exactly 0 where the rate is 0 throughout."""
    tw, aw = t.reshape(n_windows, -1), table_angle.reshape(n_windows, -1)
    slope = least_squares_slope(np, tw, aw)[0]
    at_rest = np.all(rate.reshape(n_windows, -1) == 0.0, axis=1)
    return np.where(at_rest, 0.0, slope)


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
    - `t_mid`: mean time of the window [s]; `duration`: its length [s].
    - `temperature_c`: window mean.
    - `table_rate_dps`: least-squares slope of the table angle over the window [°/s] (the
      column `table_angle_deg`, or the rate's integral), the same estimator as `rate_dps`;
      exactly 0 where the table rate is 0 throughout the window.
    - `wave_angle_deg`: mean measured wave angle over the window.
    - `rate_dps`: measured equivalent input rate −(dθ/dt)/k_e,nom.
    - `stderr_dps`: standard error of `rate_dps` (module docstring: one noise model fitted to
      every window).
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

    @property
    def static(self) -> np.ndarray:
        """Mask of windows with the table at rest."""
        return self.table_rate_dps == 0.0

    @property
    def drift_dph(self) -> np.ndarray:
        """Measured rate minus table rate [°/h] (the drift on static windows)."""
        return (self.rate_dps - self.table_rate_dps) * 3600.0

    def select(self, mask) -> RateWindows:
        """The windows where `mask` is true."""
        mask = np.asarray(mask, bool)
        return jax.tree_util.tree_map(lambda x: np.asarray(x)[mask], self)

    def __len__(self) -> int:
        return int(np.asarray(self.run).shape[0])


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


def _window_layout(
    r: MeasuredData, window_s: float | None, ramp_window_s: float | None = None
) -> tuple[int, int]:
    """(number of windows, samples per window) of one run; a static run is one window (a ramp
    — at rest, temperature moving — windows of `ramp_window_s` when given) and samples past
    the last whole window are left out of the windows (not of the data)."""
    t = r["time_s"]
    if len(t) < 4:
        raise ValueError(
            f"run {int(r.run[0])} has {len(t)} samples; reduction needs at least 4 per window"
        )
    if bool(np.all(r["table_rate_dps"] == 0.0)):
        if ramp_window_s is None or np.ptp(r["temperature_c"]) == 0.0:
            return 1, len(t)
        window_s = ramp_window_s
    elif window_s is None:
        return 1, len(t)
    n = max(int(round(window_s / float(np.median(np.diff(t))))), 4)
    n_win = len(t) // n
    return (1, len(t)) if n_win == 0 else (n_win, n)


def check_whole_angle(data: MeasuredData) -> None:
    """Refuse data a whole-angle calibration cannot read: force-to-rebalance output (the wave
    held; a `rebalance_rate_dps` column) or runs with a commanded precession (the wave turned
    by a force, not by the case; nonzero `precession_dps`) — `hrgjax self-calibrate` reads
    those."""
    if "rebalance_rate_dps" in data:
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
    - `batches`: batch count for the standard errors (≥ 3).
    - `ramp_window_s`: window length for ramps — runs at rest whose temperature moves [s]
      (e.g. `RAMP_WINDOW_S`, 300 s); `None` (default) keeps each ramp one window,
      as every static run.

    **Returns:** [`RateWindows`][hrgjax.calibration.RateWindows].

    **Raises:** `ValueError` for `k_e` outside (0, 1], `batches < 3`, `window_s ≤ 0`, a run
    too short, or
    force-to-rebalance or virtual-precession data
    ([`check_whole_angle`][hrgjax.calibration.reduce.check_whole_angle]).
    """
    check_k_e(k_e)
    check_whole_angle(data)
    if batches < 3:
        raise ValueError(f"batches must be ≥ 3 for a standard error; got {batches}")
    for name, value in (("window_s", window_s), ("ramp_window_s", ramp_window_s)):
        if value is not None and not value > 0:
            raise ValueError(f"{name} must be a positive number of seconds or None; got {value}")
    cols: dict[str, list] = {k: [] for k in RateWindows.__dataclass_fields__ if k != "k_e"}
    noise: list[dict] = []
    for r in data.runs():
        t, th = r["time_s"], r["wave_angle_deg"]
        temp, rate = r["temperature_c"], r["table_rate_dps"]
        n_win, n = _window_layout(r, window_s, ramp_window_s)
        nb = min(batches, n // 2)
        if nb < 3:
            raise ValueError(f"run {int(r.run[0])}: windows of {n} samples are too short")
        m = n_win * n
        slope, tm, ym, stats = _window_stats(np, t[:m], th[:m], n_win, nb)
        noise.append(stats)
        starts = np.arange(n_win) * n
        cols["run"].append(np.full(n_win, int(r.run[0])))
        cols["start"].append(starts)
        cols["stop"].append(starts + n)
        cols["t_mid"].append(tm)
        cols["duration"].append(t[starts + n - 1] - t[starts])
        cols["temperature_c"].append(temp[:m].reshape(n_win, n).mean(axis=1))
        cols["table_rate_dps"].append(_table_rates(t[:m], r.table_angle_deg[:m], rate[:m], n_win))
        cols["wave_angle_deg"].append(ym)
        cols["rate_dps"].append(-slope / k_e)
        cols["temperature_rate_cps"].append(least_squares_slope(np, t[:m].reshape(n_win, n),
                                                   temp[:m].reshape(n_win, n))[0])  # fmt: skip
    cols["stderr_dps"] = [slope_errors(np, noise) / k_e]  # one noise model: every window's
    arrays = {k: np.concatenate(v) for k, v in cols.items()}
    return RateWindows(**arrays, k_e=float(k_e))


def static_drift(data: MeasuredData, k_e: float = K_E_NOMINAL):
    """Drift of each static run as equivalent input rate [°/h]: −(wave-angle slope)/k_e minus
    the table rate; with the run's temperature [°C] and mean wave angle [°].

    **Returns:** dict of arrays `temperature_c`, `wave_angle_deg`, `drift_dph`,
    `stderr_dph`, `run`.
    """
    w = reduce(data, k_e, window_s=None)
    w = w.select(w.static)
    return {
        "temperature_c": w.temperature_c,
        "wave_angle_deg": w.wave_angle_deg,
        "drift_dph": w.drift_dph,
        "stderr_dph": w.stderr_dps * 3600.0,
        "run": w.run,
    }


def scale_factor_vs_angle(
    data: MeasuredData, k_e: float = K_E_NOMINAL, window_s: float = 2.0, bin_deg: float = 10.0
):
    """Local scale factor of rotation runs vs wave angle (folded to [−90°, 90°)), binned.

    SF = (Δθ_meas/Δt)/(−k_e Ω_table) over windows of `window_s`, relative to its run mean.

    **Returns:** dict `temperature_c` (T,), `wave_angle_deg` (B,), `scale_factor` (T, B):
    one row per temperature (runs' mean temperatures grouped by
    [`group_temperatures`][hrgjax.units.group_temperatures]).
    """
    temps = []
    rows = []
    edges = np.arange(-90.0, 90.0 + bin_deg / 2, bin_deg)
    centres = 0.5 * (edges[1:] + edges[:-1])
    run_temps, run_parts = [], []
    for r in data.runs():
        w = r["table_rate_dps"]
        if np.all(w == 0):
            continue
        t, th = r["time_s"], r["wave_angle_deg"]
        step = max(int(round(window_s / np.median(np.diff(t)))), 1)
        sf = (th[step:] - th[:-step]) / (t[step:] - t[:-step]) / (-k_e * w[step:])
        mid = 0.5 * (th[step:] + th[:-step])
        folded = (mid + 90.0) % 180.0 - 90.0
        run_temps.append(float(np.mean(r["temperature_c"])))
        run_parts.append((folded, sf / np.mean(sf)))
    by_temp: dict[float, list] = {}  # one row per temperature, last-bit differences merged
    for temp, part in zip(group_temperatures(run_temps), run_parts, strict=True):
        by_temp.setdefault(float(temp), []).append(part)
    for temp, parts in sorted(by_temp.items()):
        ang = np.concatenate([p[0] for p in parts])
        sf = np.concatenate([p[1] for p in parts])
        idx = np.digitize(ang, edges) - 1
        rows.append(
            [np.mean(sf[idx == b]) if np.any(idx == b) else np.nan for b in range(len(centres))]
        )
        temps.append(temp)
    return {
        "temperature_c": np.asarray(temps),
        "wave_angle_deg": centres,
        "scale_factor": np.asarray(rows),
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
