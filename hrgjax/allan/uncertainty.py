"""The uncertainty of an Allan-family deviation estimate, in NumPy (float64, no JAX).

The equivalent degrees of freedom of the estimate
([`edf_greenhall`][hrgjax.allan.edf_greenhall]; totdev's in `hrgjax.allan.totvar`)
and its χ² confidence interval ([`confidence_interval`][hrgjax.allan.confidence_interval],
[`chi2_ppf`][hrgjax.allan.chi2_ppf]), as allantools and Stable32 compute them, for the noise
type that `hrgjax.allan.noise_ident` identifies ([`noise_id`][hrgjax.allan.noise_id]; its
names are importable from here too).
"""

from __future__ import annotations

import decimal
import fractions
import functools
import math
from statistics import NormalDist

import numpy as np

from .._checks import (
    check_flag,
    check_number,
    check_numbers,
    describe,
    is_finite_real,
    whole_number,
)
from .noise_ident import ACF_POINTS as ACF_POINTS
from .noise_ident import B1_AVERAGES as B1_AVERAGES
from .noise_ident import NOISE_RULES as NOISE_RULES
from .noise_ident import RHO_SPLIT as RHO_SPLIT
from .noise_ident import RN_FACTOR as RN_FACTOR
from .noise_ident import b1_expected as b1_expected
from .noise_ident import check_rate_has_noise as check_rate_has_noise
from .noise_ident import noise_id as noise_id
from .noise_ident import rn_expected as rn_expected

ONE_SIGMA = 0.6826894921370859
"""erf(1/√2): the ±1σ confidence level, the default of `ci`."""


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


DISCRETE_EDF_M = 64
"""Up to this factor m, `edf_greenhall(..., discrete=True)` (the default of
`hg.allan.deviation`) returns the exact EDF of the estimator for noise as a gyro samples it
([`edf_discrete`][hrgjax.allan.edf_discrete]); beyond, Greenhall's, within 1 % of
it for every kind and α but flicker angle noise's oadev and ohdev (Greenhall 0.85–0.88× it)."""


def edf_greenhall(
    alpha: int, d: int, m: int, n: int, overlapping: bool, modified: bool,
    discrete: bool = False,
):  # fmt: skip
    """Equivalent degrees of freedom of a d-th difference variance at factor `m` over `n`
    phase points for power-law noise α (Greenhall & Riley 2003, eqs. 10–13 and Tables 1–3;
    d = 2 Allan, 3 Hadamard; `modified`: mdev/tdev; `overlapping`: stride 1) — allantools'
    and Stable32's numbers.

    Greenhall & Riley model the phase averaged over τ₀; a gyro's angle samples are point
    values (its rate samples exact interval means of the rate), and at m = 1 their EDF is
    0.86–1.19× the estimator's for rate noises (adev white rate 1.17×, random walk 0.86×,
    hdev flicker rate 1.13×; oadev white rate 0.88× at m = 4). `discrete=True`: the exact
    EDF ([`edf_discrete`][hrgjax.allan.edf_discrete]) up to m =
    [`DISCRETE_EDF_M`][hrgjax.allan.DISCRETE_EDF_M], Greenhall's beyond.

    **Raises:** `ValueError` naming the argument for α, d, m or n not whole numbers (1.5 is
    refused, not read as 1), d outside 1 … 3, m < 1, α > 2 or a variance that does not
    converge (α + 2d ≤ 1), or the data shorter than the filter; `TypeError` for
    `overlapping`, `modified` or `discrete` not a bool."""
    args = _check_edf_args(alpha, d, m, n, overlapping, modified)
    return _edf_greenhall(*args, check_flag("discrete", discrete))


def _filter_length(d, m, n, modified):
    """Phase points one term spans; ValueError where the record is shorter."""
    length = m + m * d if modified else 1 + m * d
    if n < length:
        raise ValueError(f"n = {n} phase points are fewer than the filter's {length:g}")
    return length


