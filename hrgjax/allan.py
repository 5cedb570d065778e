r"""Allan-family deviations in JAX (NIST SP 1065 definitions).

Inputs are *rate* ("frequency") samples $y_k$ at interval $\tau_0$; the phase is
$x_k = \tau_0\sum_{j<k} y_j$ ($x_0 = 0$). The averaging factor `m` is a static integer
($\tau = m\tau_0$). Checked against the NBS14 data set (PHYSICS.md §12).

IEEE 952 noise terms on an Allan-deviation plot: quantisation $\sqrt3 Q/\tau$, angle random
walk $N/\sqrt\tau$, bias instability flat at $0.6643B$, rate random walk $K\sqrt{\tau/3}$,
rate ramp $R\tau/\sqrt2$.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
from statistics import NormalDist

import jax
import jax.numpy as jnp
import numpy as np

from ._nnls import nnls as _nnls
from ._x64 import require_x64


def _phase(y, tau0):
    y = jnp.asarray(y, dtype=float)
    return jnp.concatenate([jnp.zeros(1), jnp.cumsum(y) * tau0])


def _check(y, m, needed, name):
    n = np.shape(y)[0]
    if int(m) != m or m < 1:
        raise ValueError(f"{name}: m must be a positive integer; got {m}")
    if n < needed:
        raise ValueError(f"{name}: m = {m} needs at least {needed} samples; got {n}")


def adev(y, m: int = 1, tau0: float = 1.0):
    """Non-overlapping Allan deviation of rate samples `y` at τ = m·τ0."""
    _check(y, m, 2 * m, "adev")
    y = jnp.asarray(y, dtype=float)
    k = y.shape[0] // m
    ybar = y[: k * m].reshape(k, m).mean(axis=1)
    return jnp.sqrt(0.5 * jnp.mean(jnp.diff(ybar) ** 2))


def oadev(y, m: int = 1, tau0: float = 1.0):
    """Overlapping Allan deviation at τ = m·τ0."""
    _check(y, m, 2 * m, "oadev")
    x = _phase(y, tau0)
    d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
    tau = m * tau0
    return jnp.sqrt(jnp.mean(d**2) / (2 * tau**2))


def mdev(y, m: int = 1, tau0: float = 1.0):
    """Modified Allan deviation at τ = m·τ0."""
    _check(y, m, 3 * m - 1, "mdev")
    x = _phase(y, tau0)
    d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
    c = jnp.concatenate([jnp.zeros(1), jnp.cumsum(d)])
    s = c[m:] - c[:-m]
    tau = m * tau0
    return jnp.sqrt(jnp.mean(s**2) / (2 * m**2 * tau**2))


def hdev(y, m: int = 1, tau0: float = 1.0):
    """Non-overlapping Hadamard deviation at τ = m·τ0."""
    _check(y, m, 3 * m, "hdev")
    y = jnp.asarray(y, dtype=float)
    k = y.shape[0] // m
    ybar = y[: k * m].reshape(k, m).mean(axis=1)
    d = ybar[2:] - 2 * ybar[1:-1] + ybar[:-2]
    return jnp.sqrt(jnp.mean(d**2) / 6)


def ohdev(y, m: int = 1, tau0: float = 1.0):
    """Overlapping Hadamard deviation at τ = m·τ0."""
    _check(y, m, 3 * m, "ohdev")
    x = _phase(y, tau0)
    d = x[3 * m :] - 3 * x[2 * m : -m] + 3 * x[m : -2 * m] - x[: -3 * m]
    tau = m * tau0
    return jnp.sqrt(jnp.mean(d**2) / (6 * tau**2))


def totdev(y, m: int = 1, tau0: float = 1.0):
    """Total deviation at τ = m·τ0 (phase extended by reflection at both ends)."""
    _check(y, m, 2, "totdev")
    x = _phase(y, tau0)
    n = x.shape[0]
    if m > n - 2:
        raise ValueError(f"totdev: m = {m} needs at least {m + 1} samples")
    j = jnp.arange(1, n - 1)
    left = 2 * x[0] - x[j][::-1]
    right = 2 * x[-1] - x[n - 1 - j]
    xs = jnp.concatenate([left, x, right])
    off = n - 2
    i = jnp.arange(1, n - 1) + off
    d = xs[i - m] - 2 * xs[i] + xs[i + m]
    tau = m * tau0
    return jnp.sqrt(_sum(d**2) / (2 * tau**2 * (n - 2)))


_KINDS = {
    "adev": adev,
    "oadev": oadev,
    "mdev": mdev,
    "hdev": hdev,
    "ohdev": ohdev,
    "totdev": totdev,
}


def allan_deviation(rate, dt: float, ms=None, kind: str = "oadev"):
    """A deviation curve of rate samples `rate` [any rate unit] taken every `dt` [s].

    One compiled program per kind and data length serves every set of averaging factors of
    the same count: `m` is a run-time value inside it (masked sums), so a curve of 20 τ
    values compiles once, not 20 times.

    **Arguments:**

    - `ms`: averaging factors (positive integers); default: octaves 1, 2, 4, … up to N/4.
    - `kind`: one of `adev`, `oadev`, `mdev`, `hdev`, `ohdev`, `totdev`.

    **Returns:** `(taus [s], deviations [rate unit])` as arrays.

    **Raises:** `ValueError` for an unknown kind, or an `m` the data are too short for.
    """
    if kind not in _KINDS:
        raise ValueError(f"kind must be one of {list(_KINDS)}; got {kind!r}")
    n = np.shape(rate)[0]
    if ms is None:
        ms = [2**k for k in range(int(np.log2(max(n // 4, 1))) + 1)]
    ms = [int(m) if int(m) == m else m for m in np.asarray(ms).ravel().tolist()]
    needed = {"adev": 2, "oadev": 2, "mdev": 3, "hdev": 3, "ohdev": 3, "totdev": 0}[kind]
    for m in ms:
        _check(rate, m, max(needed * m - (kind == "mdev"), 2), kind)
        if kind == "totdev" and m > n - 1:
            raise ValueError(f"totdev: m = {m} needs at least {m + 1} samples")
    devs = _curve(jnp.asarray(rate, dtype=float), jnp.asarray(ms), float(dt), kind)
    return jnp.asarray(ms, dtype=float) * dt, devs


@functools.partial(jax.jit, static_argnames=("kind",))
def _curve(y, ms, tau0, kind):
    """Deviations of `kind` at every averaging factor in `ms` (a run-time integer array);
    `lax.map` keeps the memory at one factor's O(N)."""
    x = _phase(y, tau0)
    n = x.shape[0]
    if kind == "totdev":  # the record reflected at both ends, built once for every m
        j = jnp.arange(1, n - 1)
        xp = jnp.concatenate([2 * x[0] - x[j][::-1], x, 2 * x[-1] - x[n - 1 - j]])
    else:  # padded with its last value: x[i + k] is a contiguous slice for any k < n
        xp = jnp.concatenate([x, jnp.full(n + _LANES, x[-1])])

    def step(last, m):
        # a grid padded with repeats of its last factor: a repeat reuses the value (a real
        # branch inside the scan, so the padding costs nothing)
        value = jax.lax.cond(
            m == last[0],
            lambda: last[1],
            lambda: _AT_M[kind](y, x, xp, m, tau0).astype(last[1].dtype),
        )
        return (m, value), value

    init = (jnp.asarray(-1, ms.dtype), jnp.zeros((), x.dtype))
    return jax.lax.scan(step, init, ms)[1]


