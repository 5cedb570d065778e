"""Which power-law noise dominates at each τ: [`noise_id`][hrgjax.allan.noise_id] (the lag-1
autocorrelation of Riley & Greenhall 2004, the B1 and R(n) ratios beyond its reach) and the
ratios' expectations ([`b1_expected`][hrgjax.allan.b1_expected],
[`rn_expected`][hrgjax.allan.rn_expected]), in NumPy (float64, no JAX). The EDF and the χ²
interval that the α feeds are in `hrgjax.allan.uncertainty`."""

from __future__ import annotations

import math

import numpy as np

from .._checks import check_1d, check_flag, check_numbers, describe, finite_number, whole_number

ACF_POINTS = 30
"""The fewest decimated phase points the lag-1 autocorrelation identifies noise from (Riley &
Greenhall 2004; Stable32's and allantools' limit); with fewer, the B1 and R(n) ratios."""
B1_AVERAGES = 8
"""The fewest τ-averages the B1 ratio identifies noise from. Below 8 its expectations for
neighbouring noise types (at N = 4: 2, 1.33, 1 for α = −2, −1, 0) lie within its sampling
spread, and at N = 2 it is 1 whatever the noise; there the factor before is carried on.
`benchmarks/coverage_allan.py` (200 records of 20 000 s each, white rate or angle noise plus
rate random walk): the ±1σ interval at the longest τ (8 192 s) covers the truth in 70–71 % of
records with this rule (59–74 % with the α of the last autocorrelation τ carried on, 58–60 %
with B1 read down to N = 3, before R(n)'s white-rate guard)."""


RN_FACTOR = 4
"""The smallest m from which R(n) = MVAR/AVAR tells white (1/m) from flicker angle noise
and both from rate noise (½ and above); below, all three lie near ½."""
RHO_SPLIT = -0.04
"""The lag-1 ρ = r₁/(1 + r₁) of the twice-differenced decimated phase (m ≥ 2) below which
the default rule reads flicker rather than random-walk rate noise: the midpoint of their
values for averaged rates, ρ = 1 − 8 ln 2/(9 ln 3 − 8 ln 2) = −0.277 (r₁ = 9 ln 3/(8 ln 2) − 2) and
0.2 (r₁ = ¼)."""
RHO_SPLIT_1 = -0.14
"""The same split at m = 1, where the phase may be point-sampled (discrete) noise, ρ = −½ for
flicker and 0 for random-walk rate noise (Riley & Greenhall's −¼ is their midpoint), or rate
data averaged over each sample interval (a counter-gated or rate-integrating gyro's angle
increments), the decimated values −0.277 and 0.2: the midpoint of averaged flicker's −0.277
and the discrete random walk's 0, the two that lie nearest (the split that serves both)."""


NOISE_RULES = ("hrgjax", "stable32")
"""The rules [`noise_id`][hrgjax.allan.noise_id] knows beyond the lag-1 autocorrelation's
reach: `"hrgjax"` (the default) and `"stable32"` (Stable32 1.60's tables)."""