@functools.lru_cache(maxsize=4096)
def _edf_greenhall(alpha, d, m, n, overlapping, modified, discrete=False):
    """`edf_greenhall`, kept: the records of one length share their octaves' EDFs."""
    if discrete and m <= DISCRETE_EDF_M and alpha <= 2:
        return edf_discrete(alpha, d, m, n, overlapping, modified)
    s = m if overlapping else 1
    length = _filter_length(d, m, n, modified)
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


FLICKER_LAGS = 64
"""`edf_discrete` sums a flicker noise's term correlations out to this many filter lengths
(they fall as lag⁻² or faster: the rest changes the EDF by < 7e-7 at 65 537 points —
flicker rate at m = 1 2.8e-7, α = −3 6.3e-7 — and ≤ 1.1e-7 at m ≥ 2)."""

_SERIES_FROM = 32
"""From this lag on, the continuous flicker kernel is its asymptotic series (below it,
exact in 60-digit decimals: the 2p-th difference of t^(1−α)·ln t cancels ~lag^(4−α) of
its terms' size)."""


def _flicker_series(n_pow: int, p: int, lags: np.ndarray) -> np.ndarray:
    """δ^(2p)[tⁿ ln t](j) for j ≫ p, 2p = n + 2: δ^(2p) = D^(2p)·(sinh(D/2)/(D/2))^(2p) =
    Σ_k s_k D^(2p+2k), and D^(n+2+2k)[tⁿ ln t] = −n!·(2k+1)!/t^(2k+2)."""
    base = [fractions.Fraction(1, 4**i * math.factorial(2 * i + 1)) for i in range(8)]
    s = [fractions.Fraction(1)] + [fractions.Fraction(0)] * 7
    for _ in range(2 * p):  # (Σ a_i x^i)^(2p), x = D², truncated at x^7
        s = [sum(s[i] * base[k - i] for i in range(k + 1)) for k in range(8)]
    j2 = 1.0 / (lags * lags)
    total = np.zeros(lags.shape)
    for k in reversed(range(8)):  # Horner in 1/j²
        total = (total + float(s[k]) * math.factorial(2 * k + 1)) * j2
    return -math.factorial(n_pow) * total


@functools.lru_cache(maxsize=32)
def _increment_kernel(alpha: int, lags: int) -> np.ndarray:
    """The autocovariance at lags 0 … `lags` − 1 of the p-fold phase increments
    `edf_discrete` works on, normalised to 1 at lag 0 (module of `edf_discrete`)."""
    out = np.zeros(lags)
    if alpha in (2, 0):  # white angle noise; white rate noise (a random-walk phase)
        out[0] = 1.0
        return out
    if alpha == 1:  # Kasdin's ARFIMA(0, −½, 0)
        k = np.arange(lags, dtype=float)
        return -1.0 / (4.0 * k * k - 1.0)
    # continuous rate noise, the phase point-sampled: generalised autocovariance
    # G(t) = |t|^(1−α) (α even) or |t|^(1−α)·ln|t| (α odd) (Greenhall's sw(t, α + 2));
    # the p-fold increments' autocovariance is ±δ^(2p)G at whole lags
    n_pow, p = 1 - alpha, (2 - alpha) // 2 if alpha % 2 == 0 else (3 - alpha) // 2
    row = [(-1) ** (i + p) * math.comb(2 * p, i + p) for i in range(-p, p + 1)]
    if alpha % 2 == 0:  # a B-spline: lags 0 … p − 1, exact in integers
        for j in range(min(p, lags)):
            out[j] = sum(b * abs(j + i - p) ** n_pow for i, b in enumerate(row))
        return out / out[0]
    near = min(lags, _SERIES_FROM)
    with decimal.localcontext(decimal.Context(prec=60)):  # whatever the caller's context
        g = [decimal.Decimal(0)] + [decimal.Decimal(t) ** n_pow * decimal.Decimal(t).ln()
                                    for t in range(1, near + p)]  # fmt: skip
        for j in range(near):
            out[j] = float(sum(b * g[abs(j + i - p)] for i, b in enumerate(row)))
    if lags > near:
        out[near:] = _flicker_series(n_pow, p, np.arange(near, lags, dtype=float))
    return out / out[0]


