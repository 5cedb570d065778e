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
the same expectation): [`mtotvar_bias`][hrgjax.allan.total.mtotvar_bias] gives it
exactly, from one run's quadratic form (a stored table) — ½ at m = 1 (each 3-point run
less its offset is [a, b, a], whose reflection gives (Δ²x)²/2: Mod Totvar = Mod σ²/2 on
every record), then
for α = 2 … −2 at m = 2: 0.998, 0.899, 0.814, 0.744, 0.687, and for large m 0.995, 0.851,
0.771, 0.717, 0.679. [`deviation`][hrgjax.allan.deviation] divides it out unless
`bias_correction=False` (the raw estimator: allantools', and Stable32's tables without its
bias option); under `noise_rule="stable32"` it divides by Stable32's
[`MTOTVAR_BIAS`][hrgjax.allan.total.MTOTVAR_BIAS] instead. The EDF
([`edf_mtotdev`][hrgjax.allan.total.edf_mtotdev]) is fitted to the exact EDF of the
estimator's quadratic form; SP 1065's Table 8 under `noise_rule="stable32"`. Each factor
costs O(N·m) (every run is reflected and averaged), ≈ N² over the octaves
([`mtotdev_points`][hrgjax.allan.total.mtotdev_points]): a 10⁴-point record's octaves take
≈ 5 s on one core, 4·10⁴ points' ≈ 60 s, 10⁶ points' days — choose `taus` accordingly
(`deviation` shows a progress bar from ≈ 2 s of work on,
`hrgjax.allan.result.STEPPED_COST`).
"""

from __future__ import annotations

from contextlib import nullcontext

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
m = 4 … 341 (r = 3 … 256), within 3.5 % where m ≥ 8 (N = 2 049, 5 000, 65 536; 5 % at
N = 300) and 8 % at m = 4–5 (`benchmarks/coverage_mtotdev.py --exact`). Used at m = 2–3
too, outside that range: 0.88–1.03× the exact EDF at m = 2 and 0.96–1.02× at m = 3 for
N ≥ 300, down to 0.75× (a wider interval) for rate noises at m = 2 where N ≤ 50."""

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
"""[`mtotvar_bias`][hrgjax.allan.total.mtotvar_bias] is exact at m up to this (a stored
table); beyond, its value at 127 or 128 (the same parity), within 3e-4 of the large-m limit."""

_ELEMENTS = 2_000_000  # extended points held at once (chunks of runs)


def mtotdev_points(n: int, ms) -> list[int]:
    """The extended points `mtotdev_curve` computes at each factor of `ms` over `n` phase
    points: 9m per run of 3m points, (N − 3m + 1)·9m a factor — its cost, ≈ N² in all at
    the long factors (≈ 4·10⁷ points a second on one core: 10⁴ samples' octaves 2.2·10⁸,
    ≈ 5 s; 4·10⁴ samples' ≈ 60 s)."""
    return [max(n - 3 * int(k) + 1, 0) * 9 * int(k) for k in ms]


def mtotdev_curve(x, ms, progress=None) -> tuple[np.ndarray, np.ndarray]:
    """`(mtotdev, runs)` at factors `ms` of phase `x` (1-D, angle units, τ₀ = 1: the caller
    divides by τ₀); `runs` = N − 3m + 1 per factor (0 where 3m > N, with NaN). `progress`:
    what to `update(n)` with each factor's `mtotdev_points` (the caller's bar, or one that
    shows nothing); default a bar of its own."""
    check_1d("x", x, "one phase (angle) sample per interval")
    x = np.asarray(x, dtype=float)
    n = x.size
    # a line through the ends taken off first (each run's own line removes any line exactly):
    # a frequency offset would otherwise grow the running sum as offset·n²/2 and cancel the
    # noise out of its differences
    x = x - x[0] - (x[-1] - x[0]) / max(n - 1, 1) * np.arange(n)
    prefix = np.concatenate([[0.0], np.cumsum(x)])
    out, counts = [], []
    work = mtotdev_points(n, ms)  # extended points per factor
    with (
        bar(sum(work), "mtotdev", unit="pt") if progress is None else nullcontext(progress) as shown
    ):
        for m, done in zip((int(k) for k in ms), work, strict=True):
            out_m, runs = _one_factor(x, prefix, m)
            out.append(out_m)
            counts.append(runs)
            shown.update(done)
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