def noise_id(x, m, dmax: int = 2, *, rule: str = "hrgjax", overlapping: bool = True) -> np.ndarray:
    """The power-law noise α (rate PSD ∝ f^α) at each factor `m` of phase (angle) samples
    `x`, as Stable32 identifies it (NIST SP 1065 §5.6):

    - where the phase decimated by m keeps at least [`ACF_POINTS`][hrgjax.allan.ACF_POINTS]
      points, the lag-1 autocorrelation (Riley & Greenhall 2004, as allantools'
      `autocorr_noise_id` with `dmin=0`): a quadratic removed, differenced until
      ρ = r₁/(1 + r₁) < 0.25 or `dmax` times; α = 2 − 2d − round(2ρ);
    - beyond, the B1 ratio (Barnes 1969; Howe, Beard, Greenhall & Riley 2000): the standard
      variance of the N non-overlapping τ-averages over their Allan variance, against its
      expectation B1(N, μ) = N(1 − N^μ)/(2(N − 1)(1 − 2^μ)) for Allan-variance slope μ
      (α = −μ − 1), the boundaries at the geometric means of neighbouring expectations;
      where it says phase noise (μ = −2), the R(n) ratio MVAR/AVAR (1/m for white, 3.37/(1.04
      + 3 ln πm) for flicker phase noise, with f_h = 1/(2τ₀)) tells white from flicker from
      m = 4 on (below, the two expectations coincide: white is taken).

    How far B1 is read is the `rule`:

    - `"hrgjax"` (default): three departures where the reference rule misreads power-law
      noise (`benchmarks/noise_id_table.py`: from ≥ 98 % right at every octave but the
      B1 ones of rate noise, where it was 24–100 %). From m = 4 on
      ([`RN_FACTOR`][hrgjax.allan.RN_FACTOR]) R(n) tells angle from rate
      noise wherever the autocorrelation reads angle noise (on the phase less its quadratic:
      decimation folds flicker angle noise's content above 1/(2mτ₀) into a white floor, and
      the autocorrelation read white in 80–93 % of records at 64–128 points) and before B1
      (B1 of white angle noise on 8–16 averages lies near white rate noise's 1: read as rate
      noise in 30 % of records); there R(n) ≤ its white/flicker-angle boundary names white
      angle noise, and flicker angle noise only where B1 says angle noise too (a random walk
      on few averages, and white angle + white rate noise near their crossover, the
      commonest gyro mixture, fall in its band: read flicker angle noise at T/4 their ±1σ
      held 50–54 %, now 67–71 %; pure flicker angle noise is read right in 66–78 % of
      records at m ≥ 256, the rest white rate noise: conservative, ±1σ 79–88 %). At d = 2 of a decimated phase (m ≥ 2), flicker rate noise below ρ = −0.04
      ([`RHO_SPLIT`][hrgjax.allan.RHO_SPLIT]; averaged rates: −0.28 for flicker, 0.2 for a random walk;
      Riley & Greenhall's −¼ suits their discrete noises' −½ and 0, and read flicker rate
      noise as a random walk in 11–52 % of records); at m = 1 below −0.14
      ([`RHO_SPLIT_1`][hrgjax.allan.RHO_SPLIT_1]), between averaged flicker's −0.28 and a
      point-sampled random walk's 0 (−¼ read averaged flicker rate noise right in 86–94 % of
      records of 2 048–4 096 samples, 63 % of 256; now 100 %, 94 %). B1
      on the
      record as it is, from [`B1_AVERAGES`][hrgjax.allan.B1_AVERAGES] averages on; with
      fewer, the α of the factor before is carried on (for the first factor asked: that of
      the largest m/2, m/4, … that can be read). A record of fewer than `ACF_POINTS` phase
      points (no factor reaches the autocorrelation) is read once, at m = 1 on all its
      averages, and that α given at every factor: B1 read again at m = 2 on 8–14 averages
      misread more (white rate noise of 16 samples read right at m ≥ 2 in 41 of 100
      records, 71 at m = 1; docs/allan.md). On drift-free white + random-walk records
      its ±1σ intervals cover the truth at the nominal rate at every τ
      (`benchmarks/coverage_allan.py`), and on each pure power-law noise from m = 1 to T
      (`benchmarks/coverage_totdev.py`) but the rate noises at τ ≥ T/8 (B1 on ≤ 8
      averages: flicker 46–62 % right, a random walk 56–60 %: `deviation`'s totdev interval
      there spans the rate noises within one step of the type read) and flicker angle noise at m ≥ 256 (read as white rate
      noise in 22–34 % of records: ±1σ 79–88 %, conservative).
    - `"stable32"`: as Stable32 1.60's octave tables of two records, whose α it reproduces
      at every τ of the seven σ kinds: a real OCXO's (90/90, `benchmarks/stable32_ocxo.py`)
      and PHASE.DAT's (57/57, `benchmarks/stable32_phasedat.py --noise-rule stable32`,
      which also prints its mtotdev decade table's 8/8 and the mtotdev and ttotdev octave
      tables' α differing at m = 128, 256; the rule was read off those tables, not from
      Stable32's code): B1 on the rate with its least-squares line (a frequency drift)
      removed, from [`B1_AVERAGES`][hrgjax.allan.B1_AVERAGES] averages on, and with fewer the
      α of the factor before carried on, as by default (PHASE.DAT at m = 128, 7 averages:
      Stable32 carries m = 64's α = 0 on in its octave tables while B1 reads flicker angle
      noise there — and at m = 125–142 of its all-τ table, where the α before is 1, it
      reads 1); the non-overlapping kinds (`overlapping=False`: adev, hdev) carry the last
      autocorrelation α on instead. Stable32's all-τ tables it does not reproduce
      everywhere: their α scatters between neighbouring τ read by B1 (OCXO 1 338 of 1 924
      rows, PHASE.DAT 849 of 991, its mtotdev 104 of 158). On drift-free white +
      random-walk records (`coverage_allan.py --noise-rule stable32`) removing the line
      biases B1 away from the random walk.

    `dmax` = 3 (Hadamard) lets both methods name flicker walk (α = −3).

    **Returns:** an int array, each α within [2 − 2·`dmax`, 2]: the autocorrelation of a
    periodic component (no power law: r₁ → −1) is held to the nearest end of that range.

    **Raises:** `ValueError` for an unknown `rule`, or when no factor of the record can be
    read: fewer than `B1_AVERAGES` + 1 points (fewer than `ACF_POINTS` under `"stable32"`
    with `overlapping=False`); its line names the rate and angle samples of
    `hrgjax.allan.deviation` that this is, and the least of each."""
    return np.fromiter(noise_id_each(x, m, dmax, rule=rule, overlapping=overlapping), dtype=int)


