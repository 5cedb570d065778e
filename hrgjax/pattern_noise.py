r"""The noise on a whole-angle gyro's measured *pattern* (electrical) wave angle: white angle
noise, angle random walk, a first-order Gauss–Markov rate and a run-to-run bias — one model,
[`NoiseModel`][hrgjax.pattern_noise.NoiseModel], for the calibration's bench design and the
discovery's search alike.

Everything is in pattern-angle units (electrical): σ_w [rad], N [rad/√s], σ_GM [rad/s],
T_c [s], σ_b [rad/s]. A known gyro's [`hrgjax.Noise`][] (equivalent input rate) gives it
through [`NoiseModel.from_gyro`][hrgjax.pattern_noise.NoiseModel.from_gyro] (the rate parts
× the angular gain k_e); measured data give it through
[`NoiseModel.estimate`][hrgjax.pattern_noise.NoiseModel.estimate], which reads every stretch
of a log where the table is still and the temperature holds (the static dwells of a bench
grid, the holds of a continuous record, both in a mixed log). Its second moments:

- the **least-squares slope** of a window of samples
  ([`slope_sigma`][hrgjax.pattern_noise.NoiseModel.slope_sigma]; for n equally spaced samples
  without the Gauss–Markov part, the closed form
  [`slope_variance`][hrgjax.pattern_noise.slope_variance]);
- the **mean of the Gauss–Markov rate** over a segment
  ([`gauss_markov_mean_variance`][hrgjax.pattern_noise.gauss_markov_mean_variance]);
- the **block increments** of continuous records
  ([`increment_covariance`][hrgjax.pattern_noise.NoiseModel.increment_covariance]);
- the **lag-τ second differences** the estimator fits
  ([`d2_variance`][hrgjax.pattern_noise.NoiseModel.d2_variance]).

The module-level closed forms are arithmetic (and `expm1`) on their arguments: NumPy floats
give NumPy floats, (traced) JAX arrays give JAX arrays — the bench design's Fisher
information uses them under `jax.jit` and `jax.grad`.

Angle covariance under the model (times from a stretch's start, $s, t \ge 0$):

$$C(s,t) = \sigma_w^2\delta_{st} + N^2\min(s,t)
  + \sigma^2T_c\bigl[s + t - |s-t| - T_c(1 - e^{-s/T_c} - e^{-t/T_c} + e^{-|s-t|/T_c})\bigr].$$
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import (
    FINITE_NONNEGATIVE,
    FINITE_POSITIVE,
    check_1d,
    check_numbers,
    check_values,
    finite_number,
    whole_number,
)
from ._nnls import nnls as _nnls
from .units import DEG, DEG_PER_H
from .units import STILL_RATE_DPS as STILL_RATE_DPS

if TYPE_CHECKING:
    from .data import MeasuredData

GM_TIMES = (30.0, 100.0, 300.0, 1000.0, 3000.0)
"""Correlation times tried for the Gauss–Markov part of the noise model [s]."""
MIN_STRETCH = 16
"""Fewest samples of a still stretch that the estimator uses."""
TEMPERATURE_TOLERANCE_C = 0.1
"""A still stretch's temperature stays within this of its first sample [°C] (a measured
temperature's sensor noise does not cut a static dwell into pieces; a ramp does)."""