def edf_discrete(alpha: int, d: int, m: int, n: int, overlapping: bool, modified: bool):
    """Exact EDF of a d-th difference variance at factor `m` over `n` phase points for
    power-law noise α as a gyro samples it: (tr AΣ)²/tr (AΣ)², AΣ the estimator's quadratic
    form on the noise's covariance, i.e. (M·R₀)² / (M·R₀² + 2 Σₖ (M − k)·R_k²) over the M
    terms the estimator averages, R_k the covariance of terms k strides apart.

    The noise model, by α (the phase x is the angle, point-sampled every τ₀; the rate
    samples its first differences, i.e. interval means of the rate):

    - α = 2 (white angle noise): white phase samples;
    - α = 1 (flicker angle noise): Kasdin's discrete flicker phase (ARFIMA(0, −½, 0)
      increments, autocovariance −1/(4k² − 1), as allantools' generator);
    - α ≤ 0 (white rate noise, flicker rate noise, rate random walk; −3, −4 for the
      Hadamard kinds): continuous rate noise S_y ∝ f^α with no cut-off, its exact
      interval means — as a gyro integrates it and as
      [`ImuModel`][hrgjax.ins.sensors.ImuModel] draws a rate random walk. The phase's
      generalised autocovariance is Greenhall's sw(t, α + 2) (|t|^(1−α), times ln|t| for
      odd α); the p-fold phase increments' covariance is its 2p-th difference (white rate
      noise: white increments, as Kasdin's; a random walk: (1, ¼) at lags 0, 1; flicker
      rate: ∝ −2/k² at large lags, summed out to `FLICKER_LAGS` = 64 filter lengths).
      Kasdin's discrete rate random walk and flicker rate noise (this function's model
      until 2026-12-01) are not a gyro's: at m = 1 their EDF is 1.125× this one for oadev
      (random walk), 0.85× for hdev, 0.92× for flicker rate adev.

    Cost O(d²m²) (flicker, 64 filter lengths), O(d²m) (the rest); d, α, `overlapping`,
    `modified` as [`edf_greenhall`][hrgjax.allan.edf_greenhall].

    **Raises:** as [`edf_greenhall`][hrgjax.allan.edf_greenhall]."""
    alpha, d, m, n, overlapping, modified = _check_edf_args(alpha, d, m, n, overlapping, modified)
    _filter_length(d, m, n, modified)
    c = np.zeros(d * m + 1)
    c[::m] = [(-1) ** k * math.comb(d, k) for k in range(d + 1)]
    c = np.convolve(c, np.ones(m)) / m if modified else c
    stride = 1 if overlapping else m
    terms = 1 + (n - c.size) // stride
    p = (3 - alpha) // 2 if alpha % 2 else (2 - alpha) // 2
    for _ in range(p):
        c = np.cumsum(c[::-1])[::-1][1:]  # the filter on the increments of one sum fewer
    rc = np.correlate(c, c, mode="full")  # lags −(L − 1) … L − 1
    size = c.size
    if alpha % 2 == 0:  # increments correlated over max(p − 1, 0) lags: R ends there
        reach = size - 1 + max(p - 1, 0)
    else:
        reach = FLICKER_LAGS * size
    top = min((terms - 1) * stride, reach)
    k = np.abs(np.arange(-(size - 1), top + size))
    r = np.convolve(_increment_kernel(alpha, 1 << int(k.max()).bit_length())[k], rc,
                    mode="valid")[: top + 1]  # fmt: skip
    r = r[::stride]
    weight = terms - np.arange(r.size)
    return float((terms * r[0]) ** 2 / (terms * r[0] ** 2 + 2 * np.sum(weight[1:] * r[1:] ** 2)))