def noise_id_each(x, m, dmax: int = 2, *, rule: str = "hrgjax", overlapping: bool = True):
    """[`noise_id`][hrgjax.allan.noise_id]`(x, m, dmax, rule=..., overlapping=...)` one factor
    at a time: a generator of each factor's α (an int, rate PSD ∝ f^α) in the order of `m`,
    the same values; the whole-record work (the phase's curvature, Stable32's drift-free
    phase) is done once, before the first. For a progress step per factor
    (`hrgjax.allan.deviation` on long records).

    **Raises:** as `noise_id`, when the generator is first advanced."""
    if not isinstance(rule, str) or rule not in NOISE_RULES:
        raise ValueError(f"rule must be one of {list(NOISE_RULES)}; got {describe(rule)}")
    check_numbers("x", x, "real phase (angle) samples, 1-D")  # complex: its real part read
    check_1d("x", x, "one phase (angle) sample per interval")
    x = np.asarray(x, dtype=float)
    if not np.all(np.isfinite(x)):  # NaN was read as "y has no noise to identify"
        i = int(np.argmin(np.isfinite(x)))
        raise ValueError(f"x must be finite; found {x[i]} at index {i} (for records with gaps "
                         "(NaN): hrgjax.allan.deviation)")  # fmt: skip
    dmax = whole_number("dmax", dmax, "the highest difference order 1, 2 or 3 (3: Hadamard)")
    if dmax not in (1, 2, 3):
        raise ValueError(f"dmax must be the highest difference order 1, 2 or 3 (3: Hadamard); "
                         f"got {dmax}")  # fmt: skip
    overlapping = check_flag("overlapping", overlapping)
    if rule == "hrgjax":
        curvature = _curvature(x)  # R(n) on the phase less its quadratic, as the ACF
        read = lambda k: _identify(x, k, dmax, refine=curvature)  # noqa: E731
        needs, least = f"{B1_AVERAGES} averages", B1_AVERAGES + 1
        if x.size < ACF_POINTS:  # no factor reaches the autocorrelation: the whole record's
            whole = read(1)  # B1 at τ₀ (the most averages) at every factor (SHORT_RECORD)
            read = lambda k: whole  # noqa: E731
    elif overlapping:  # B1 on the drift-free record from 8 averages on, no R(n) guard
        drift_free = _less_drift(x)
        read = lambda k: _identify(x, k, dmax, b1_x=drift_free, guard=False)  # noqa: E731
        needs, least = f"{B1_AVERAGES} averages", B1_AVERAGES + 1
    else:  # Stable32's adev and hdev: the autocorrelation, its last α carried beyond
        read, needs = (lambda k: _identify(x, k, dmax, b1_min=None)), f"{ACF_POINTS} points"
        least = ACF_POINTS
    factors = np.asarray(m)
    if (factors.ndim != 1 or factors.dtype.kind not in "iuf"
            or not np.all(np.isfinite(factors)) or np.any(factors != np.round(factors))
            or np.any(factors < 1)):  # fmt: skip
        raise ValueError(
            f"m must be a 1-D array of whole averaging factors >= 1; got {describe(m)}"
        )
    if factors.size and factors.max() > x.size - 1:  # was read as the α carried on
        raise ValueError(f"m must be at most the {x.size - 1} intervals of x's {x.size} phase "
                         f"points (τ ≤ T); got {describe(m)}")  # fmt: skip
    last = None
    for k in factors.astype(int):
        a = read(int(k))
        if a is None and last is None:  # the first factor: from the largest k/2ʲ that can
            j = int(k) // 2
            while a is None and j >= 1:
                a, j = read(j), j // 2
            if a is None:  # x is hrgjax.allan.deviation's phase of its y: both named
                raise ValueError(
                    f"x: {x.size} phase points leave {x.size - 1} averages at m = 1 "
                    f"(hrgjax.allan.deviation: {x.size - 1} rate samples y, or {x.size} angle "
                    f"samples with data='phase'); noise identification needs {needs}: at "
                    f"least {least} phase points, {least - 1} rate samples or {least} angle "
                    "samples (the deviation alone, without its interval: "
                    "hrgjax.allan_deviation(rate, dt))"
                )
        last = last if a is None else a
        yield int(last)