@dataclasses.dataclass(frozen=True)
class NoiseModel:
    """The noise of a whole-angle gyro's measured wave angle, in pattern-angle units.

    **Fields:** `angle_white` σ_w [rad per sample], `angle_random_walk` N [rad/√s],
    `gm_sigma` σ_GM [rad/s] and `gm_time` T_c [s] of a Gauss–Markov rate, `run_bias` σ_b
    [rad/s] (spread of a constant rate per switch-on). All electrical pattern angle: divide
    rates by the angular gain k_e for input rate
    ([`from_gyro`][hrgjax.pattern_noise.NoiseModel.from_gyro] multiplies a gyro's by it).
    """

    angle_white: float
    angle_random_walk: float = 0.0
    gm_sigma: float = 0.0
    gm_time: float = 100.0
    run_bias: float = 0.0

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            ok = isinstance(v, (int, float)) and not isinstance(v, bool)  # True read as 1
            if not (ok and math.isfinite(v) and v >= 0):
                raise ValueError(f"NoiseModel.{f.name} must be a finite number ≥ 0; got {v!r}")
        if self.gm_time <= 0:
            raise ValueError(f"NoiseModel.gm_time must be > 0 [s]; got {self.gm_time!r}")

    def replace(self, **changes) -> NoiseModel:
        """A copy with `changes` (this one is left as it is)."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_gyro(cls, noise, k_e: float) -> NoiseModel:
        """The model of a known [`hrgjax.Noise`][]: its equivalent-input-rate parts scaled by
        the angular gain `k_e` to pattern-angle units (σ_w as it is: it is already on the
        measured angle; `amplitude_white` is not part of the angle's noise). The one
        conversion: the bench design's noise (`calibration.design.pattern_arw`, …) and the
        discovery's known noise both read it."""
        from .noise import Noise

        if not isinstance(noise, Noise):  # was an AttributeError
            raise TypeError(f"noise must be an hrgjax.Noise; got {type(noise).__name__}")
        k_e = _gain("from_gyro: k_e", k_e)
        return cls(
            angle_white=float(noise.angle_white),
            angle_random_walk=k_e * float(noise.angle_random_walk),
            gm_sigma=k_e * float(noise.bias_instability),
            gm_time=float(noise.correlation_time),
            run_bias=k_e * float(noise.run_bias),
        )

    # -- second moments -------------------------------------------------------
    def angle_covariance(self, t) -> np.ndarray:
        """Covariance (n, n) [rad²] of the measured angle at times `t` [s] of one stretch
        (white + ARW + Gauss–Markov; the run bias is a constant rate, left to the fits)."""
        t = _times("angle_covariance: t", t, 1)
        s = t - t[0]
        a, b = s[:, None], s[None, :]
        cov = self.angle_white**2 * np.eye(s.size) + self.angle_random_walk**2 * np.minimum(a, b)
        if self.gm_sigma > 0:
            tc = self.gm_time
            d = np.abs(a - b)
            cov = cov + self.gm_sigma**2 * tc * (
                a + b - d - tc * (1 - np.exp(-a / tc) - np.exp(-b / tc) + np.exp(-d / tc))
            )
        return cov

    def slope_sigma(self, t) -> float:
        """Standard error [rad/s] of the least-squares slope of the angle sampled at `t` [s]:
        $\\sqrt{w^\\top C w}$ with $w = (t-\\bar t)/\\sum(t-\\bar t)^2$ — exact for every part
        (for n equally spaced samples the white and walk parts are
        [`slope_variance`][hrgjax.pattern_noise.slope_variance]; for dense samples σ_w²·12/(nT²)
        and 6N²/5T)."""
        t = _times("slope_sigma: t", t, 2)
        w = (t - t.mean()) / np.sum((t - t.mean()) ** 2)
        # white and walk in O(n): the walk is a sum of independent increments, each weighted
        # by the slope weights of the samples after it
        tail = np.cumsum(w[::-1])[::-1][1:]
        var = self.angle_white**2 * np.sum(w**2)
        var += self.angle_random_walk**2 * np.sum(np.diff(t) * tail**2)
        if self.gm_sigma > 0:
            gm = self.replace(angle_white=0.0, angle_random_walk=0.0).angle_covariance(t)
            var += float(w @ gm @ w)
        return float(np.sqrt(var))

    def increment_covariance(self, delta: float, k: int) -> np.ndarray:
        """Covariance (K, K) [rad²] of K consecutive block increments of length `delta` [s]
        (the whitening of the discovery's continuous records,
        [`ContinuousProblem`][hrgjax.discovery.continuous.ContinuousProblem]), the run bias
        included (each run its own switch-on)."""
        delta = check_values(
            "increment_covariance: delta", delta, FINITE_POSITIVE, "a block length > 0 [s]"
        )
        k = whole_number("increment_covariance: k", k, "a whole number of increments ≥ 1")
        if k < 1:  # 1.5 was read as 2, 0 gave an empty matrix
            raise ValueError(f"increment_covariance: k must be a whole number of increments ≥ 1; "
                             f"got {k}")  # fmt: skip
        lag = np.abs(np.subtract.outer(np.arange(k), np.arange(k)))
        cov = self.angle_white**2 * np.where(lag == 0, 2.0, np.where(lag == 1, -1.0, 0.0))
        cov = cov + np.where(lag == 0, self.angle_random_walk**2 * delta, 0.0)
        if self.gm_sigma > 0:
            sigma, tc = self.gm_sigma, self.gm_time
            one_minus_e = -math.expm1(-delta / tc)
            off = sigma**2 * tc**2 * one_minus_e**2 * np.exp(-(np.maximum(lag, 1) - 1) * delta / tc)
            diag = sigma**2 * gm_structure(delta, tc)  # accurate where Δ ≪ T_c
            cov = cov + np.where(lag == 0, diag, off)
        return cov + self.run_bias**2 * delta**2

    def d2_variance(self, tau):
        """Variance [rad²] of the lag-τ second difference θ(t+τ) − 2θ(t) + θ(t−τ)."""
        tau = check_values("d2_variance: tau", tau, FINITE_NONNEGATIVE, "lags >= 0 [s]")
        return _d2_basis(np.asarray(tau, float), self.gm_time) @ np.array(
            [self.angle_white**2, self.angle_random_walk**2, self.gm_sigma**2]
        )

    def gauss_markov_mean_variance(self, duration):
        """Variance [rad²/s²] of the Gauss–Markov rate's mean over `duration` [s]
        ([`gauss_markov_mean_variance`][hrgjax.pattern_noise.gauss_markov_mean_variance] of
        this model's σ_GM, T_c)."""
        return gauss_markov_mean_variance(self.gm_sigma, self.gm_time, duration)

    def report(self, k_e: float) -> dict:
        """The model in report units (equivalent input rate: divided by `k_e`)."""
        k_e = _gain("report: k_e", k_e)  # 0: ZeroDivisionError, < 0: negative noise
        return {
            "angle_white_arcsec": self.angle_white / DEG * 3600,
            "angle_random_walk_dph_per_sqrt_h": self.angle_random_walk / k_e / DEG * 60,
            "gauss_markov_dph": self.gm_sigma / k_e / DEG_PER_H,
            "gauss_markov_time_s": self.gm_time,
            "run_bias_dph": self.run_bias / k_e / DEG_PER_H,
        }

    # -- estimation -------------------------------------------------------------
    @classmethod
    def estimate(cls, data: MeasuredData, max_lag_s: float = 1024.0) -> NoiseModel:
        r"""Estimate σ_w, N and a Gauss–Markov part from every still stretch of `data` (table
        still within [`STILL_RATE_DPS`][hrgjax.units.STILL_RATE_DPS], temperature within
        [`TEMPERATURE_TOLERANCE_C`][hrgjax.pattern_noise.TEMPERATURE_TOLERANCE_C], ≥
        [`MIN_STRETCH`][hrgjax.pattern_noise.MIN_STRETCH] samples): static dwells and the
        holds of continuous records alike.

        Lag-τ second differences remove a stretch's angle and drift rate; they are taken on
        the samples' true times (three samples t − a, t, t + b weighted so that the drift
        cancels for any a, b, each term's variance from its own spans), so a gap in the
        samples or uneven stamps leave no drift in them. Their mean square, pooled over
        stretches per lag (τ = 1, 2, 4, … samples of the stretch's median step, up to
        `max_lag_s` and a quarter of the stretch), is fitted against the terms' mean variance
        columns by non-negative least squares with relative
        errors set by each lag's number of roughly independent terms (iterated on the model,
        so the weights do not follow the noise of the estimates). The Gauss–Markov part is
        kept only where it earns its two parameters (χ² drop > 2 ln n, the correlation times
        of [`GM_TIMES`][hrgjax.pattern_noise.GM_TIMES] up to 4× the longest lag): short
        dwells cannot tell it from the angle random walk, and then it is left out.

        **Returns:** the model (`run_bias` 0: it needs fitted run means).

        **Raises:** `ValueError` when `data` has no still stretch or `max_lag_s` is not > 0,
        `TypeError` when `data` is not a `MeasuredData`.
        """
        return cls._from_stretches("estimate", data, max_lag_s, TEMPERATURE_TOLERANCE_C)

    @classmethod
    def estimate_drifting(cls, data: MeasuredData, max_lag_s: float = 256.0) -> NoiseModel:
        r"""Estimate the model as [`estimate`][hrgjax.pattern_noise.NoiseModel.estimate]
        does, from every stretch where the table is still **whatever the temperature does**
        (a chamber that ramps without a hold), for logs with no still stretch. Along a ramp
        the drift rate moves with the temperature, and a drift rate that changes at R
        [rad/s²] adds R·a·b to a second difference over spans a, b: a column (a·b)² is
        fitted beside the noise's and dropped (its R² is the ramp's curvature, not noise).
        A term whose three samples straddle a turn of the ramp (the temperature's own
        second difference beyond [`TEMPERATURE_TOLERANCE_C`][hrgjax.pattern_noise.TEMPERATURE_TOLERANCE_C])
        is left out: no column fits that kink. Lags stop at `max_lag_s` [s] (default 256 s)
        or where no term is left. Figures: `benchmarks/noise_drifting.py`.

        **Raises:** as `estimate`, `ValueError` when no stretch has the table still."""
        return cls._from_stretches("estimate_drifting", data, max_lag_s, math.inf)

    @classmethod
    def _from_stretches(cls, owner, data, max_lag_s, tolerance_c) -> NoiseModel:
        """The estimate over the stretches with the table still and the temperature within
        `tolerance_c` [°C] of their first sample (`math.inf`: any, with the rate-ramp column
        of `estimate_drifting`)."""
        from .data import MeasuredData

        if not isinstance(data, MeasuredData):  # was an AttributeError
            raise TypeError(f"data must be an hrgjax.MeasuredData; got {type(data).__name__}")
        max_lag_s = finite_number("max_lag_s", max_lag_s, "s")
        if max_lag_s <= 0:  # read as "no still stretch"
            raise ValueError(f"max_lag_s must be > 0 [s]; got {max_lag_s}")
        ramp = math.isinf(tolerance_c)
        sums: dict[float, np.ndarray] = {}
        for idx in data.run_indices():
            time = data["time_s"][idx]
            rate, temp = data["table_rate_dps"][idx], data["temperature_c"][idx]
            for a, b in _still_stretches(rate, temp, tolerance_c):
                th = data["wave_angle_deg"][idx][a:b] * DEG
                t = time[a:b]
                dt = float(np.median(np.diff(t)))
                k = 1
                while k * dt <= max_lag_s and k <= (b - a) // 4:
                    d2, coef = _d2_terms(t, th, k)
                    if ramp:  # the drift rate's change along the stretch: R²(a·b)²
                        spans = (t[k:-k] - t[: -2 * k]) * (t[2 * k :] - t[k:-k])
                        coef = np.concatenate([coef, spans[:, None] ** 2], axis=1)
                        # only where the temperature is a straight line across the three
                        # samples (its own second difference within the tolerance): a
                        # turn of the ramp inside them is a kink no column fits
                        bent = np.abs(_d2_terms(t, temp[a:b], k)[0]) > TEMPERATURE_TOLERANCE_C
                        d2, coef = d2[~bent], coef[~bent]
                        if not d2.size:
                            break
                    acc = sums.setdefault(float(f"{k * dt:.9g}"), np.zeros(3 + coef.shape[1]))
                    acc[0] += float(np.sum(d2**2))
                    acc[1] += d2.size
                    acc[2] += d2.size / (1.0 + k)  # roughly independent terms
                    acc[3:] += coef.sum(axis=0)
                    k *= 2
        if not sums:
            held = f" and the temperature constant within {tolerance_c} °C" if not ramp else ""
            raise ValueError(
                f"{owner}: the noise model needs a stretch of at least {MIN_STRETCH} samples "
                f"with the table still (|table_rate_dps| ≤ {STILL_RATE_DPS}{held}), e.g. a "
                "static run; or pass noise=hrgjax.Noise(...)"
            )
        taus = np.asarray(sorted(sums))
        acc = np.asarray([sums[t] for t in taus])
        var, n_eff = acc[:, 0] / acc[:, 1], acc[:, 2]
        basis = acc[:, 3:] / acc[:, 1:2]  # the terms' mean (σ_w², N², σ_GM²(T_c)…) columns
        extra = [basis.shape[1] - 1] if ramp else []  # the ramp column, fitted and dropped
        fits = [_fit_d2(basis[:, [0, 1, *extra]], var, n_eff, None)]
        fits += [
            _fit_d2(basis[:, [0, 1, 2 + i, *extra]], var, n_eff, tc)
            for i, tc in enumerate(GM_TIMES)
            if tc <= 4 * taus[-1]
        ]
        best = min(fits[1:], key=lambda f: f[0], default=None)
        chosen = fits[0]
        if best is not None and best[2] > 0 and fits[0][0] - best[0] > 2 * math.log(n_eff.sum()):
            chosen = best
        chi2, coef, tc = chosen
        return cls(
            angle_white=float(np.sqrt(coef[0])),
            angle_random_walk=float(np.sqrt(coef[1])),
            gm_sigma=float(np.sqrt(coef[2])),
            gm_time=float(tc) if tc is not None else cls.gm_time,
        )


def slope_variance(angle_white, angle_random_walk, samples, dt):
    r"""Variance [rad²/s²] of the least-squares slope of n = `samples` equally spaced samples
    (interval Δt = `dt` [s]) of the angle under white angle noise σ_w = `angle_white` [rad per
    sample] and a random walk of density N = `angle_random_walk` [rad/√s]:

    $$\frac{6(n^2+1)}{5n(n^2-1)}\frac{N^2}{\Delta t} + \frac{12\,\sigma_w^2}{\Delta t^2 n(n^2-1)},$$

    exact (the closed form of
    [`NoiseModel.slope_sigma`][hrgjax.pattern_noise.NoiseModel.slope_sigma]² of such samples
    without the Gauss–Markov part; → 6/5 of a mean rate's N²/(nΔt) for long windows). Arithmetic only: NumPy floats or (traced) JAX arrays, `samples` need not be a
    whole number (the bench design's windows)."""
    at = "slope_variance: "
    angle_white = check_values(at + "angle_white", angle_white, FINITE_NONNEGATIVE,
                       "a standard deviation >= 0 [rad]")  # fmt: skip
    angle_random_walk = check_values(at + "angle_random_walk", angle_random_walk, FINITE_NONNEGATIVE,
                             "a density >= 0 [rad/√s]")  # fmt: skip
    samples = check_values(
        at + "samples", samples, lambda v: np.isfinite(v) & (v > 1), "a count > 1"
    )
    dt = check_values(
        at + "dt", dt, FINITE_POSITIVE, "a sample interval > 0 [s]"
    )  # < 0: a negative variance
    n = samples
    m = n * (n**2 - 1.0)
    walk = 6.0 * (n**2 + 1.0) / (5.0 * m) * angle_random_walk**2 / dt
    white = 12.0 * angle_white**2 / (dt**2 * m)
    return walk + white


def gauss_markov_mean_factor(x):
    """1 − (1 − e^(−x))/x, written with `expm1` (accurate for short segments): the variance of
    a Gauss–Markov rate's mean over a duration D = x T_c in units of 2σ²T_c/D
    ([`gauss_markov_mean_variance`][hrgjax.pattern_noise.gauss_markov_mean_variance]). NumPy
    or (traced) JAX."""
    x = check_values("gauss_markov_mean_factor: x", x, FINITE_NONNEGATIVE,
             "a duration over a correlation time, >= 0")  # fmt: skip
    xp = jnp if isinstance(x, jax.Array) else np
    return 1.0 + xp.expm1(-x) / x


def gauss_markov_mean_variance(sigma, correlation_time, duration):
    """Variance [rad²/s²] of the mean over `duration` D [s] of a stationary first-order
    Gauss–Markov rate of σ = `sigma` [rad/s] and correlation time τ = `correlation_time` [s]:
    2σ²τ/D · (1 − (τ/D)(1 − e^(−D/τ))) — the Gauss–Markov part of
    [`NoiseModel.angle_covariance`][hrgjax.pattern_noise.NoiseModel.angle_covariance] at (D, D)
    over D². NumPy or (traced) JAX."""
    at = "gauss_markov_mean_variance: "
    sigma = check_values(
        at + "sigma", sigma, FINITE_NONNEGATIVE, "a standard deviation >= 0 [rad/s]"
    )
    correlation_time = check_values(
        at + "correlation_time", correlation_time, FINITE_POSITIVE, "> 0 [s]"
    )
    duration = check_values(
        at + "duration", duration, FINITE_POSITIVE, "> 0 [s]"
    )  # < 0: wrong, 0: 1/0
    x = duration / correlation_time
    return 2.0 * sigma**2 * correlation_time / duration * gauss_markov_mean_factor(x)


def _gain(name: str, k_e) -> float:
    """The angular gain k_e as a float > 0, else one line naming `name`."""
    k_e = finite_number(name, k_e, "-")
    if k_e <= 0:
        raise ValueError(f"{name} must be the angular gain, > 0; got {k_e}")
    return k_e


def _times(name: str, t, least: int) -> np.ndarray:
    """Sample times `t` [s] of one stretch as a float array: 1-D, finite, not decreasing, at
    least `least` of them (and for `least` 2, two distinct), else one line naming `name`."""
    check_numbers(name, t, "sample times [s], 1-D")
    check_1d(name, t, "sample times [s]")
    t = np.asarray(t, dtype=float)
    if t.size < least or (least > 1 and np.ptp(t) == 0):  # 1 sample: a NaN slope σ
        raise ValueError(f"{name} must hold at least {least} distinct sample times; got {t.size}")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):  # backwards: a wrong covariance
        raise ValueError(
            f"{name} must be finite sample times [s] that do not decrease; got "
            f"{t[~np.isfinite(t)][0] if not np.all(np.isfinite(t)) else 'a decrease'}"
        )
    return t


