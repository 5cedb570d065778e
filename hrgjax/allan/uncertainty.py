"""The uncertainty of an Allan-family deviation estimate, in NumPy (float64, no JAX).

The equivalent degrees of freedom of the estimate
([`edf_greenhall`][hrgjax.allan.edf_greenhall]; totdev's in `hrgjax.allan.totvar`)
and its χ² confidence interval ([`confidence_interval`][hrgjax.allan.confidence_interval],
[`chi2_ppf`][hrgjax.allan.chi2_ppf]), as allantools and Stable32 compute them, for the noise
type that `hrgjax.allan.noise_ident` identifies ([`noise_id`][hrgjax.allan.noise_id]; its
names are importable from here too).
"""

from __future__ import annotations

import functools
import math
from statistics import NormalDist

import numpy as np

from .._checks import describe, is_finite_real
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
`hg.allan.deviation`) returns the exact EDF of the estimator for point-sampled noise
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
    values (its rate samples exact first differences of them), and at small m their EDF is
    up to 24 % above the estimator's for rate noises (adev white rate 1.17×, hdev flicker
    rate 1.24×, oadev white rate 0.88× at m = 4). `discrete=True`: the exact EDF
    ([`edf_discrete`][hrgjax.allan.edf_discrete]) up to m =
    [`DISCRETE_EDF_M`][hrgjax.allan.DISCRETE_EDF_M], Greenhall's beyond.

    **Raises:** `ValueError` where the variance does not converge (α + 2d ≤ 1) or the data
    are shorter than the filter."""
    args = tuple(v.item() if isinstance(v, np.generic) else v
                 for v in (alpha, d, m, n, overlapping, modified, discrete))  # fmt: skip
    try:
        return _edf_greenhall(*args)
    except TypeError:  # an unhashable argument (an array): not kept
        return _edf_greenhall.__wrapped__(*args)


def _filter_length(d, m, n, modified):
    """Phase points one term spans; ValueError where the record is shorter."""
    length = m + m * d if modified else 1 + m * d
    if n < length:
        raise ValueError(f"n = {n} phase points are fewer than the filter's {length:g}")
    return length


@functools.lru_cache(maxsize=4096)
def _edf_greenhall(alpha, d, m, n, overlapping, modified, discrete=False):
    """`edf_greenhall`, kept: the records of one length share their octaves' EDFs."""
    if alpha + 2 * d <= 1:
        raise ValueError(f"alpha = {alpha} needs alpha + 2d > 1 (d = {d})")
    if discrete and m <= DISCRETE_EDF_M and alpha <= 2:
        return edf_discrete(alpha, d, m, n, overlapping, modified)
    s = int(m) if overlapping else 1
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
(they fall as lag⁻² or faster: the rest changes the EDF by < 2e-7 at 65 537 points)."""


def edf_discrete(alpha: int, d: int, m: int, n: int, overlapping: bool, modified: bool):
    """Exact EDF of a d-th difference variance at factor `m` over `n` phase points for
    discrete power-law noise α: (tr AΣ)²/tr (AΣ)², AΣ the estimator's quadratic form on the
    noise's covariance, i.e. (M·R₀)² / (M·R₀² + 2 Σₖ (M − k)·R_k²) over the M terms the
    estimator averages, R_k the covariance of terms k strides apart.

    The noise (Kasdin's discrete power laws, as allantools' generators): the phase is white
    (α = 2) or a p-fold running sum of white noise (α = 0, −2, −4: p = 1, 2, 3) or of
    ARFIMA(0, −½, 0) noise, autocovariance −1/(4k² − 1) (flicker, α = 1, −1, −3: p = 1, 2,
    3) — white rate noise is the exact point-sampled continuous one. Cost O(d·m) (white,
    random walk), O(d²m²) (flicker); d, α, `overlapping`, `modified` as
    [`edf_greenhall`][hrgjax.allan.edf_greenhall].

    **Raises:** `ValueError` where the variance does not converge (α + 2d ≤ 1), for
    α > 2 or the data shorter than the filter."""
    alpha, d, m, n = int(alpha), int(d), int(m), int(n)
    if alpha + 2 * d <= 1 or alpha > 2:
        raise ValueError(f"alpha = {alpha} needs 1 - 2d < alpha <= 2 (d = {d})")
    _filter_length(d, m, n, modified)
    c = np.zeros(d * m + 1)
    c[::m] = [(-1) ** k * math.comb(d, k) for k in range(d + 1)]
    c = np.convolve(c, np.ones(m)) / m if modified else c
    stride = 1 if overlapping else m
    terms = 1 + (n - c.size) // stride
    for _ in range((3 - alpha) // 2 if alpha % 2 else (2 - alpha) // 2):
        c = np.cumsum(c[::-1])[::-1][1:]  # the filter on the increments of one sum fewer
    rc = np.correlate(c, c, mode="full")  # lags −(L − 1) … L − 1
    size = c.size
    if alpha % 2 == 0:  # white increments: R is the filter's own correlation
        r = rc[size - 1 : size + min((terms - 1) * stride, size - 1)]
    else:
        top = min((terms - 1) * stride, FLICKER_LAGS * size)
        k = np.arange(-(size - 1), top + size, dtype=float)
        r = np.convolve(-1.0 / (4.0 * k * k - 1.0), rc, mode="valid")[: top + 1]
    r = r[::stride]
    weight = terms - np.arange(r.size)
    return float((terms * r[0]) ** 2 / (terms * r[0] ** 2 + 2 * np.sum(weight[1:] * r[1:] ** 2)))


def confidence_interval(dev, edf, ci: float = ONE_SIGMA):
    """χ² interval (low, high) of deviations `dev` (any unit; the interval in it) with `edf`
    degrees of freedom at level `ci`: σ²·edf/χ²(1 − p) … σ²·edf/χ²(p), p = (1 − ci)/2
    (NIST SP 1065 eq. 45), for any ci in (0, 1).

    **Raises:** `ValueError` for a `ci` outside (0, 1) or an EDF ≤ 0."""
    if not (is_finite_real(ci) and 0.0 < ci < 1.0):
        raise ValueError(f"ci must be a confidence level in (0, 1); got {describe(ci)}")
    dev, edf = np.asarray(dev, dtype=float), np.asarray(edf, dtype=float)
    p = (1.0 - ci) / 2
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


def chi2_sf(x: float, dof: float) -> float:
    """Upper tail probability P(χ²_dof > x) (float64 whatever JAX's precision)."""
    return 1.0 - _gammainc(dof / 2.0, max(x, 0.0) / 2.0)


def chi2_ppf(q: float, k: float) -> float:
    """The q-quantile of the χ² distribution with k (> 0, real) degrees of freedom.

    **Raises:** `ValueError` for k ≤ 0 (or NaN) or q outside (0, 1)."""
    q, k = float(q), float(k)
    if not k > 0:
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