def _less_drift(x):
    """The phase of the rate diff(x) less its least-squares line (Stable32's drift removal
    before B1)."""
    y = np.diff(x)
    t = np.linspace(-1.0, 1.0, y.size)
    y = y - y.mean()
    y = y - t * (np.dot(t, y) / np.dot(t, t))
    return np.concatenate([[0.0], np.cumsum(y)])


def _identify(x, k, dmax, *, b1_x=None, b1_min=B1_AVERAGES, guard=True, refine=None):
    """α at factor k by the lag-1 autocorrelation or, from `b1_min` averages on (None: never),
    B1/R(n) on `b1_x` (default `x`); None where neither reaches. `refine` (the default rule:
    the phase's curvature, `_curvature`): R(n) arbitrates angle against rate noise from
    `RN_FACTOR` on, and the averaged rate noises' ρ split flicker from random walk."""
    z = x[::k]
    if z.size >= ACF_POINTS:
        split = -0.25 if refine is None else RHO_SPLIT if k > 1 else RHO_SPLIT_1
        a = _acf_alpha(z, dmax, split)
        if refine is not None and a >= 1 and k >= RN_FACTOR:
            return _rn_class(_rn(x, k, refine), k, a)
        return a
    if b1_min is not None and (x.size - 1) // k >= b1_min:
        if refine is not None and k >= RN_FACTOR and x.size > 3 * k:
            a, mu = _rn_class(_rn(x, k), k, 0), _b1_mu(x, k, dmax)  # the record as it is
            # R(n) never falls to white angle noise's 1/m unless it is there; flicker angle
            # noise's band is also that of a rate random walk on few averages and of white
            # angle + white rate noise near their crossover (≈ (1/m + ½)/2): flicker angle
            # noise only where B1 says angle noise too (μ = −2), else B1's rate noise
            if a == 2 or (a == 1 and mu == -2):
                return a
            return -max(mu, -1) - 1  # rate noise: B1's μ = −2 is white (α = 0)
        return _b1_alpha(x if b1_x is None else b1_x, k, dmax, white_rate_guard=guard)
    return None