def longest_still_s(data: MeasuredData) -> float:
    """The longest stretch [s] of `data` that [`NoiseModel.estimate`][hrgjax.pattern_noise.NoiseModel.estimate]
    reads (table still, temperature held within `TEMPERATURE_TOLERANCE_C`, ≥ `MIN_STRETCH`
    samples); 0 where there is none. A ramp sampled fast leaves still stretches of a few
    seconds (0.1 °C at 1 °C/min: 6 s), too short for the lags the walk shows at."""
    longest = 0.0
    for idx in data.run_indices():
        t = data["time_s"][idx]
        for a, b in _still_stretches(data["table_rate_dps"][idx], data["temperature_c"][idx]):
            longest = max(longest, float(t[b - 1] - t[a]))
    return longest


def _still_stretches(rate_dps, temperature_c, tolerance_c=TEMPERATURE_TOLERANCE_C):
    """(start, stop) of every stretch of ≥ MIN_STRETCH samples with the table still
    (|rate| ≤ STILL_RATE_DPS) and the temperature within `tolerance_c` of the
    stretch's first sample (a sample that leaves it starts the next stretch). NumPy over
    the samples: each stretch's end is searched in blocks that double, so a log costs
    O(samples) whatever its stretches."""
    temp = np.asarray(temperature_c, dtype=float)
    still = np.abs(np.asarray(rate_dps, dtype=float)) <= STILL_RATE_DPS
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(np.int8), [0]])))
    out = []
    for lo, hi in zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True):
        start = lo
        while start < hi:
            stop, block = hi, 64
            at = start
            while at < hi:  # the first sample beyond the tolerance of temp[start]
                seg = temp[at : min(at + block, hi)]
                away = np.flatnonzero(np.abs(seg - temp[start]) > tolerance_c)
                if away.size:
                    stop = at + int(away[0])
                    break
                at, block = at + block, 2 * block
            if stop - start >= MIN_STRETCH:
                out.append((start, stop))
            start = stop
    return out


