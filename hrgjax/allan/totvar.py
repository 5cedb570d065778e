r"""The total variance's bias and equivalent degrees of freedom by noise type (NumPy, float64).

Totvar (NIST SP 1065 eq. 25) averages the N − 2 second differences
$x^*_{i-m} - 2x^*_i + x^*_{i+m}$ of the phase reflected at both ends
($x^*_{-j} = 2x_0 - x_j$, $x^*_{N-1+j} = 2x_{N-1} - x_{N-1-j}$). Where a difference reaches
past an end, it reads the end point twice over ($2x_0$): for the frequency noises that
cancels part of the long-τ variance (SP 1065 §5.2.11: E[Totvar] = (1 − a·τ/T)·σ², a =
0.481 for flicker and 0.750 for random-walk rate noise, none for white rate noise), but for
phase (angle) noise the end point's own noise enters with weight 2: white angle noise reads
E[Totvar]/σ² = 1 + (4/3)·τ/T to O(1/N) at every factor m up to N − 2 (τ = T − τ₀: 2.33),
and 8/3 only at the last, τ = T (for long records: 4 at n = 3); flicker angle noise about three-quarters of that excess.
SP 1065 gives no bias for phase noises (Howe recommends MDEV or MTOT for them); here both
are computed, not tabulated:

- white angle noise (α = 2): the phase points are independent, so Totvar is a quadratic
  form xᵀAx of independent variables and E[Totvar]/σ² = tr A/(6(N − 2)) and its EDF
  (tr A)²/tr A² are exact ([`totvar_white_phase`][hrgjax.allan.totvar_white_phase]; the
  rows' supports are a few diagonals of A, summed in closed form: no N × N matrix);
- flicker angle noise (α = 1): the same rows over the flicker phase's structure function
  D(k) = E[(x_{j+k} − x_j)²] ∝ ln(πk) + γ, which assumes the bandwidth f_h = 1/(2τ₀) of
  [`rn_expected`][hrgjax.allan.rn_expected] (its Allan variance 1.038 + 3 ln(2π f_h τ)).
  A sensor filtered below Nyquist has a smaller bias: with f_h = 1/(8τ₀) or 1/(32τ₀) the
  true value at τ = T (N = 513) is 2.14 or 1.99 where this gives 2.23 (4.5 % and 12 % in
  variance; 1.44, 1.36 against 1.48 at T/2: `benchmarks/coverage_totdev.py --exact`).
  Each range of rows over which a row is one pattern of indices linear in i sums
  Σ ln|s·i + b| as a difference of lgamma values: O(1) per factor.

Here N = `n` counts phase points (N − 1 rate samples; T = (N − 1)τ₀).
"""

from __future__ import annotations

import functools
import math

from .._checks import check_flag
from .._checks import whole_number as _whole
from .uncertainty import edf_greenhall

TOTVAR_BIAS = {-1: 0.481, -2: 0.750}
"""NIST SP 1065 §5.2.11: the total variance's bias a by noise type α (flicker and random-walk
rate noise; none for white rate noise): E[Totvar] = (1 − a·τ/T)·σ²(τ), T the record's
length. Phase (angle) noises: [`totvar_bias`][hrgjax.allan.totvar_bias]."""

_EULER_GAMMA = 0.5772156649015329


def totvar_bias(alpha: int, m: int, n: int, *, angle_noise: bool = True) -> float:
    """E[Totvar]/σ²(τ) at factor `m` over `n` phase points (T = (n − 1)τ₀) for power-law
    noise α (rate PSD ∝ f^α, a whole number from −2 to 2): 1 − a·τ/T for α = −1, −2
    ([`TOTVAR_BIAS`][hrgjax.allan.TOTVAR_BIAS]), 1 for white rate noise, the exact value for
    white angle noise (α = 2, [`totvar_white_phase`][hrgjax.allan.totvar_white_phase]) and
    that of flicker angle noise's structure function (α = 1, f_h = 1/(2τ₀): module
    docstring). `angle_noise=False`: SP 1065's correction alone (Stable32's, which corrects
    the frequency noises only), 1 for α = 1, 2.

    **Raises:** `ValueError` naming the argument for n < 3, m not a whole number in
    1 … n − 1, or α not a whole number in −2 … 2; `TypeError` for an `angle_noise` that
    is not a bool."""
    alpha, m, n = _check_args(alpha, m, n)
    angle_noise = check_flag("angle_noise", angle_noise)
    if alpha == 2 and angle_noise:
        return _white_phase(m, n)[0]
    if alpha == 1 and angle_noise:
        return _flicker_phase_bias(m, n)
    return 1.0 - TOTVAR_BIAS.get(alpha, 0.0) * m / (n - 1)