def _acf_alpha(z, dmax, split=-0.25):
    """α from the lag-1 autocorrelation r₁ of `z` less its least-squares quadratic,
    differenced d times until ρ = r₁/(1 + r₁) < 0.25 or d = `dmax` (Riley & Greenhall's
    rule, as Stable32): α = 2 − 2d − round(2ρ). At d = 2, flicker rate noise below `split`
    (≥ −¼): Riley & Greenhall's −¼ is the midpoint of their discrete fractional noises' −½
    and 0; the default rule takes `RHO_SPLIT` for a decimated phase (m ≥ 2: the rate
    averaged over m samples) and `RHO_SPLIT_1` at m = 1."""
    z = np.ascontiguousarray(z, dtype=float)  # an octave's strided view read once
    size, sums, first, last = _detrended_sums(z, dmax)
    d = 0
    while True:
        count = z.size - d
        total, square, lag = sums[d]
        mean = total / count
        power = square - count * mean * mean  # Σ(v − v̄)²: v̄ ≈ 0 after the quadratic's removal
        # no noise: the quadratic's residual at the data's round-off (RMS ≤ 1e-14 of their
        # size; a noise-free quadratic leaves ≤ 1e-15 up to 10⁶ points), or 0 once differenced
        # (a rate's summation leaves more: `check_rate_has_noise` reads the rate itself)
        floor = (1e-14 * size) ** 2 * count if d == 0 else 1e-30 * square
        if not power > max(floor, 1e-300):
            _no_noise()
        # Σ(v_i − v̄)(v_{i+1} − v̄) from the raw sums
        r1 = (lag - mean * (2 * total - first[d] - last[d]) + (count - 1) * mean * mean) / power
        rho = r1 / (1.0 + r1)
        if rho < 0.25 or d >= dmax:
            break
        d += 1
    # a periodic or deterministic component (r₁ → −1: ρ → −∞) reads as no power law at all;
    # the nearest the deviation's differences can take: 2 (white phase) … 2 − 2·dmax
    k = round(2 * rho)
    if d == 2 and k == 0 and rho < split:
        k = -1  # flicker rate noise (averaged: −0.28), not a random walk (0; averaged 0.2)
    return min(2, max(2 - 2 * dmax, int(-k - 2 * d) + 2))


_BLOCK = 1 << 15
"""Points per block of `_detrended_sums` (256 kB a float array: each block's passes stay in
the cache; on 10⁶ points 2× faster than whole-array passes)."""


def _detrended_sums(z, dmax):
    """For v = z less its least-squares quadratic in the sample index and its differences
    v⁽ᵈ⁾, d ≤ `dmax`: `(max |z|, sums (dmax + 1, 3) = Σv⁽ᵈ⁾, Σ(v⁽ᵈ⁾)², Σ v⁽ᵈ⁾_i v⁽ᵈ⁾_{i+1},
    first and last values of each v⁽ᵈ⁾)`, in blocks of `_BLOCK` points (two passes over z,
    nothing of its size allocated). The quadratic by the orthogonal polynomials 1, t,
    t² − mean(t²) on the symmetric index t ∈ [−1, 1], their norms in closed form (as
    `np.polyfit(t, z, 2)`)."""
    n = z.size
    step = 2.0 / max(n - 1, 1)

    def index(i0, size):  # t at points i0 … i0 + size − 1
        t = np.arange(i0, i0 + size, dtype=float)
        t *= step
        t -= 1.0
        return t

    s0 = s1 = s2 = top = bottom = 0.0
    for i0 in range(0, n, _BLOCK):
        zb = z[i0 : i0 + _BLOCK]
        t = index(i0, zb.size)
        s0 += float(zb.sum())
        s1 += float(np.dot(t, zb))
        t *= t
        s2 += float(np.dot(t, zb))
        top, bottom = max(top, float(zb.max())), min(bottom, float(zb.min()))
    if n < 3:  # a mean only
        b2 = b1 = 0.0
        c0 = s0 / max(n, 1)
    else:
        sum2 = n * (n + 1) / (3.0 * (n - 1))  # Σt², and Σt⁴ below
        sum4 = n * (n + 1) * (3.0 * n * n - 7) / (15.0 * (n - 1) ** 3)
        c2 = sum2 / n  # mean(t²)
        a0 = s0 / n
        b1 = s1 / sum2
        b2 = (s2 - c2 * n * a0) / (sum4 - n * c2 * c2)
        c0 = a0 - b2 * c2
    sums = np.zeros((dmax + 1, 3))
    first, last = [0.0] * (dmax + 1), [None] * (dmax + 1)
    for i0 in range(0, n, _BLOCK):
        zb = z[i0 : i0 + _BLOCK]
        t = index(i0, zb.size)
        fit = b2 * t
        fit += b1
        fit *= t
        fit += c0
        v = zb - fit
        before = list(last)  # each sequence's last value in the blocks before
        for d in range(dmax + 1):
            if d:  # the difference across the blocks' seam included
                v = np.diff(v if before[d - 1] is None else np.concatenate([[before[d - 1]], v]))
            if v.size == 0:
                break
            sums[d] += (v.sum(), np.dot(v, v), np.dot(v[:-1], v[1:])
                        + (0.0 if before[d] is None else before[d] * v[0]))  # fmt: skip
            if before[d] is None:
                first[d] = float(v[0])
            last[d] = float(v[-1])
    return max(abs(top), abs(bottom)), sums, first, last