def _shifted(x, k):
    """x[i + k] for every i (k a run-time integer); past the end the last value repeats
    (masked by callers). A contiguous slice of the padded array, not a gather."""
    n = x.shape[0]
    return jax.lax.dynamic_slice(jnp.concatenate([x, jnp.full(n, x[-1])]), (k,), (n,))


def _sum(v):
    """Σ v over a 1-D array as 16 interleaved partial sums: XLA:CPU turns a plain reduction
    into one serial chain of additions (latency-bound, ≈ 2 ns per element); 16 independent
    accumulators vectorise, 5× faster on 10⁶ samples (the order of the additions differs
    from `jnp.sum` at round-off)."""
    n = v.shape[0]
    pad = -n % _LANES
    if pad:
        v = jnp.concatenate([v, jnp.zeros(pad, v.dtype)])
    return jnp.sum(jnp.sum(v.reshape(-1, _LANES), axis=0))


_LANES = 16


def _masked_mean(v, count):
    return _sum(v) / jnp.asarray(count).astype(v.dtype)


def _tau(m, tau0, like):
    return m.astype(like.dtype) * tau0


def _slice(xp, k, n):
    return jax.lax.dynamic_slice(xp, (k,), (n,))


def _difference_dev(y, x, xp, m, tau0, order, overlapping):
    """Allan (`order` 2) or Hadamard (3) deviation at factor m from the phase's `order`-th
    differences at lag m: every start (overlapping) or starts at multiples of m. The
    differences run over a length rounded up to whole `_LANES` (the padded phase is long
    enough) so that their sum vectorises without a copy."""
    n1 = x.shape[0]
    length = -(-n1 // _LANES) * _LANES
    i = jnp.arange(length)
    if order == 2:
        d = _slice(xp, 2 * m, length) - 2 * _slice(xp, m, length) + xp[:length]
    else:
        d = (_slice(xp, 3 * m, length) - 3 * _slice(xp, 2 * m, length)
             + 3 * _slice(xp, m, length) - xp[:length])  # fmt: skip
    span = n1 - order * m  # starts i < span have all their points
    keep = i < span
    count = span
    if not overlapping:  # starts at multiples of m: (i + ½)/m floors exactly (float, as
        # integer division does not vectorise on XLA:CPU)
        mf, fi = m.astype(d.dtype), i.astype(d.dtype)
        keep = keep & (jnp.floor((fi + 0.5) * (1.0 / mf)) * mf == fi)
        count = (span + m - 1) // m
    d = jnp.where(keep, d, 0.0)
    tau = _tau(m, tau0, d)
    return jnp.sqrt(_masked_mean(d**2, count) / ((2 if order == 2 else 6) * tau**2))


def _mdev_m(y, x, xp, m, tau0):
    n1 = x.shape[0]
    i = jnp.arange(n1)
    length = n1 - 2 * m
    d = jnp.where(i < length, _slice(xp, 2 * m, n1) - 2 * _slice(xp, m, n1) + x, 0.0)
    c = jnp.concatenate([jnp.zeros(1), jnp.cumsum(d)])
    s = jnp.where(jnp.arange(n1 + 1) <= length - m, _shifted(c, m) - c, 0.0)
    tau = _tau(m, tau0, s)
    return jnp.sqrt(_masked_mean(s**2, length - m + 1) / (2 * m.astype(s.dtype) ** 2 * tau**2))


def _totdev_m(y, x, xs, m, tau0):
    n = x.shape[0]
    i0 = n - 1  # x[1] in the reflected record; the n − 2 inner points from there
    d = _slice(xs, i0 - m, n - 2) - 2 * xs[i0 : i0 + n - 2] + _slice(xs, i0 + m, n - 2)
    tau = _tau(m, tau0, d)
    return jnp.sqrt(_sum(d**2) / (2 * tau**2 * (n - 2)))


_AT_M = {
    "adev": functools.partial(_difference_dev, order=2, overlapping=False),
    "oadev": functools.partial(_difference_dev, order=2, overlapping=True),
    "mdev": _mdev_m,
    "hdev": functools.partial(_difference_dev, order=3, overlapping=False),
    "ohdev": functools.partial(_difference_dev, order=3, overlapping=True),
    "totdev": _totdev_m,
}


# ---------------------------------------------------------------------------------------
# Allan statistics: τ grids, term counts, noise identification, EDF and intervals

KINDS = ("adev", "oadev", "mdev", "tdev", "hdev", "ohdev", "totdev")
"""The deviations [`deviation`][hrgjax.allan.deviation] computes."""
ONE_SIGMA = 0.6826894921370859
"""erf(1/√2): the ±1σ confidence level, the default of `ci`."""


@dataclasses.dataclass(frozen=True)
class AllanResult:
    """A deviation curve with its uncertainty (NumPy arrays, one entry per τ).

    - `kind`: the deviation (one of [`KINDS`][hrgjax.allan.KINDS]); `ci`: the confidence level.
    - `taus` [s]; `m`: averaging factors (τ = m/rate_hz).
    - `dev`: the deviation [rate unit; tdev: rate unit × s, an angle];
      `dev_low`, `dev_high`: the χ² interval at level `ci` (NIST SP 1065 eq. 45).
    - `edf`: equivalent degrees of freedom (Greenhall–Riley; totdev: SP 1065 Table 7).
    - `n_terms`: the number of differences each estimate averages.
    - `alpha`: the power-law noise identified at each τ, the exponent α of the rate PSD
      S_y(f) ∝ f^α: 2 white angle (phase) noise, 1 flicker angle, 0 white rate (angle random
      walk), −1 flicker rate (bias instability), −2 rate random walk (lag-1 autocorrelation,
      Riley & Greenhall 2004).
    """

    kind: str
    ci: float
    taus: np.ndarray
    m: np.ndarray
    dev: np.ndarray
    dev_low: np.ndarray
    dev_high: np.ndarray
    edf: np.ndarray
    n_terms: np.ndarray
    alpha: np.ndarray


def deviation(
    y,
    rate_hz: float,
    kind: str = "oadev",
    taus="octave",
    data: str = "rate",
    ci: float = ONE_SIGMA,
) -> AllanResult:
    r"""An Allan-family deviation with confidence intervals, as allantools and Stable32
    compute it.

    **Arguments:**

    - `y`: the samples (1-D): rates (`data="rate"`, e.g. °/h) or angles (`data="phase"`, e.g.
      °), taken at `rate_hz` [Hz].
    - `kind`: one of [`KINDS`][hrgjax.allan.KINDS] (tdev = τ·mdev/√3, in angle units).
    - `taus`: `"octave"` (m = 1, 2, 4, …), `"decade"` (1, 2, 4, 10, 20, 40, …), `"all"`
      (every m) or τ values in seconds (rounded to the nearest m, duplicates dropped, as
      allantools does). Factors whose estimate would average fewer than 2 terms are left
      out (allantools' and Stable32's limit).
    - `ci`: confidence level of the interval (default ±1σ, 0.683).

    One compiled program per kind and data length serves every τ grid (factors are run-time
    values, padded to a power-of-two count), so a new grid compiles nothing.

    **Returns:** an [`AllanResult`][hrgjax.allan.AllanResult].

    **Raises:** `ValueError` naming the argument for an unknown kind or data type, a
    non-positive rate, non-finite samples, a `ci` outside (0, 1), or data too short for any τ;
    `RuntimeError` when JAX is in float32 mode (a summed phase's differences need float64).
    """
    require_x64("hrgjax.allan.deviation (differences of a summed phase)")
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {list(KINDS)}; got {kind!r}")
    if data not in ("rate", "phase"):
        raise ValueError(f"data must be 'rate' or 'phase'; got {data!r}")
    if not (isinstance(rate_hz, numbers.Real) and math.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be a positive sample rate [Hz]; got {rate_hz!r}")
    if not (0.0 < ci < 1.0):
        raise ValueError(f"ci must be a confidence level in (0, 1); got {ci!r}")
    kind_of = np.asarray(y).dtype.kind
    if kind_of in "cbOUSMm":
        what = {"c": "complex numbers", "b": "booleans"}.get(kind_of, f"{np.asarray(y).dtype}")
        if kind_of not in "O" or not all(isinstance(v, numbers.Real) and not isinstance(v, bool)
                                         for v in np.ravel(y)):  # fmt: skip
            raise ValueError(f"y holds {what}; give real numbers (rates or angles)")
    y = np.asarray(y, dtype=float)
    if y.ndim != 1 or y.size < 3:
        raise ValueError(f"y must be 1-D with at least 3 samples; got shape {y.shape}")
    if not np.all(np.isfinite(y)):
        raise ValueError(f"y has a non-finite value at index {int(np.argmin(np.isfinite(y)))}")
    tau0 = 1.0 / float(rate_hz)
    if data == "phase":
        x = y - y[0]
        rate = np.diff(y) / tau0
    else:
        rate = y
        x = np.concatenate([[0.0], np.cumsum(y) * tau0])
    n_phase = x.size
    m = _factors(taus, rate_hz, n_phase)
    n_terms = np.asarray([_n_terms(kind, int(k), n_phase) for k in m], dtype=int)
    m, n_terms = m[n_terms > 1], n_terms[n_terms > 1]
    if m.size == 0:
        raise ValueError(
            f"y: {y.size} samples are too few for {kind} at any of the τ asked (taus={taus!r})"
        )
    base = "mdev" if kind == "tdev" else kind
    # one program for every grid of ≤ 32 τ (octave grids up to 2³² samples), powers of two
    # beyond
    pad = max(32, 1 << int(math.ceil(math.log2(m.size))))
    ms = np.concatenate([m, np.full(pad - m.size, m[-1])])
    # JAX runs the curve asynchronously while NumPy identifies the noise and the EDF
    pending = _curve(jnp.asarray(rate), jnp.asarray(ms), tau0, base)
    dmax = 3 if kind in ("hdev", "ohdev") else 2
    alpha = noise_id(x, m, dmax=dmax)
    edf = np.asarray([_edf(kind, int(a), int(k), n_phase) for a, k in zip(alpha, m, strict=True)])
    dev = np.asarray(pending)[: m.size]
    taus_s = m * tau0
    if kind == "tdev":
        dev = dev * taus_s / math.sqrt(3.0)
    low, high = confidence_interval(dev, edf, ci)
    return AllanResult(
        kind=kind, ci=float(ci), taus=taus_s, m=m, dev=dev, dev_low=low, dev_high=high,
        edf=edf, n_terms=n_terms, alpha=alpha,
    )  # fmt: skip


def _factors(taus, rate_hz: float, n_phase: int) -> np.ndarray:
    """Averaging factors of a τ grid (allantools' `tau_generator`), sorted and unique."""
    if isinstance(taus, str):
        if taus == "all":
            m = np.arange(1, n_phase + 1, dtype=float)
        elif taus == "octave":
            m = 2.0 ** np.arange(int(math.floor(math.log2(n_phase))) + 1)
        elif taus == "decade":
            m = np.asarray(
                [
                    c * 10.0**k
                    for k in range(int(math.floor(math.log10(n_phase))) + 1)
                    for c in (1, 2, 4)
                ]  # fmt: skip
            )
        else:
            raise ValueError(
                f"taus must be 'octave', 'decade', 'all' or τ values in seconds; got {taus!r}"
            )
    else:
        t = np.asarray(taus, dtype=float).ravel()
        if t.size == 0 or not np.all(np.isfinite(t)):
            raise ValueError(f"taus must be finite τ values in seconds; got {taus!r}")
        if np.any(t <= 0):
            raise ValueError(f"taus must be > 0 s; got {float(t[t <= 0][0]):g} in {taus!r}")
        m = np.round(t * rate_hz)
    m = m[(m > 0) & (m < n_phase)]
    return np.unique(m).astype(int)


def _n_terms(kind: str, m: int, n: int) -> int:
    """Differences averaged by `kind` at factor m over n phase points (allantools' `ns`)."""
    if kind == "adev":
        return max(0, -(-(n - 2 * m) // m))
    if kind == "hdev":
        return max(0, -(-(n - 3 * m) // m))
    if kind == "oadev":
        return max(0, n - 2 * m)
    if kind == "ohdev":
        return max(0, n - 3 * m)
    if kind in ("mdev", "tdev"):
        return max(0, n - 3 * m + 1)
    return n - 2 if m <= n - 1 else 0  # totdev: every point, the record reflected


def noise_id(x, m, dmax: int = 2) -> np.ndarray:
    """The power-law noise α (rate PSD ∝ f^α) at each factor `m` of phase (angle) samples
    `x`, by the lag-1 autocorrelation method (Riley & Greenhall 2004, as allantools'
    `autocorr_noise_id` with `dmin=0`): the phase decimated by m, a quadratic removed,
    differenced until ρ = r₁/(1 + r₁) < 0.25 or `dmax` times; α = 2 − 2d − round(2ρ). Where
    fewer than 30 decimated points are left, the α of the largest factor that had them is
    carried on (allantools stops there). **Returns:** an int array."""
    x = np.asarray(x, dtype=float)
    out, last = [], None
    for k in np.asarray(m, dtype=int):
        z = x[:: int(k)]
        if z.size < 30:
            if last is None:
                raise ValueError(
                    f"x: {x.size} samples leave {z.size} at m = {k}; noise identification needs 30"
                )
            out.append(last)
            continue
        z = _detrend2(z)
        d = 0
        while True:
            zc = z - z.mean()
            r1 = float(np.dot(zc[:-1], zc[1:]) / np.dot(zc, zc))
            rho = r1 / (1.0 + r1)
            if rho < 0.25 or d >= dmax:
                break
            z = np.diff(z)
            d += 1
        last = int(-round(2 * rho) - 2 * d) + 2
        out.append(last)
    return np.asarray(out, dtype=int)


def _detrend2(z):
    """z less its least-squares quadratic in the sample index (as `np.polyfit(t, z, 2)`), by
    three orthogonal polynomials on the index: three passes instead of a Vandermonde solve."""
    n = z.size
    t = np.linspace(-1.0, 1.0, n)
    p1 = t
    p2 = t * t - np.dot(t, t) / n
    out = z - z.mean()
    for p in (p1, p2):
        out = out - p * (np.dot(p, out) / np.dot(p, p))
    return out


# -- equivalent degrees of freedom (Greenhall & Riley, "Uncertainty of stability variances
# based on finite differences", PTTI 2003; NIST SP 1065 Table 7 for totdev)


def _sw(t, alpha):
    """Eq. 7: the generalised autocovariance of the noise, up to a constant."""
    t = abs(t)
    if alpha % 2 == 0:  # α = 2: −|t|; 0, −2, −4: |t|^(3−α)
        return -t if alpha == 2 else t ** (3 - alpha)
    return 0.0 if t == 0 else t ** (3 - alpha) * math.log(t)  # α odd: t^(3−α)·ln|t|


def _sx(t, f, alpha):
    """Eq. 8: the filter of factor F (F = ∞: its limit)."""
    if math.isinf(f):
        return _sw(t, alpha + 2)
    return f * f * (2 * _sw(t, alpha) - _sw(t - 1.0 / f, alpha) - _sw(t + 1.0 / f, alpha))


_BINOMIAL = {1: (2, -1), 2: (6, -4, 1), 3: (20, -15, 6, -1)}


def _sz(t, f, alpha, d):
    """Eq. 9: the d-th difference."""
    c = _BINOMIAL[d]
    return c[0] * _sx(t, f, alpha) + sum(
        c[k] * (_sx(t - k, f, alpha) + _sx(t + k, f, alpha)) for k in range(1, d + 1)
    )


def _basic_sum(j, m_terms, s, f, alpha, d):
    """Eq. 10."""
    total = _sz(0, f, alpha, d) ** 2 + (1 - j / m_terms) * _sz(j / s, f, alpha, d) ** 2
    return total + sum(
        2 * (1 - k / m_terms) * _sz(k / s, f, alpha, d) ** 2 for k in range(1, int(j))
    )


_TABLE1 = {  # modified variances, (a0, a1) by α (rows) and d = 1, 2, 3
    2: ((2 / 3, 1 / 3), (7 / 9, 1 / 2), (22 / 25, 2 / 3)),
    1: ((0.840, 0.345), (0.997, 0.616), (1.141, 0.843)),
    0: ((1.079, 0.368), (1.033, 0.607), (1.184, 0.848)),
    -1: (None, (1.048, 0.534), (1.180, 0.816)),
    -2: (None, (1.302, 0.535), (1.175, 0.777)),
    -3: (None, None, (1.194, 0.703)),
    -4: (None, None, (1.489, 0.702)),
}
_TABLE2 = {  # unmodified variances
    2: ((3 / 2, 1 / 2), (35 / 18, 1.0), (231 / 100, 3 / 2)),
    1: ((78.6, 25.2), (790.0, 410.0), (9950.0, 6520.0)),
    0: ((2 / 3, 1 / 6), (2 / 3, 1 / 3), (7 / 9, 1 / 2)),
    -1: (None, (0.852, 0.375), (0.997, 0.617)),
    -2: (None, (1.079, 0.368), (1.033, 0.607)),
    -3: (None, None, (1.053, 0.553)),
    -4: (None, None, (1.302, 0.535)),
}
_TABLE3 = {1: (6.0, 4.0), 2: (15.23, 12.0), 3: (47.8, 40.0)}  # flicker phase, unmodified


def edf_greenhall(alpha: int, d: int, m: int, n: int, overlapping: bool, modified: bool):
    """Equivalent degrees of freedom of a d-th difference variance at factor `m` over `n`
    phase points for power-law noise α (Greenhall & Riley 2003, eqs. 10–13 and Tables 1–3;
    d = 2 Allan, 3 Hadamard; `modified`: mdev/tdev; `overlapping`: stride 1).

    **Raises:** `ValueError` where the variance does not converge (α + 2d ≤ 1) or the data
    are shorter than the filter."""
    if alpha + 2 * d <= 1:
        raise ValueError(f"alpha = {alpha} needs alpha + 2d > 1 (d = {d})")
    f = 1 if modified else int(m)
    s = int(m) if overlapping else 1
    length = m / f + m * d
    if n < length:
        raise ValueError(f"n = {n} phase points are fewer than the filter's {length:g}")
    m_terms = 1 + math.floor(s * (n - length) / m)
    j = min(m_terms, (d + 1) * s)
    j_max = 100
    r = m_terms / s
    if modified:
        if j <= j_max:
            return _sz(0, 1, alpha, d) ** 2 * m_terms / _basic_sum(j, m_terms, s, 1, alpha, d)
        if r > d + 1:
            a0, a1 = _TABLE1[alpha][d - 1]
            return 1.0 / ((a0 - a1 / r) / r)
        mp = j_max / r
        return _sz(0, 1, alpha, d) ** 2 * j_max / _basic_sum(j_max, j_max, mp, 1, alpha, d)
    if alpha <= 0:
        if j <= j_max:
            fp = m if m * (d + 1) <= j_max else math.inf
            return _sz(0, fp, alpha, d) ** 2 * m_terms / _basic_sum(j, m_terms, s, fp, alpha, d)
        if r > d + 1:
            a0, a1 = _TABLE2[alpha][d - 1]
            return 1.0 / ((a0 - a1 / r) / r)
        mp = j_max / r
        return (
            _sz(0, math.inf, alpha, d) ** 2
            * j_max
            / _basic_sum(j_max, j_max, mp, math.inf, alpha, d)
        )
    if alpha == 1:
        if j <= j_max:
            return _sz(0, m, 1, d) ** 2 * m_terms / _basic_sum(j, m_terms, s, m, 1, d)
        b0, b1 = _TABLE3[d]
        if r > d + 1:
            a0, a1 = _TABLE2[1][d - 1]
            return (b0 + b1 * math.log(m)) ** 2 * r / (a0 - a1 / r)
        mp = j_max / r
        return (b0 + b1 * math.log(m)) ** 2 * j_max / _basic_sum(j_max, j_max, mp, mp, 1, d)
    # α = 2, unmodified: eq. 13's limit where the estimate has more than d + 1 terms, else
    # the basic sum itself
    if math.ceil(r) > d:
        a0 = math.comb(4 * d, 2 * d) / math.comb(2 * d, d) ** 2
        return 1.0 / ((a0 - (d / 2.0) / r) / m_terms)
    return _sz(0, m, 2, d) ** 2 * m_terms / _basic_sum(j, m_terms, s, m, 2, d)


def edf_totdev(alpha: int, m: int, n: int) -> float:
    """EDF of the total deviation: b·N/m − c (NIST SP 1065 Table 7) for α = 0, −1, −2; other
    noises the (N−1)-point approximations of Stein (1985)."""
    table7 = {0: (1.50, 0.0), -1: (1.17, 0.22), -2: (0.93, 0.36)}
    if alpha in table7:
        b, c = table7[alpha]
        return b * n / m - c
    if alpha == 2:
        return (n + 1) * (n - 2 * m) / (2 * (n - m))
    if alpha == 1:
        return math.exp(
            math.sqrt(math.log((n - 1) / (2 * m)) * math.log((2 * m + 1) * (n - 1) / 4))
        )
    return float(n - 1)


def _edf(kind: str, alpha: int, m: int, n: int) -> float:
    if kind == "totdev":
        return edf_totdev(alpha, m, n)
    d = 3 if kind in ("hdev", "ohdev") else 2
    alpha = max(alpha, 2 - 2 * d)  # the variance converges for α > 1 − 2d
    return edf_greenhall(
        alpha, d, m, n, overlapping=kind in ("oadev", "ohdev", "mdev", "tdev"),
        modified=kind in ("mdev", "tdev"),
    )  # fmt: skip


def confidence_interval(dev, edf, ci: float = ONE_SIGMA):
    """χ² interval (low, high) of deviations `dev` with `edf` degrees of freedom at level
    `ci`: σ²·edf/χ²(1 − p) … σ²·edf/χ²(p), p = (1 − ci)/2 (NIST SP 1065 eq. 45)."""
    dev, edf = np.asarray(dev, dtype=float), np.asarray(edf, dtype=float)
    p = min(ci, 1 - ci) / 2
    lo = np.vectorize(lambda k: chi2_ppf(1 - p, k))(edf)
    hi = np.vectorize(lambda k: chi2_ppf(p, k))(edf)
    return dev * np.sqrt(edf / lo), dev * np.sqrt(edf / hi)


def _gammainc(a: float, x: float) -> float:
    """Regularised lower incomplete gamma P(a, x) (series below a + 1, continued fraction
    above; float64 whatever JAX's precision)."""
    if x <= 0:
        return 0.0
    log_front = a * math.log(x) - x - math.lgamma(a)
    if x < a + 1 + 20 * math.sqrt(a):
        # the series Σ xⁿ/(a(a+1)…(a+n)), summed at once: its terms fall off as
        # exp(−n²/2a) past n ≈ x − a, so 10√x + (x − a) + 50 of them reach round-off
        n = int(10 * math.sqrt(x) + max(x - a, 0.0) + 50)
        terms = np.cumprod(x / (a + np.arange(1, n + 1)))
        return float((1.0 + terms.sum()) / a * math.exp(log_front))
    tiny = 1e-300  # modified Lentz for Q(a, x)
    b = x + 1 - a
    c, dd = 1 / tiny, 1 / b
    h = dd
    for i in range(1, 10_000):
        an = -i * (i - a)
        b += 2
        dd = an * dd + b
        dd = tiny if abs(dd) < tiny else dd
        c = b + an / c
        c = tiny if abs(c) < tiny else c
        dd = 1 / dd
        delta = dd * c
        h *= delta
        if abs(delta - 1) < 1e-16:
            break
    return 1.0 - math.exp(log_front) * h


def chi2_ppf(q: float, k: float) -> float:
    """The q-quantile of the χ² distribution with k (> 0, real) degrees of freedom."""
    a = 0.5 * k
    # Wilson–Hilferty start, then safeguarded Newton on P(k/2, x/2) = q
    z = NormalDist().inv_cdf(q)
    x = max(k * (1 - 2 / (9 * k) + z * math.sqrt(2 / (9 * k))) ** 3, 1e-8)
    lo, hi = 0.0, math.inf
    for _ in range(200):
        f = _gammainc(a, 0.5 * x) - q
        if f > 0:
            hi = x
        else:
            lo = x
        pdf = math.exp((a - 1) * math.log(0.5 * x) - 0.5 * x - math.lgamma(a)) * 0.5
        step = f / pdf if pdf > 0 else math.inf
        new = x - step
        if not (lo < new < hi):
            new = 0.5 * (lo + hi) if math.isfinite(hi) else 2 * x
        if abs(new - x) <= 1e-15 * x:
            return new
        x = new
    return x


# -- IEEE 952 noise terms from an Allan variance

NOISE_TERMS = (
    ("quantization", "Q", "rate unit·s", lambda t: 3.0 / t**2),
    ("angle_random_walk", "N", "rate unit·√s", lambda t: 1.0 / t),
    ("bias_instability", "B", "rate unit", lambda t: np.full_like(t, 2 * math.log(2) / math.pi)),
    ("rate_random_walk", "K", "rate unit/√s", lambda t: t / 3.0),
    ("rate_ramp", "R", "rate unit/s", lambda t: t**2 / 2.0),
)
"""IEEE 952 terms of the Allan variance: (name, symbol, unit, σ²(τ) per unit coefficient²)
— 3Q²/τ², N²/τ, (2 ln 2/π)B², K²τ/3, R²τ²/2 (the bias instability's flat part, 0.664 B)."""


@dataclasses.dataclass(frozen=True)
class NoiseFit:
    """IEEE 952 noise coefficients fitted to an Allan deviation
    ([`fit_noise`][hrgjax.allan.fit_noise]).

    - `value`, `sigma`, `low`, `high`: `{name: float}` for quantization Q [rate unit·s],
      angle_random_walk N [rate unit·√s], bias_instability B [rate unit], rate_random_walk K
      [rate unit/√s] and rate_ramp R [rate unit/s] — for rates in °/h, N in °/h·√s is
      N/60 in °/√h. A term the data do not show is 0 with an upper bound. `low`/`high`: the
      interval at the result's `ci`, from the fit's covariance.
    - `chi2`, `dof`: the weighted misfit of the Allan variance and its degrees of freedom.
    """

    value: dict
    sigma: dict
    low: dict
    high: dict
    chi2: float
    dof: int

    def adev(self, taus) -> np.ndarray:
        """The fitted Allan deviation at `taus` [s]."""
        t = np.asarray(taus, dtype=float)
        return np.sqrt(sum(self.value[n] ** 2 * f(t) for n, _, _, f in NOISE_TERMS))


def fit_noise(result: AllanResult, terms=None) -> NoiseFit:
    r"""Fit the IEEE 952 terms to an Allan deviation by weighted non-negative least squares
    on the Allan variance $\sigma^2(\tau) = 3Q^2/\tau^2 + N^2/\tau + (2\ln2/\pi)B^2 + K^2\tau/3
    + R^2\tau^2/2$, each τ weighted by its EDF (var σ̂² ≈ 2σ⁴/edf, the σ⁴ of the model,
    iterated) — what allantools leaves to the user.

    **Arguments:** `result` from [`deviation`][hrgjax.allan.deviation] with kind `adev` or
    `oadev` (the terms are Allan-variance slopes); `terms`: names of
    [`NOISE_TERMS`][hrgjax.allan.NOISE_TERMS] to fit (default all five).

    **Returns:** a [`NoiseFit`][hrgjax.allan.NoiseFit]; intervals at the result's `ci`,
    from the fit's covariance with the τ points taken as independent — overlapping estimates
    at neighbouring octaves are correlated, so read them as optimistic (in simulated white
    + rate-random-walk records the K interval at 3σ held in 5 of 6).
    """
    if not isinstance(result, AllanResult):
        raise TypeError(f"result must be an AllanResult; got {type(result).__name__}")
    if result.kind not in ("adev", "oadev"):
        raise ValueError(
            f"result.kind must be 'adev' or 'oadev' (Allan variance); got {result.kind!r}"
        )
    names = [n for n, *_ in NOISE_TERMS]
    terms = names if terms is None else list(terms)
    bad = [t for t in terms if t not in names]
    if bad:
        raise ValueError(f"terms must be among {names}; got {bad}")
    t, var, edf = result.taus, result.dev**2, result.edf
    basis = np.stack([f(t) for n, _, _, f in NOISE_TERMS if n in terms], axis=1)
    model = var.copy()
    for _ in range(5):
        w = np.sqrt(edf / 2.0) / model
        a = basis * w[:, None]
        scale = np.linalg.norm(a, axis=0)  # the columns span 10⁹ over a τ grid
        coef = _nnls(a / scale, var * w) / scale
        model = np.maximum(basis @ coef, 1e-300)
    a = basis * w[:, None] / scale
    cov = np.linalg.pinv(a.T @ a) / np.outer(scale, scale)
    z = NormalDist().inv_cdf(0.5 + result.ci / 2)
    value, sigma, low, high = {}, {}, {}, {}
    it = iter(range(len(terms)))
    for n in names:
        if n not in terms:
            value[n] = sigma[n] = low[n] = high[n] = 0.0
            continue
        i = next(it)
        c, sc = coef[i], math.sqrt(max(cov[i, i], 0.0))
        value[n] = math.sqrt(c)
        sigma[n] = sc / (2 * math.sqrt(c)) if c > 0 else math.sqrt(sc)
        low[n] = math.sqrt(max(c - z * sc, 0.0))
        high[n] = math.sqrt(c + z * sc)
    chi2 = float(np.sum(((basis @ coef - var) * w) ** 2))
    return NoiseFit(value, sigma, low, high, chi2, int(t.size - np.count_nonzero(coef)))