def _d2_terms(t, theta, k):
    r"""The lag-k (in samples) second differences of the angle `theta` [rad] sampled at `t`
    [s], on the samples' true times, and each term's variance columns.

    Three samples at t − a, t, t + b give D = (b θ(t−a) − (a+b) θ(t) + a θ(t+b))/h, h =
    (a+b)/2: θ(t+τ) − 2θ(t) + θ(t−τ) where a = b = τ, and a constant angle and drift rate
    cancel exactly for any a, b — a gap or uneven stamps between the samples leave no drift
    in D. Its variance under the model, −Σ_{i<j} w_i w_j S(|t_i − t_j|) over the increments'
    structure function S (N²Δ for the walk, 2σ²T_c(Δ − T_c(1 − e^{−Δ/T_c})) for the
    Gauss–Markov rate) plus σ_w² Σ w_i², has the columns (σ_w², N², σ_GM² at each T_c of
    GM_TIMES) returned as (terms, 2 + len(GM_TIMES)); equal spans give `_d2_basis`.

    **Returns:** `(d2, columns)`."""
    a = t[k:-k] - t[: -2 * k]
    b = t[2 * k :] - t[k:-k]
    h = 0.5 * (a + b)
    w1, w3 = b / h, a / h  # the middle sample's weight is −2
    d2 = w1 * theta[: -2 * k] - 2.0 * theta[k:-k] + w3 * theta[2 * k :]
    even = a.size > 0 and np.ptp(np.concatenate([a, b])) <= 1e-9 * float(np.max(a))
    if even:  # a logger's usual case: every term has the columns of one, computed once
        a, b = a[:1], b[:1]
        w1, w3 = b / (0.5 * (a + b)), a / (0.5 * (a + b))

    def pairs(s):  # −Σ_{i<j} w_i w_j S(|t_i − t_j|)
        return 2.0 * w1 * s(a) + 2.0 * w3 * s(b) - w1 * w3 * s(a + b)

    cols = [w1**2 + 4.0 + w3**2, pairs(lambda x: x)]
    cols += [pairs(lambda x, tc=tc: gm_structure(x, tc)) for tc in GM_TIMES]
    cols = np.stack(cols, axis=-1)
    return d2, np.broadcast_to(cols, (d2.size, cols.shape[1])) if even else cols