def b1_expected(n: int, mu: int) -> float:
    """B1(N, μ): the expected ratio of the N-sample standard variance to the Allan variance
    for Allan-variance slope μ (σ² ∝ τ^μ; Barnes 1969, no dead time)."""
    n = whole_number("n", n, "a whole number of averages ≥ 2")  # 2.5 was read as is
    if n < 2:
        raise ValueError(f"n must be at least 2 averages; got {n}")
    mu = finite_number("mu", mu, "the Allan-variance slope")
    if mu == 0:  # flicker rate: the limit μ → 0
        return n * math.log(n) / (2 * (n - 1) * math.log(2))
    return n * (1 - float(n) ** mu) / (2 * (n - 1) * (1 - 2.0**mu))


def rn_expected(m: int, alpha: int) -> float:
    """R(n) = MVAR/AVAR expected at factor m for white (α = 2) or flicker (α = 1) phase noise,
    the measurement bandwidth f_h = 1/(2τ₀) (NIST TN 1337, A-6), and for white rate noise
    (α = 0: ½, its limit for m ≫ 1)."""
    m = whole_number("m", m, "a whole averaging factor ≥ 1")  # 0: ZeroDivisionError
    if m < 1:
        raise ValueError(f"m must be a whole averaging factor ≥ 1; got {m}")
    if alpha == 2:
        return 1.0 / m
    if alpha == 1:
        return 3.37 / (1.04 + 3 * math.log(math.pi * m))
    if alpha == 0:
        return 0.5
    raise ValueError(
        f"R(n) tells white (2) and flicker (1) phase noise from white rate noise (0); got "
        f"alpha = {alpha}"
    )


def _b1_mu(x, m, dmax):
    """The Allan-variance slope μ that B1 on (x.size − 1)//m ≥ 3 averages of the phase `x`
    is nearest (geometric means of neighbouring expectations), from −2 to 1 (2 for dmax 3)."""
    n = (x.size - 1) // m
    ybar = np.diff(x[: n * m + 1 : m])  # τ-averages (×τ: the scale cancels in the ratios)
    avar = 0.5 * np.mean(np.diff(ybar) ** 2)
    if not avar > 0:
        _no_noise()
    b1 = float(np.var(ybar, ddof=1) / avar)
    mus = range(2 if dmax >= 3 else 1, -3, -1)  # μ = 2 (α = −3) only for Hadamard
    expected = {mu: b1_expected(n, mu) for mu in mus}
    for hi in mus:
        if hi > -2 and b1 > math.sqrt(expected[hi] * expected[hi - 1]):
            return hi
    return -2


def _rn(x, m, curvature=0.0):
    """R(n) = MVAR/AVAR at factor m of the phase `x`, less a quadratic of `curvature`."""
    d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
    if curvature:
        d = d - curvature * m * m
    avar = np.mean(d**2)
    if not avar > 0:
        _no_noise()
    c = np.concatenate([[0.0], np.cumsum(d)])
    return float(np.mean((c[m:] - c[:-m]) ** 2) / m**2 / avar)


def _rn_class(rn, m, alpha):
    """White (2) or flicker (1) angle noise by R(n) at factor m, or `alpha` ≤ 0 (rate noise:
    R(n) above the geometric mean of flicker angle noise's and white rate noise's ½)."""
    if rn > math.sqrt(rn_expected(m, 1) * rn_expected(m, 0)):
        return min(alpha, 0)
    return 1 if rn > math.sqrt(rn_expected(m, 1) * rn_expected(m, 2)) else 2


