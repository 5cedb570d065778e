r"""The modified total deviation (mtotdev) and the time total deviation (ttotdev), in NumPy
(NIST SP 1065 eq. 27–28, Howe & Vernotte 1999).

For each of the N − 3m + 1 runs of 3m phase points $x_i \ldots x_{i+3m-1}$:

1. the run's frequency offset is removed: the mean of its first ⌊3m/2⌋ points and of its
   last ⌊3m/2⌋ points, their difference over their distance (3m/2 samples, or (3m + 1)/2
   where 3m is odd), taken off as a line;
2. the run is extended to 9m points by uninverted even reflection at both ends
   (reversed, itself, reversed);
3. the 6m overlapping second differences of its m-point averages are squared and averaged.

$$\mathrm{Mod\,Tot}\sigma^2(\tau) = \frac{1}{2\tau^2(N-3m+1)}\sum_i
\frac1{6m}\sum_{j=0}^{6m-1}\Big(\frac{S_j - 2S_{j+m} + S_{j+2m}}{m}\Big)^2,$$

$S_j$ the sum of m extended points from j, τ = mτ₀; ttotdev = τ·mtotdev/√3 (in angle
units). The estimator is biased low, by a factor b(α, m) = E[Mod Totvar]/Mod σ² that
depends on the noise type and on m but not on N (every run's detrended, reflected form has
the same expectation): [`mtotvar_bias`][hrgjax.allan.total.mtotvar_bias] computes it
exactly from one run's quadratic form — ½ at m = 1 (each 3-point run less its offset is
[a, b, a], whose reflection gives (Δ²x)²/2: Mod Totvar = Mod σ²/2 on every record), then
for α = 2 … −2 at m = 2: 0.998, 0.899, 0.814, 0.744, 0.687, and for large m 0.995, 0.851,
0.771, 0.717, 0.679. [`deviation`][hrgjax.allan.deviation] divides it out unless
`bias_correction=False` (the raw estimator: allantools', and Stable32's tables without its
bias option); under `noise_rule="stable32"` it divides by Stable32's
[`MTOTVAR_BIAS`][hrgjax.allan.total.MTOTVAR_BIAS] instead. The EDF
([`edf_mtotdev`][hrgjax.allan.total.edf_mtotdev]) is fitted to the exact EDF of the
estimator's quadratic form; SP 1065's Table 8 under `noise_rule="stable32"`. Each factor
costs O(N·m) (every run is reflected and averaged): a 10⁴-point record's octaves take well
under a second, 10⁶ points' long τ minutes — choose `taus` accordingly.
"""

from __future__ import annotations

import functools

import numpy as np

from .._checks import check_1d
from .._progress import bar
from .uncertainty import edf_greenhall

EDF_MTOTDEV = {2: (1.90, 2.10), 1: (1.20, 1.40), 0: (1.10, 1.20), -1: (0.85, 0.50),
               -2: (0.75, 0.31)}  # fmt: skip
"""NIST SP 1065 Table 8: noise type α → (b, c) with EDF = b·(N/m) − c (used under
`noise_rule="stable32"`)."""

EDF_MTOTDEV_FIT = {2: (1.766, 3.561, 5.48), 1: (1.263, 3.791, 7.376), 0: (1.123, 3.409, 6.104),
                   -1: (1.052, 3.330, 5.285), -2: (0.837, 3.053, 5.367)}  # fmt: skip
"""Noise type α → (b, c, d) with EDF = b·r − c + d/r, r = N/m phase points per τ: fitted
to the exact EDF (tr AΣ)²/tr (AΣ)² of the estimator's quadratic form over N = 1 025 points,
m = 4 … 341 (r = 3 … 256), within 3 % where m ≥ 8 (N = 2 049 checked) and 8 % at m = 4–5
(`benchmarks/coverage_mtotdev.py --exact`)."""

EDF_MTOTDEV_WHITE_ANGLE = {2: 0.70, 3: 0.79, 4: 0.93}
"""White angle noise (α = 2) at m = 2–4: the exact EDF per N/m is this share of the fit's
slope (1.23, 1.39, 1.63 against 1.77 at N = 1 025 and 2 049)."""

MTOTVAR_BIAS = {2: 0.94, 1: 0.83, 0: 0.73, -1: 0.70, -2: 0.69}
"""Stable32's E[Mod Totvar]/Mod σ² by noise type α (Howe & Vernotte; Riley's table), used
under `noise_rule="stable32"` to reproduce Stable32's bias-corrected tables (PHASE.DAT's
158-τ ttotdev table: within 5e-5). Not this estimator's bias: that is ½ at m = 1 and
0.995, 0.851, 0.771, 0.717, 0.679 for large m ([`mtotvar_bias`][hrgjax.allan.total.mtotvar_bias]),
so these divisors made the corrected deviation 0.73–0.85× mdev at τ₀ and up to 6 % high
(white angle, flicker angle and white rate noise) beyond."""