def _check_edf_args(alpha, d, m, n, overlapping, modified):
    """The EDF functions' arguments as ints and bools, else a one-line error naming one."""
    alpha = whole_number("alpha", alpha, "a whole noise exponent (rate PSD ∝ f^α), ≤ 2")
    d = whole_number("d", d, "the difference order 1, 2 or 3 (3: Hadamard)")
    if d not in (1, 2, 3):
        raise ValueError(f"d must be the difference order 1, 2 or 3 (3: Hadamard); got {d}")
    m = whole_number("m", m, "a whole averaging factor ≥ 1")
    if m < 1:
        raise ValueError(f"m must be a whole averaging factor ≥ 1; got {m}")
    n = whole_number("n", n, "a whole number of phase points")
    if alpha + 2 * d <= 1 or alpha > 2:
        raise ValueError(f"alpha = {alpha} needs 1 - 2d < alpha <= 2 (d = {d}: the variance "
                         "converges, rate PSD ∝ f^α)")  # fmt: skip
    return alpha, d, m, n, check_flag("overlapping", overlapping), check_flag("modified", modified)


def confidence_interval(dev, edf, ci: float = ONE_SIGMA):
    """χ² interval (low, high) of deviations `dev` (any unit; the interval in it) with `edf`
    degrees of freedom at level `ci`: σ²·edf/χ²(1 − p) … σ²·edf/χ²(p), p = (1 − ci)/2
    (NIST SP 1065 eq. 45), for any ci in (0, 1).

    **Raises:** `ValueError` for a `ci` outside (0, 1), an EDF ≤ 0, a deviation that is
    negative or infinite (a NaN deviation gives a NaN interval), or `dev` and `edf` of
    shapes that do not broadcast together."""
    if not (is_finite_real(ci) and 0.0 < ci < 1.0):
        raise ValueError(f"ci must be a confidence level in (0, 1); got {describe(ci)}")
    check_numbers("dev", dev, "deviations >= 0 (any unit)")
    check_numbers("edf", edf, "degrees of freedom > 0, one per deviation")
    dev, edf = np.asarray(dev, dtype=float), np.asarray(edf, dtype=float)
    try:
        np.broadcast_shapes(dev.shape, edf.shape)
    except ValueError:  # NumPy's "shape mismatch" after the χ² work
        raise ValueError(f"dev and edf must have shapes that broadcast together; got shapes "
                         f"{dev.shape} and {edf.shape}") from None  # fmt: skip
    bad = (dev < 0) | np.isinf(dev)  # a negative σ gave a negative interval; NaN stays NaN
    if bad.any():
        raise ValueError(f"dev must be deviations >= 0 (or NaN); got {dev[bad].flat[0]}")
    p = (1.0 - ci) / 2
    lo = np.vectorize(lambda k: chi2_ppf(1 - p, k), otypes=[float])(edf)
    hi = np.vectorize(lambda k: chi2_ppf(p, k), otypes=[float])(edf)
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


def chi2_sf(x: float, dof: float) -> float:
    """Upper tail probability P(χ²_dof > x) (float64 whatever JAX's precision)."""
    return 1.0 - _gammainc(dof / 2.0, max(x, 0.0) / 2.0)


def chi2_ppf(q: float, k: float) -> float:
    """The q-quantile of the χ² distribution with k (> 0, real) degrees of freedom.

    **Raises:** `ValueError` for k ≤ 0 (or NaN, inf) or q outside (0, 1), `TypeError` for
    a q or k that is not a number."""
    q = float(check_number("chi2_ppf: q", q, "a probability"))
    k = float(check_number("chi2_ppf: k", k, "degrees of freedom"))
    if not 0 < k < math.inf:
        raise ValueError(f"chi2_ppf: the degrees of freedom (EDF) must be > 0; got {k!r}")
    if not 0.0 < q < 1.0:
        raise ValueError(f"chi2_ppf: the quantile q must be in (0, 1); got {q!r}")
    return _chi2_ppf(q, k)


@functools.lru_cache(maxsize=4096)
def _chi2_ppf(q: float, k: float) -> float:
    """`chi2_ppf`, kept: the records of one length and octave grid share a few EDFs."""
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