def _increment_autocovariance(alpha: int, size: int) -> np.ndarray:
    """γ(k), k < `size`, of the stationary increments that drive discrete power-law noise
    α: white (α = 2, 0, −2) or ARFIMA(0, −½, 0) (α = 1, −1: γ(0) = Γ(2)/Γ(3/2)² = 4/π,
    γ(k) = γ(k − 1)(k − 3/2)/(k + 1/2)). They are the phase itself (2), its first
    difference (1, 0), or its second (−1, −2)."""
    g = np.zeros(size)
    if alpha % 2:
        k = np.arange(1, size)
        g[0] = 4.0 / np.pi
        g[1:] = g[0] * np.cumprod((k - 1.5) / (k + 0.5))
    else:
        g[0] = 1.0
    return g


def _bias(alpha: int, m: int) -> float:
    """E[Mod Totvar]/Mod σ² at factor m for noise α, the source of `_BIAS_TABLE`, in
    O(m² log m): each of one run's 6m rows (a combination of the run's phase that ignores a
    line) written on the noise's stationary increments by summing by parts (x_k = Σ_{l<k}
    u_l; Σr = Σk·r_k = 0 make the sums close), its variance Σ_k γ(k)·(the row's
    autocorrelation at lag k) by FFT. Equal to the dense form Σ_kl r_k r_l C_kl over the
    phase's generalised covariance C (14eefff's, O(m³)) within 3e-13 at every m ≤ 128."""
    rows = _run_rows(m)
    order = {2: 0, 1: 1, 0: 1, -1: 2, -2: 2}[alpha]
    for _ in range(order):  # Σ_k r_k x_k = −Σ_l (Σ_{k≤l} r_k) u_l where Σ_k r_k = 0
        rows = -np.cumsum(rows, axis=1)[:, :-1]
    size = rows.shape[1]
    length = 1 << (2 * size - 1).bit_length()  # ≥ 2·size − 1: no lag wraps round
    spectrum = np.fft.rfft(rows, length, axis=1)
    autocorrelation = np.fft.irfft(np.abs(spectrum) ** 2, length, axis=1)[:, :size]
    g = _increment_autocovariance(alpha, size)
    variance = autocorrelation @ (np.r_[1.0, 2.0 * np.ones(size - 1)] * g)
    return float(np.mean(variance) / variance[3 * m])  # row 3m: the run's own Mod σ² term