BIAS_EXACT_TO = 128
"""[`mtotvar_bias`][hrgjax.allan.total.mtotvar_bias] is computed at m up to this; beyond,
its value at 127 or 128 (the same parity), within 3e-4 of the large-m limit."""

_ELEMENTS = 2_000_000  # extended points held at once (chunks of runs)


def mtotdev_curve(x, ms) -> tuple[np.ndarray, np.ndarray]:
    """`(mtotdev, runs)` at factors `ms` of phase `x` (1-D, angle units, τ₀ = 1: the caller
    divides by τ₀); `runs` = N − 3m + 1 per factor (0 where 3m > N, with NaN)."""
    check_1d("x", x, "one phase (angle) sample per interval")
    x = np.asarray(x, dtype=float)
    n = x.size
    # a line through the ends taken off first (each run's own line removes any line exactly):
    # a frequency offset would otherwise grow the running sum as offset·n²/2 and cancel the
    # noise out of its differences
    x = x - x[0] - (x[-1] - x[0]) / max(n - 1, 1) * np.arange(n)
    prefix = np.concatenate([[0.0], np.cumsum(x)])
    out, counts = [], []
    work = [max(n - 3 * int(k) + 1, 0) * 9 * int(k) for k in ms]  # extended points per factor
    with bar(sum(work), "mtotdev", unit="pt") as progress:
        for m, done in zip((int(k) for k in ms), work, strict=True):
            out_m, runs = _one_factor(x, prefix, m)
            out.append(out_m)
            counts.append(runs)
            progress.update(done)
    return np.asarray(out), np.asarray(counts, dtype=int)


