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
units). The EDF is SP 1065's Table 8, b·(T/τ) − c with T/τ = N/m phase points per τ
([`EDF_MTOTDEV`][hrgjax.allan.total.EDF_MTOTDEV]). The estimator is biased low, by a factor
that depends on the noise type ([`MTOTVAR_BIAS`][hrgjax.allan.total.MTOTVAR_BIAS]);
[`deviation`][hrgjax.allan.deviation] divides it out unless `bias_correction=False` (the raw
estimator: allantools', and Stable32's tables without its bias option). Each factor costs O(N·m) (every run is reflected
and averaged): a 10⁴-point record's octaves take well under a second, 10⁶ points' long τ
minutes — choose `taus` accordingly.
"""

from __future__ import annotations

import numpy as np

from .._checks import check_1d
from .._progress import bar
from .uncertainty import edf_greenhall

EDF_MTOTDEV = {2: (1.90, 2.10), 1: (1.20, 1.40), 0: (1.10, 1.20), -1: (0.85, 0.50),
               -2: (0.75, 0.31)}  # fmt: skip
"""NIST SP 1065 Table 8: noise type α → (b, c) with EDF = b·(N/m) − c."""

MTOTVAR_BIAS = {2: 0.94, 1: 0.83, 0: 0.73, -1: 0.70, -2: 0.69}
"""E[Mod Totvar]/Mod σ² by noise type α (Howe & Vernotte; Riley's table): with
`bias_correction` the deviation is divided by its square root, as Stable32's bias-corrected
tables are (PHASE.DAT's 158-τ ttotdev table: within 5e-5). These are Stable32's convention,
kept for that agreement, not this estimator's measured bias: over 100 records of 3000
samples (m = 4–64) the ratio E[raw Mod Totvar]/E[Mod σ²] is 0.77–0.78 for white rate
noise (α = 0) and 0.995 for white angle noise (α = 2), so the corrected deviation reads
≈ 3 % high there; for a rate random walk it is 0.68 (agrees)."""

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


SMALL_M_EDF_CAP = 2
"""Up to this factor m the EDF of mtotdev is at most the Greenhall EDF of mdev
([`edf_mtotdev`][hrgjax.allan.total.edf_mtotdev])."""


def edf_mtotdev(alpha: int, m: int, n: int) -> float:
    """EDF of mtotdev (and ttotdev) at factor `m` over `n` phase points (3m ≤ n) for noise
    type `alpha` (rate PSD ∝ f^α, clamped to −2…2): SP 1065 Table 8's b·(N/m) − c, at least
    1. At m = 1–2 ([`SMALL_M_EDF_CAP`][hrgjax.allan.total.SMALL_M_EDF_CAP]) at most the
    Greenhall EDF of mdev over the same record (as many terms, N − 3m + 1): there Table 8
    exceeds the terms averaged or the Monte Carlo EDF (2001 points, 1000 records: white rate
    noise 2200 at m = 1 against 1999 terms and a Monte Carlo 1390 ± 60, capped to 1565;
    white angle noise 3800 and 1899 at m = 1, 2 against 1015 and 1280, capped to 1028 and
    934), so its intervals were too narrow.
    From m = 3 on Table 8 is kept: mtotdev has more EDF than mdev at long τ (white rate
    noise, m = 2–8: Monte Carlo 1.3–1.4× mdev's Greenhall EDF, Table 8 1.1–1.15×)."""
    alpha = int(min(max(alpha, -2), 2))
    b, c = EDF_MTOTDEV[alpha]
    edf = b * n / m - c
    if m <= SMALL_M_EDF_CAP:
        edf = min(edf, edf_greenhall(alpha, 2, int(m), int(n), overlapping=True, modified=True))
    return max(edf, 1.0)