# fmt: off
_BIAS_TABLE = {
    2: (
        0.500000000, 0.997942387, 0.937530864, 0.996013374, 0.972638889, 0.995605345, 0.982751448,
        0.995458783, 0.987104117, 0.995390288, 0.989405299, 0.995352906, 0.990785321, 0.995330306,
        0.991686663, 0.995315615, 0.992312788, 0.995305531, 0.992768469, 0.995298313, 0.993112400,
        0.995292969, 0.993379683, 0.995288903, 0.993592433, 0.995285738, 0.993765192, 0.995283226,
        0.993907867, 0.995281199, 0.994027414, 0.995279540, 0.994128844, 0.995278164, 0.994215850,
        0.995277012, 0.994291205, 0.995276036, 0.994357029, 0.995275203, 0.994414969, 0.995274486,
        0.994466318, 0.995273865, 0.994512110, 0.995273323, 0.994553174, 0.995272847, 0.994590187,
        0.995272427, 0.994623705, 0.995272055, 0.994654188, 0.995271723, 0.994682020, 0.995271426,
        0.994707524, 0.995271159, 0.994730974, 0.995270919, 0.994752604, 0.995270701, 0.994772611,
        0.995270503, 0.994791169, 0.995270324, 0.994808426, 0.995270159, 0.994824511, 0.995270009,
        0.994839538, 0.995269871, 0.994853606, 0.995269744, 0.994866802, 0.995269627, 0.994879203,
        0.995269519, 0.994890877, 0.995269419, 0.994901887, 0.995269326, 0.994912285, 0.995269239,
        0.994922121, 0.995269159, 0.994931439, 0.995269084, 0.994940277, 0.995269014, 0.994948671,
        0.995268948, 0.994956653, 0.995268887, 0.994964253, 0.995268829, 0.994971497, 0.995268775,
        0.994978409, 0.995268724, 0.994985012, 0.995268676, 0.994991324, 0.995268631, 0.994997365,
        0.995268588, 0.995003151, 0.995268548, 0.995008699, 0.995268510, 0.995014022, 0.995268474,
        0.995019133, 0.995268440, 0.995024045, 0.995268407, 0.995028770, 0.995268376, 0.995033317,
        0.995268347, 0.995037696, 0.995268319, 0.995041917, 0.995268293, 0.995045987, 0.995268267,
        0.995049915, 0.995268243,
    ),
    1: (
        0.500000000, 0.898598251, 0.852571585, 0.870573774, 0.857610615, 0.861849166, 0.856214637,
        0.858002775, 0.854949755, 0.855951353, 0.854064682, 0.854719889, 0.853448330, 0.853918637,
        0.853007504, 0.853365943, 0.852682737, 0.852967423, 0.852436914, 0.852669897, 0.852246409,
        0.852441451, 0.852095740, 0.852261947, 0.851974465, 0.852118144, 0.851875349, 0.852001029,
        0.851793257, 0.851904288, 0.851724463, 0.851823387, 0.851666212, 0.851754995, 0.851616429,
        0.851696622, 0.851573530, 0.851646374, 0.851536285, 0.851602786, 0.851503731, 0.851564714,
        0.851475100, 0.851531251, 0.851449779, 0.851501671, 0.851427270, 0.851475386, 0.851407164,
        0.851451918, 0.851389128, 0.851430870, 0.851372882, 0.851411918, 0.851358194, 0.851394786,
        0.851344868, 0.851379246, 0.851332738, 0.851365104, 0.851321663, 0.851352194, 0.851311523,
        0.851340375, 0.851302213, 0.851329525, 0.851293645, 0.851319540, 0.851285740, 0.851310329,
        0.851278430, 0.851301813, 0.851271657, 0.851293923, 0.851265368, 0.851286597, 0.851259517,
        0.851279782, 0.851254065, 0.851273432, 0.851248975, 0.851267504, 0.851244215, 0.851261961,
        0.851239757, 0.851256770, 0.851235576, 0.851251901, 0.851231649, 0.851247328, 0.851227955,
        0.851243027, 0.851224476, 0.851238977, 0.851221196, 0.851235157, 0.851218098, 0.851231551,
        0.851215171, 0.851228144, 0.851212401, 0.851224919, 0.851209777, 0.851221864, 0.851207289,
        0.851218968, 0.851204928, 0.851216220, 0.851202684, 0.851213608, 0.851200551, 0.851211125,
        0.851198520, 0.851208762, 0.851196586, 0.851206511, 0.851194742, 0.851204365, 0.851192983,
        0.851202317, 0.851191303, 0.851200362, 0.851189697, 0.851198494, 0.851188162, 0.851196708,
        0.851186693, 0.851194998,
    ),
    0: (
        0.500000000, 0.814403292, 0.781111111, 0.783670721, 0.776538462, 0.776583854, 0.773929499,
        0.773977500, 0.772670419, 0.772747905, 0.771990584, 0.772073693, 0.771586458, 0.771665005,
        0.771327978, 0.771398876, 0.771153103, 0.771216020, 0.771029464, 0.771085024, 0.770938907,
        0.770987994, 0.770870635, 0.770914134, 0.770817911, 0.770856617, 0.770776359, 0.770810956,
        0.770743036, 0.770774104, 0.770715909, 0.770743934, 0.770693534, 0.770718923, 0.770674863,
        0.770697959, 0.770659123, 0.770680213, 0.770645731, 0.770665060, 0.770634244, 0.770652018,
        0.770624316, 0.770640712, 0.770615678, 0.770630848, 0.770608116, 0.770622190, 0.770601458,
        0.770614549, 0.770595566, 0.770607773, 0.770590327, 0.770601735, 0.770585648, 0.770596332,
        0.770581451, 0.770591478, 0.770577674, 0.770587101, 0.770574261, 0.770583141, 0.770571167,
        0.770579546, 0.770568355, 0.770576272, 0.770565789, 0.770573283, 0.770563444, 0.770570547,
        0.770561293, 0.770568035, 0.770559317, 0.770565725, 0.770557497, 0.770563594, 0.770555816,
        0.770561625, 0.770554261, 0.770559801, 0.770552820, 0.770558110, 0.770551482, 0.770556538,
        0.770550237, 0.770555074, 0.770549076, 0.770553709, 0.770547993, 0.770552434, 0.770546981,
        0.770551241, 0.770546033, 0.770550123, 0.770545144, 0.770549075, 0.770544310, 0.770548090,
        0.770543526, 0.770547163, 0.770542788, 0.770546291, 0.770542092, 0.770545468, 0.770541436,
        0.770544691, 0.770540816, 0.770543958, 0.770540230, 0.770543263, 0.770539675, 0.770542606,
        0.770539150, 0.770541983, 0.770538651, 0.770541392, 0.770538178, 0.770540831, 0.770537729,
        0.770540297, 0.770537302, 0.770539790, 0.770536895, 0.770539307, 0.770536508, 0.770538847,
        0.770536139, 0.770538408,
    ),
    -1: (
        0.500000000, 0.744148663, 0.724778957, 0.723904313, 0.720388272, 0.720063907, 0.718811152,
        0.718753181, 0.718142362, 0.718157128, 0.717803074, 0.717837116, 0.717608490, 0.717645702,
        0.717486838, 0.717522177, 0.717405800, 0.717437847, 0.717349135, 0.717377720, 0.717307970,
        0.717333344, 0.717277128, 0.717299660, 0.717253426, 0.717273488, 0.717234819, 0.717252750,
        0.717219944, 0.717236037, 0.717207866, 0.717222372, 0.717197925, 0.717211055, 0.717189645,
        0.717201578, 0.717182676, 0.717193562, 0.717176754, 0.717186722, 0.717171680, 0.717180839,
        0.717167299, 0.717175741, 0.717163491, 0.717171295, 0.717160160, 0.717167394, 0.717157229,
        0.717163954, 0.717154637, 0.717160903, 0.717152334, 0.717158185, 0.717150277, 0.717155754,
        0.717148434, 0.717153570, 0.717146775, 0.717151602, 0.717145277, 0.717149821, 0.717143919,
        0.717148205, 0.717142686, 0.717146733, 0.717141561, 0.717145390, 0.717140532, 0.717144160,
        0.717139590, 0.717143032, 0.717138724, 0.717141994, 0.717137926, 0.717141037, 0.717137190,
        0.717140152, 0.717136509, 0.717139333, 0.717135878, 0.717138574, 0.717135292, 0.717137868,
        0.717134747, 0.717137210, 0.717134239, 0.717136597, 0.717133765, 0.717136025, 0.717133322,
        0.717135489, 0.717132907, 0.717134988, 0.717132518, 0.717134517, 0.717132153, 0.717134075,
        0.717131810, 0.717133659, 0.717131487, 0.717133268, 0.717131183, 0.717132899, 0.717130896,
        0.717132550, 0.717130625, 0.717132221, 0.717130369, 0.717131909, 0.717130126, 0.717131614,
        0.717129896, 0.717131335, 0.717129678, 0.717131070, 0.717129472, 0.717130818, 0.717129275,
        0.717130578, 0.717129088, 0.717130351, 0.717128911, 0.717130134, 0.717128741, 0.717129928,
        0.717128580, 0.717129731,
    ),
    -2: (
        0.500000000, 0.686625514, 0.681418440, 0.681195012, 0.679974708, 0.679872552, 0.679399655,
        0.679386653, 0.679146872, 0.679157739, 0.679015789, 0.679032329, 0.678939511, 0.678956351,
        0.678891337, 0.678906894, 0.678859009, 0.678872920, 0.678836279, 0.678848586, 0.678819696,
        0.678830564, 0.678807231, 0.678816846, 0.678797625, 0.678806165, 0.678790068, 0.678797686,
        0.678784016, 0.678790843, 0.678779094, 0.678785241, 0.678775038, 0.678780597, 0.678771656,
        0.678776705, 0.678768807, 0.678773410, 0.678766384, 0.678770597, 0.678764307, 0.678768176,
        0.678762512, 0.678766077, 0.678760951, 0.678764245, 0.678759585, 0.678762638, 0.678758383,
        0.678761220, 0.678757319, 0.678759962, 0.678756373, 0.678758841, 0.678755528, 0.678757838,
        0.678754771, 0.678756937, 0.678754089, 0.678756124, 0.678753474, 0.678755389, 0.678752916,
        0.678754721, 0.678752408, 0.678754114, 0.678751946, 0.678753559, 0.678751523, 0.678753051,
        0.678751135, 0.678752585, 0.678750778, 0.678752156, 0.678750450, 0.678751760, 0.678750147,
        0.678751395, 0.678749867, 0.678751056, 0.678749607, 0.678750742, 0.678749366, 0.678750450,
        0.678749141, 0.678750179, 0.678748932, 0.678749925, 0.678748737, 0.678749688, 0.678748554,
        0.678749467, 0.678748384, 0.678749260, 0.678748223, 0.678749065, 0.678748073, 0.678748882,
        0.678747932, 0.678748710, 0.678747799, 0.678748548, 0.678747673, 0.678748395, 0.678747555,
        0.678748251, 0.678747443, 0.678748115, 0.678747338, 0.678747986, 0.678747238, 0.678747864,
        0.678747143, 0.678747748, 0.678747053, 0.678747639, 0.678746968, 0.678747535, 0.678746887,
        0.678747436, 0.678746810, 0.678747341, 0.678746737, 0.678747252, 0.678746667, 0.678747166,
        0.678746601, 0.678747085,
    ),
}
# fmt: on
"""`_bias(α, m)` for α = 2 … −2, m = 1 … 128, to 9 decimals (`benchmarks/coverage_mtotdev.py
--bias-table` prints it from `_bias` and checks every entry against a dense form built
from SP 1065 eq. 27's steps). Stored: `_bias` costs ≈ 25 ms per entry at m = 128, ≈ 0.8 s
for one α's 128 factors (a `taus="all"` mtotdev's first call), ≈ 4 s for all five."""