def _one_factor(x, prefix, m):
    """`(mtotdev, runs)` at factor m of phase `x` with running sum `prefix` (module
    docstring); NaN and 0 where 3m > N."""
    runs = x.size - 3 * m + 1
    if runs < 1:
        return np.nan, 0
    length = 3 * m
    half = length // 2  # both halves' length; the middle point (3m odd) is in neither
    distance = (length - 1) / 2 + 1 if length % 2 else length / 2
    k = np.arange(length + 1)
    # the extension's running sum C(p), p = 0 … 9m, from the run's own R(k) = Σ_{l<k} r_l:
    # reversed part R(3m) − R(3m − p), then R(3m) + R(p − 3m), then 3R(3m) − R(9m − p)
    p = np.arange(9 * m + 1)
    index = np.where(p <= length, length - p, np.where(p <= 2 * length, p - length, 3 * length - p))
    sign = np.where((p <= length) | (p > 2 * length), -1.0, 1.0)
    whole = np.where(p <= 2 * length, 1.0, 3.0)
    total = 0.0
    step = max(1, _ELEMENTS // (9 * m))
    for lo in range(0, runs, step):
        i = np.arange(lo, min(lo + step, runs))
        first = (prefix[i + half] - prefix[i]) / half
        last = (prefix[i + length] - prefix[i + length - half]) / half
        slope = (last - first) / distance
        # R(k) of the detrended run x_{i+l} − slope·l
        r = prefix[i[:, None] + k] - prefix[i][:, None] - slope[:, None] * (k * (k - 1) / 2)
        c = whole * r[:, -1:] + sign * r[:, index]
        # S_j − 2S_{j+m} + S_{j+2m} = C(j+3m) − 3C(j+2m) + 3C(j+m) − C(j), j < 6m
        second = (c[:, 3 * m :] - 3 * c[:, 2 * m : 8 * m + 1] + 3 * c[:, m : 7 * m + 1]
                  - c[:, : 6 * m + 1])[:, : 6 * m]  # fmt: skip
        total += float(np.sum(np.mean((second / m) ** 2, axis=1)))
    return float(np.sqrt(total / (2.0 * m * m * runs))), runs


def _run_rows(m: int) -> np.ndarray:
    """The 6m second differences (of m-point averages, over m) of one run of 3m points,
    detrended and reflected as `_one_factor` does, as rows over the run's points (6m × 3m)."""
    length = 3 * m
    half = length // 2
    distance = (length - 1) / 2 + 1 if length % 2 else length / 2
    slope = np.zeros(length)
    slope[:half] -= 1.0 / half
    slope[length - half :] += 1.0 / half
    detrend = np.eye(length) - np.outer(np.arange(length), slope / distance)
    order = np.arange(length)
    extended = detrend[np.r_[order[::-1], order, order[::-1]]]  # 9m × 3m
    sums = np.vstack([np.zeros(length), np.cumsum(extended, axis=0)])
    j = np.arange(6 * m)

    def window(a):
        return sums[a + m] - sums[a]

    return (window(j) - 2 * window(j + m) + window(j + 2 * m)) / m


def _run_covariance(alpha: int, length: int) -> np.ndarray:
    """A (generalised) covariance of `length` phase points of discrete power-law noise α:
    white phase (2), the running sum of white (0) or ARFIMA(0, −½, 0) rate (1), the
    double running sum of white (−2) or ARFIMA(0, −½, 0) (−1) rate increments. Good for any
    quadratic form that ignores a line in the phase."""
    if alpha == 2:
        return np.eye(length)
    size = length - 1
    if alpha in (1, -1):  # flicker: ARFIMA(0, d = −½, 0) autocovariance
        g = np.empty(size)
        g[0] = 4.0 / np.pi  # Γ(1 − 2d)/Γ(1 − d)²
        for k in range(1, size):
            g[k] = g[k - 1] * (k - 1.5) / (k + 0.5)
        lag = np.abs(np.subtract.outer(np.arange(size), np.arange(size)))
        gamma = g[lag]
    else:
        gamma = np.eye(size)
    step = np.tril(np.ones((length, size)), -1)  # x_k = Σ_{l<k} u_l
    if alpha <= -1:
        step = step @ np.tril(np.ones((size, size)))  # u: the rate's increments
    return step @ gamma @ step.T


@functools.lru_cache(maxsize=1024)
def _bias(alpha: int, m: int) -> float:
    rows = _run_rows(m)
    variance = np.sum((rows @ _run_covariance(alpha, 3 * m)) * rows, axis=1)
    return float(np.mean(variance) / variance[3 * m])  # row 3m: the run's own Mod σ² term


def mtotvar_bias(alpha: int, m: int) -> float:
    """E[Mod Totvar]/Mod σ² of the raw estimator at factor `m` (≥ 1) for power-law noise `alpha`
    (rate PSD ∝ f^α, clamped to −2…2), exact: the mean of one run's 6m reflected second
    differences' variances over its own Mod σ² term's, for the discrete noise (white phase,
    white rate, random-walk rate; flicker as ARFIMA(0, −½, 0)), the same for every run and N.
    ½ at m = 1; at m = 2: 0.998, 0.899, 0.814, 0.744, 0.687 for α = 2 … −2; large m: 0.995,
    0.851, 0.771, 0.717, 0.679 (odd m a little lower for white angle noise: 0.938 at m = 3,
    whose detrending leaves out the middle point). Beyond m = 128
    ([`BIAS_EXACT_TO`][hrgjax.allan.total.BIAS_EXACT_TO]) the value at 127 or 128."""
    alpha, m = int(min(max(alpha, -2), 2)), int(m)
    if m < 1:
        raise ValueError(f"m must be an averaging factor ≥ 1; got {m}")
    if m > BIAS_EXACT_TO:
        m = BIAS_EXACT_TO - (m - BIAS_EXACT_TO) % 2
    return _bias(alpha, m)


def edf_mtotdev(alpha: int, m: int, n: int, rule: str = "hrgjax") -> float:
    """EDF of mtotdev (and ttotdev) at factor `m` over `n` phase points (3m ≤ n) for noise
    type `alpha` (rate PSD ∝ f^α, clamped to −2…2), at least 1.

    - m = 1: the Greenhall EDF of mdev over the record (Mod Totvar = Mod σ²/2 there, the
      same statistic);
    - m ≥ 2: b·r − c + d/r, r = n/m ([`EDF_MTOTDEV_FIT`][hrgjax.allan.total.EDF_MTOTDEV_FIT],
      fitted to the exact EDF of the quadratic form), for white angle noise at m = 2–4 times
      [`EDF_MTOTDEV_WHITE_ANGLE`][hrgjax.allan.total.EDF_MTOTDEV_WHITE_ANGLE]. SP 1065's
      Table 8 exceeds the exact EDF by up to 1.7× in the last octaves (r = 4, random-walk
      rate: 2.69 against 1.56) and 1.55× for white angle noise at m = 2;
    - `rule="stable32"`: Table 8's b·r − c, at m = 1–2 at most mdev's Greenhall EDF
      ([`SMALL_M_EDF_CAP`][hrgjax.allan.total.SMALL_M_EDF_CAP])."""
    alpha, m, n = int(min(max(alpha, -2), 2)), int(m), int(n)
    greenhall = edf_greenhall(alpha, 2, m, n, True, True, discrete=rule != "stable32")
    if rule == "stable32":
        b, c = EDF_MTOTDEV[alpha]
        edf = b * n / m - c
        if m <= SMALL_M_EDF_CAP:
            edf = min(edf, greenhall)
        return max(edf, 1.0)
    if m == 1:
        return max(greenhall, 1.0)
    b, c, d = EDF_MTOTDEV_FIT[alpha]
    r = n / m
    edf = (b * r - c + d / r) * (EDF_MTOTDEV_WHITE_ANGLE.get(m, 1.0) if alpha == 2 else 1.0)
    return max(edf, 1.0)


SMALL_M_EDF_CAP = 2
"""Under `noise_rule="stable32"`, up to this factor m the EDF of mtotdev is at most the
Greenhall EDF of mdev ([`edf_mtotdev`][hrgjax.allan.total.edf_mtotdev])."""