def _d2_basis(tau, tc):
    """Columns (σ_w², N², σ_GM²) of the lag-τ second difference's variance."""
    cols = [np.full_like(tau, 6.0), 2 * tau]
    if tc is None:
        cols.append(np.zeros_like(tau))
    else:  # 4S(τ) − S(2τ), the x² terms cancelling exactly in the series (x = τ/T_c)
        x = tau / tc
        series = x**3 * (2 / 3 - x / 2 + 7 * x**2 / 30 - x**3 / 12 + 31 * x**4 / 1260)
        closed = 4 * gm_structure(tau, tc) - gm_structure(2 * tau, tc)
        cols.append(np.where(x < 1e-2, 2 * tc**2 * series, closed))
    return np.stack(cols, axis=-1)


def gm_structure(delta, tc):
    """Structure function of a unit-σ first-order Gauss–Markov rate's angle [rad² per
    (rad/s)²]: E[(φ(t+Δ) − φ(t))²] = 2T_c(Δ − T_c(1 − e^{−Δ/T_c})) = 2T_c²(x + expm1(−x)),
    x = Δ/T_c — by its series where x < 1e-2, whose leading x²/2 the closed form reaches
    only through cancellation (relative error ε/x: 1e-3 of a second difference's variance
    at τ = 1 ms, T_c = 3000 s). NumPy."""
    at = "gm_structure: "
    delta = check_values(
        at + "delta", delta, FINITE_NONNEGATIVE, "a time difference >= 0 [s]"
    )  # Δ < 0: wrong
    tc = check_values(
        at + "tc", tc, FINITE_POSITIVE, "a correlation time > 0 [s]"
    )  # 0: NaN, < 0: wrong
    x = np.asarray(delta, float) / tc
    series = x**2 * (0.5 - x / 6 + x**2 / 24 - x**3 / 120 + x**4 / 720)
    return 2 * tc**2 * np.where(x < 1e-2, series, x + np.expm1(-x))


def _fit_d2(basis, var, n_eff, tc):
    """Weighted NNLS of the pooled second-difference variances on the columns `basis`
    (σ_w², N² and, with a correlation time `tc`, σ_GM²): (χ², coefficients, T_c)."""
    scale = var.copy()
    for _ in range(3):  # relative errors on the model, not on the noisy estimates
        w = np.sqrt(n_eff / 2.0) / scale
        coef = _nnls(basis * w[:, None], var * w)
        model = basis @ coef
        scale = np.where(model > 0, model, var)
    chi2 = float(np.sum(((basis @ coef - var) * w) ** 2))
    if tc is None:  # no Gauss–Markov part: its σ² is 0 (a ramp column, if any, after it)
        coef = np.insert(coef, 2, 0.0)
    return chi2, coef, tc