def gapped_alpha(alpha: int, m: int, rn: float) -> int:
    """The noise type at factor `m` of a record with gaps: `alpha`, read on the record with
    its gaps bridged ([`hrgjax.allan.gaps.bridged`][hrgjax.allan.gaps.bridged]), or white
    angle noise (2) where `rn`, R(n) = MVAR/AVAR of the gap-free windows alone
    ([`hrgjax.allan.gaps.gapped_rn`][hrgjax.allan.gaps.gapped_rn]), falls to white angle
    noise's 1/m band, from [`RN_FACTOR`][hrgjax.allan.RN_FACTOR] on. A bridge cannot know
    the angle a gap's missing rates turned through: each bridged gap steps the angle by
    about the noise's own (white angle noise: ≈ √2 σₓ), a random walk in the bridged angle
    that reads as flicker angle or white rate noise from m ≈ the gaps' spacing on (white
    angle noise, 2 % of 4 096 rates missing: flicker angle at m = 16 in 170 of 200 records,
    flicker angle or white rate at 32–64 in every one). R(n) of the gap-free windows has no
    such step. The steps only redden the record, so R(n) moves the read one way, to white
    angle noise: moved to flicker angle or rate noise as well, flicker angle noise read white
    rate noise in 6 more of 200 records at m = 64 (R(n)'s scatter on few windows, ≥ 2m). NaN `rn`
    (too few gap-free windows) or m < `RN_FACTOR`: `alpha` as read."""
    if m >= RN_FACTOR and np.isfinite(rn) and _rn_class(float(rn), int(m), int(alpha)) == 2:
        return 2
    return int(alpha)


def _curvature(x):
    """The second difference per sample² of the phase's least-squares quadratic."""
    n = x.size
    if n < 3:
        return 0.0
    t = np.arange(n, dtype=float) - (n - 1) / 2.0
    t2 = t * t - np.mean(t * t)
    return 2.0 * float(np.dot(t2, x) / np.dot(t2, t2))


def _b1_alpha(x, m, dmax, white_rate_guard: bool = True):
    """B1 (and R(n)) at factor m of the phase x (the Stable32 rule); the guard: R(n) nearer
    white rate noise's than flicker phase noise's takes white rate noise."""
    mu = _b1_mu(x, m, dmax)
    if mu > -2:
        return -mu - 1
    if x.size < 3 * m or m < RN_FACTOR:  # R(n) needs a modified variance at m; below m = 4
        return 2  # its expectations for white and flicker coincide (both 1 at m = 1): white
    rn = _rn(x, m)
    if white_rate_guard and rn > math.sqrt(rn_expected(m, 1) * rn_expected(m, 0)):
        return 0  # rate noise after all: few averages put its B1 of 1 below the boundary
    return 1 if rn > math.sqrt(rn_expected(m, 1) * rn_expected(m, 2)) else 2


def check_rate_has_noise(rate):
    """Raise `_no_noise`'s error when the rate samples `rate` (NaN: missing) are a straight
    line in time to round-off (RMS about their least-squares line ≤ 64 ε of their largest
    size): a stuck or constant sensor. Read on the rate itself, because summing it into a
    phase leaves round-off (3e-15 of the phase's size at 10³ constant samples, 6e-14 at
    2·10⁴, 3e-12 at 10⁶) above the phase test's floor."""
    rate = np.asarray(rate, dtype=float)
    present = np.isfinite(rate)
    if present.sum() < 3:
        return
    t, v = np.flatnonzero(present).astype(float), rate[present]
    size = np.max(np.abs(v))
    t, v = t - t.mean(), v - v.mean()
    v = v - t * (np.dot(t, v) / np.dot(t, t))
    if not np.sqrt(np.mean(v**2)) > 64 * np.finfo(float).eps * size:
        _no_noise()


def _no_noise():
    raise ValueError(
        "y has no noise to identify: its angle is a polynomial of degree ≤ 2 (a constant or "
        "ramping rate) to round-off, and every deviation of it is a deterministic value"
    )