def _check_args(alpha, m, n) -> tuple[int, int, int]:
    n = _whole("n", n, "a whole number of phase points ≥ 3")
    if n < 3:
        raise ValueError(f"n must be a whole number of phase points ≥ 3; got {n}")
    m = _check_factor(m, n)
    alpha = _whole("alpha", alpha, "a whole noise exponent from −2 to 2 (rate PSD ∝ f^α)")
    if not -2 <= alpha <= 2:
        raise ValueError(f"alpha must be a whole noise exponent from −2 to 2 (rate PSD ∝ f^α); "
                         f"got {alpha}")  # fmt: skip
    return alpha, m, n


def _check_factor(m, n: int) -> int:
    what = f"a whole averaging factor from 1 to n − 1 = {n - 1}"
    m = _whole("m", m, what)
    if not 1 <= m <= n - 1:
        raise ValueError(f"m must be {what}; got {m}")
    return m


def _rows(m: int, n: int):
    """Totvar's rows by ranges of i over which each is one pattern: (first i, last i, weight
    on x₀, weight on x_{n−1}, [(σ, β, c)]: coefficient c on x at index σ·i + β, inside)."""
    lefts = [(1, m - 1, 2, [(-1, m, -1.0)]), (m, m, 1, []), (m + 1, n - 2, 0, [(1, -m, 1.0)])]
    rights = [(1, n - 2 - m, 0, [(1, m, 1.0)]), (n - 1 - m, n - 1 - m, 1, []),
              (n - m, n - 2, 2, [(-1, 2 * (n - 1) - m, -1.0)])]  # fmt: skip
    out = []
    for llo, lhi, p, left in lefts:
        for rlo, rhi, q, right in rights:
            lo, hi = max(1, llo, rlo), min(n - 2, lhi, rhi)
            if lo <= hi:
                out.append((lo, hi, p, q, [*left, (1, 0, -2.0), *right]))
    return out


def _square_sum(segments) -> float:
    """Σₐ v(a)² of v = Σ w·[lo ≤ a ≤ hi] over `segments` (lo, hi, w)."""
    events: dict[int, float] = {}
    for lo, hi, w in segments:
        events[lo] = events.get(lo, 0.0) + w
        events[hi + 1] = events.get(hi + 1, 0.0) - w
    total = value = 0.0
    points = sorted(events)
    for a, b in zip(points, points[1:], strict=False):
        value += events[a]
        total += value * value * (b - a)
    return total


def _value(segments, a: int) -> float:
    return sum(w for lo, hi, w in segments if lo <= a <= hi)


def totvar_white_phase(m: int, n: int) -> tuple[float, float]:
    """`(bias, edf)` of Totvar at factor `m` over `n` phase points for white angle (phase)
    noise, exact: E[Totvar] = bias·σ²(τ), σ²(τ) = 3σₓ²/τ² its Allan variance, and the EDF
    (tr A)²/tr A² of Totvar = xᵀAx/(2τ²(n − 2)) over the independent phase points x. bias
    is 1 + (4/3)·τ/T to O(1/n) for every m up to n − 2 and ≈ 8/3 only at τ = T (m = n − 1; 4 at n = 3);
    the EDF ≈ n/1.94 at small m (as an overlapping Allan variance), 4.0 at τ = T. Equal to
    the dense matrices' tr A, tr A² to round-off for every m of n = 3 … 40
    (tests/test_allan_stats.py).

    **Raises:** `ValueError` naming the argument for n < 3 or m not a whole number in
    1 … n − 1."""
    n = _whole("n", n, "a whole number of phase points ≥ 3")
    if n < 3:
        raise ValueError(f"n must be a whole number of phase points ≥ 3; got {n}")
    return _white_phase(_check_factor(m, n), n)