def mtotvar_bias(alpha: int, m: int) -> float:
    """E[Mod Totvar]/Mod σ² of the raw estimator at factor `m` (≥ 1) for power-law noise `alpha`
    (rate PSD ∝ f^α, clamped to −2…2), exact: the mean of one run's 6m reflected second
    differences' variances over its own Mod σ² term's, for the discrete noise (white phase,
    white rate, random-walk rate; flicker as ARFIMA(0, −½, 0)), the same for every run and N.
    ½ at m = 1; at m = 2: 0.998, 0.899, 0.814, 0.744, 0.687 for α = 2 … −2; large m: 0.995,
    0.851, 0.771, 0.717, 0.679 (odd m a little lower for white angle noise: 0.938 at m = 3,
    whose detrending leaves out the middle point). Exact for these discrete noises: at small
    m b follows the noise's high frequencies (point samples of a continuous 1/f phase cut
    off at 0.15/τ₀ … 50/τ₀: b(2) = 0.77–0.96 for α = 1, within 1 % of ARFIMA's from m ≈
    32–64; a continuous Brownian rate: 0.675 for α = −2). Read from a stored table (9
    decimals) up to m = 128 ([`BIAS_EXACT_TO`][hrgjax.allan.total.BIAS_EXACT_TO]), beyond
    it the value at 127 or 128."""
    alpha, m = int(min(max(alpha, -2), 2)), int(m)
    if m < 1:
        raise ValueError(f"m must be an averaging factor ≥ 1; got {m}")
    if m > BIAS_EXACT_TO:
        m = BIAS_EXACT_TO - (m - BIAS_EXACT_TO) % 2
    return _BIAS_TABLE[alpha][m - 1]


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