@functools.lru_cache(maxsize=4096)
def _white_phase(m: int, n: int) -> tuple[float, float]:
    # rows c_i = s_i + p_i·e₀ + q_i·e_{n−1}, s_i inside: G_ij = s_i·s_j + p_i p_j + q_i q_j, and
    # tr A² = Σ G_ij² = ‖Σ s_i s_iᵀ‖²_F + 2(‖Σ p_i s_i‖² + ‖Σ q_i s_i‖²) + (p·p)² + 2(p·q)² + (q·q)²
    lines: dict[tuple[str, int], list] = {}  # Σ s_i s_iᵀ by diagonal (a, a + d) or anti (a, s − a)
    sp, sq = [], []
    pp = pq = qq = 0.0
    for lo, hi, p, q, slots in _rows(m, n):
        count = hi - lo + 1
        pp, pq, qq = pp + p * p * count, pq + p * q * count, qq + q * q * count
        for su, bu, cu in slots:
            a0, a1 = sorted((su * lo + bu, su * hi + bu))
            sp += [(a0, a1, p * cu)] if p else []
            sq += [(a0, a1, q * cu)] if q else []
            for sv, bv, cv in slots:
                key = ("d", bv - bu) if su == sv else ("s", bu + bv)
                lines.setdefault(key, []).append((a0, a1, cu * cv))
    square = sum(_square_sum(s) for s in lines.values())
    trace = sum(w * (hi - lo + 1) for lo, hi, w in lines.get(("d", 0), []))
    for (kind, s), anti in lines.items():
        if kind != "s":
            continue
        trace += _value(anti, s // 2) if s % 2 == 0 else 0.0
        for (other, d), diagonal in lines.items():  # a cell on both lines: (k, k + d) = (k, s − k)
            if other == "d" and (s - d) % 2 == 0:
                square += 2 * _value(diagonal, (s - d) // 2) * _value(anti, (s - d) // 2)
    trace += pp + qq
    square += 2 * (_square_sum(sp) + _square_sum(sq)) + pp * pp + 2 * pq * pq + qq * qq
    return trace / (6.0 * (n - 2)), trace * trace / square


@functools.lru_cache(maxsize=4096)
def _flicker_phase_bias(m: int, n: int) -> float:
    """E[Totvar]/σ²(τ) for flicker angle noise: each row's −½ Σ c_a c_b D(|a − b|) over the
    structure function D(k) = ln(πk) + γ (k ≥ 1, 0 at k = 0), against the Allan variance's
    4D(m) − D(2m). Over a range of rows of one pattern, a pair of coefficients sits at
    index distance |s·i + b| (s = 0, ±1, ±2): its D summed over the range in O(1)
    (`_log_sum`), so the whole sum costs O(1) per factor (interior rows, m ≤ i ≤ n − 1 − m:
    4D(m) − D(2m) each)."""
    shift = math.log(math.pi) + _EULER_GAMMA
    total = 0.0
    for lo, hi, p, q, slots in _rows(m, n):
        terms = [*slots, *([(0, 0, float(p))] if p else []),
                 *([(0, n - 1, float(q))] if q else [])]  # fmt: skip
        for u, (su, bu, cu) in enumerate(terms):
            for sv, bv, cv in terms[u + 1 :]:
                count, logs = _log_sum(su - sv, bu - bv, lo, hi)
                total -= cu * cv * (count * shift + logs)
    d_m, d_2m = math.log(math.pi * m) + _EULER_GAMMA, math.log(2 * math.pi * m) + _EULER_GAMMA
    return total / (n - 2) / (4 * d_m - d_2m)


def _log_sum(s: int, b: int, lo: int, hi: int) -> tuple[int, float]:
    """(count, Σ ln|s·i + b|) over the integers i = lo … hi where s·i + b ≠ 0 (s = 0, ±1, ±2):
    Σ ln(s(i + b/s)) over a run is run·ln s + lgamma(last + 1 + b/s) − lgamma(first + b/s)."""
    if s < 0:
        s, b = -s, -b
    if s == 0:
        return (0, 0.0) if b == 0 else (hi - lo + 1, (hi - lo + 1) * math.log(abs(b)))
    count, total = 0, 0.0
    first = max(lo, -((b - 1) // s))  # s·i + b ≥ 1 from i = ⌈(1 − b)/s⌉
    if first <= hi:
        count += hi - first + 1
        total += (hi - first + 1) * math.log(s) + math.lgamma(hi + 1 + b / s)
        total -= math.lgamma(first + b / s)
    last = min(hi, (-1 - b) // s)  # s·i + b ≤ −1 up to i = ⌊(−1 − b)/s⌋: |s·i + b| = s·j − b
    if lo <= last:  # over j = −i from −last to −lo
        count += last - lo + 1
        total += (last - lo + 1) * math.log(s) + math.lgamma(-lo + 1 - b / s)
        total -= math.lgamma(-last - b / s)
    return count, total


def edf_totdev(alpha: int, m: int, n: int, discrete: bool = True) -> float:
    """EDF of the total deviation at factor `m` over `n` phase points for noise type `alpha`
    (rate PSD ∝ f^α, a whole number from −2 to 2), for every factor totdev reads
    (1 ≤ m ≤ n − 1):

    - α = 0, −1, −2: b·N/m − c, N = `n` (NIST SP 1065 Table 7);
    - α = 2 (white angle noise): exact, that of Totvar's quadratic form
      ([`totvar_white_phase`][hrgjax.allan.totvar_white_phase]): ≈ n/1.94 at small m (Table
      7's white-rate line 1.5·N/m, used before, was 23× too small at m = 128 of N = 8193),
      4.0 at τ = T; not capped (it may exceed the Greenhall EDF below by round-off: 1053.28
      against 1053.27 at m = 2 of N = 2049);
    - α = 1 (flicker angle noise): Stein's (N − 1)-point approximation for the Allan variance
      (as allantools), exp(√(ln((N − 1)/(2m))·ln((2m + 1)(N − 1)/4))), up to m = N/4; beyond,
      where it falls to 1 at m = (N − 1)/2 and is undefined past it, never below Table 7's
      white-rate line 1.5·N/m;
    - α ≤ 1: at most the EDF of an overlapping Allan deviation averaging as many terms
      (N − 2, on N + 2m − 2 points): `discrete=True` (the default, and `deviation`'s under its
      default rule) its exact EDF for noise as a gyro samples it up to m = 64
      ([`edf_greenhall`][hrgjax.allan.edf_greenhall]`(..., discrete=True)`), `False`
      Greenhall's (`noise_rule="stable32"`). Table 7's line exceeds the number of terms at
      m = 1–2 (3002 at m = 1 over 2001 points, 1999 terms; Monte Carlo 1200–1600, exact
      oadev EDF 1333, Greenhall's 1565), and Stein's flicker value exceeds the Monte Carlo
      EDF from m ≈ N/60 on;
    - never below 1.

    Against the exact EDF of totdev's quadratic form (N = 201) white rate noise's is high by
    at most 26 % at m ≈ 3N/4 (Table 7); at m = 1 it is within 1 % (Greenhall's cap,
    `discrete=False`, 17 % high). On 200 simulated records of N = 2001: rate random walk
    below the Monte Carlo EDF; flicker angle noise up to 1.4× it at m = 128 (Stein's value
    alone: 1.8×).

    **Raises:** `ValueError` naming the argument for n < 3, m not a whole number in
    1 … n − 1, or α not a whole number in −2 … 2; `TypeError` for `discrete` not a bool."""
    alpha, m, n = _check_args(alpha, m, n)
    discrete = check_flag("discrete", discrete)
    if alpha == 2:
        return max(_white_phase(m, n)[1], 1.0)
    table7 = {0: (1.50, 0.0), -1: (1.17, 0.22), -2: (0.93, 0.36)}
    line = 1.5 * n / m
    if alpha in table7:
        b, c = table7[alpha]
        edf = b * n / m - c
    else:  # α = 1
        edf = _stein_flicker(m, n) if 2 * m < n - 1 else 0.0
        if 4 * m > n:
            edf = max(edf, line)
    cap = edf_greenhall(alpha, 2, m, n + 2 * m - 2, True, False, discrete=discrete)
    return max(min(edf, cap), 1.0)


def _stein_flicker(m: int, n: int) -> float:
    """The (N − 1)-point EDF approximation of the Allan variance for flicker angle noise
    (Stein 1985; allantools' `edf_simple`), m < (N − 1)/2."""
    return math.exp(math.sqrt(math.log((n - 1) / (2 * m)) * math.log((2 * m + 1) * (n - 1) / 4)))
