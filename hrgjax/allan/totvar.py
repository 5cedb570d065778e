r"""The total variance's bias and equivalent degrees of freedom by noise type (NumPy, float64).

Totvar (NIST SP 1065 eq. 25) averages the N − 2 second differences
$x^*_{i-m} - 2x^*_i + x^*_{i+m}$ of the phase reflected at both ends
($x^*_{-j} = 2x_0 - x_j$, $x^*_{N-1+j} = 2x_{N-1} - x_{N-1-j}$). Where a difference reaches
past an end, it reads the end point twice over ($2x_0$): for the frequency noises that
cancels part of the long-τ variance (SP 1065 §5.2.11: E[Totvar] = (1 − a·τ/T)·σ², a =
0.481 for flicker and 0.750 for random-walk rate noise, none for white rate noise), but for
phase (angle) noise the end point's own noise enters with weight 2: white angle noise reads
E[Totvar]/σ² = 1 + (4/3)·τ/T up to τ = T/2 and 8/3 at τ = T, flicker angle noise about
three-quarters of that excess. SP 1065 gives no bias for phase noises (Howe recommends
MDEV or MTOT for them); here both are computed, not tabulated:

- white angle noise (α = 2): the phase points are independent, so Totvar is a quadratic
  form xᵀAx of independent variables and E[Totvar]/σ² = tr A/(6(N − 2)) and its EDF
  (tr A)²/tr A² are exact ([`totvar_white_phase`][hrgjax.allan.totvar_white_phase]; the
  rows' supports are a few diagonals of A, summed in closed form: no N × N matrix);
- flicker angle noise (α = 1): the same rows over the flicker phase's structure function
  D(k) = E[(x_{j+k} − x_j)²] ∝ ln(πk) + γ (the bandwidth f_h = 1/(2τ₀) of
  [`rn_expected`][hrgjax.allan.rn_expected]; its Allan variance 1.038 + 3 ln(2π f_h τ)).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .uncertainty import edf_greenhall

TOTVAR_BIAS = {-1: 0.481, -2: 0.750}
"""NIST SP 1065 §5.2.11: the total variance's bias a by noise type α (flicker and random-walk
rate noise; none for white rate noise): E[Totvar] = (1 − a·τ/T)·σ²(τ), T the record's
length. Phase (angle) noises: [`totvar_bias`][hrgjax.allan.totvar_bias]."""


def totvar_bias(alpha: int, m: int, n: int) -> float:
    """E[Totvar]/σ²(τ) at factor `m` over `n` phase points (T = (n − 1)τ₀) for power-law
    noise α (rate PSD ∝ f^α): 1 − a·τ/T for α = −1, −2 ([`TOTVAR_BIAS`][hrgjax.allan.TOTVAR_BIAS]),
    1 for white rate noise, the exact value for white angle noise (α = 2,
    [`totvar_white_phase`][hrgjax.allan.totvar_white_phase]) and that of flicker angle noise's
    structure function (α = 1, module docstring). Other α (below −2) are given 1.

    **Raises:** `ValueError` for m outside 1 … n − 1."""
    alpha, m, n = int(alpha), int(m), int(n)
    _check_factor(m, n)
    if alpha == 2:
        return totvar_white_phase(m, n)[0]
    if alpha == 1:
        return _flicker_phase_bias(m, n)
    return 1.0 - TOTVAR_BIAS.get(alpha, 0.0) * m / (n - 1)


def _check_factor(m: int, n: int) -> None:
    if not 1 <= m <= n - 1:
        raise ValueError(f"m = {m} is outside totdev's factors 1 … n − 1 = {n - 1}")


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


@functools.lru_cache(maxsize=4096)
def totvar_white_phase(m: int, n: int) -> tuple[float, float]:
    """`(bias, edf)` of Totvar at factor `m` over `n` phase points for white angle (phase)
    noise, exact: E[Totvar] = bias·σ²(τ), σ²(τ) = 3σₓ²/τ² its Allan variance, and the EDF
    (tr A)²/tr A² of Totvar = xᵀAx/(2τ²(n − 2)) over the independent phase points x. bias
    is 1 + (4/3)·τ/T to O(1/n) up to τ = T/2 and 8/3 at τ = T; the EDF ≈ n/1.94 at small m
    (as an overlapping Allan variance), 4.0 at τ = T. Equal to the dense matrices'
    tr A, tr A² to round-off for every m of n = 3 … 40 (tests/test_allan_stats.py).

    **Raises:** `ValueError` for m outside 1 … n − 1."""
    m, n = int(m), int(n)
    _check_factor(m, n)
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
    structure function D(k) = ln(πk) + γ (k ≥ 1), against the Allan variance's 4D(m) − D(2m)."""
    total = 0.0
    step = 1 << 16
    for start in range(1, n - 1, step):
        i = np.arange(start, min(start + step, n - 1))
        index, coef = [], []
        for k, c in ((i - m, 1.0), (i, -2.0), (i + m, 1.0)):  # reflected: 2x_end − x_mirror
            low, high = k < 0, k > n - 1
            inside = ~(low | high)
            index += [
                np.where(inside, k, np.where(low, -k, 2 * n - 2 - k)),
                np.where(high, n - 1, 0),
            ]
            coef += [np.where(inside, c, -c), np.where(low | high, 2 * c, 0.0)]
        for u in range(len(index)):
            for v in range(u + 1, len(index)):
                total -= float(np.sum(coef[u] * coef[v] * _structure(np.abs(index[u] - index[v]))))
    return float(total / (n - 2) / (4 * _structure(m) - _structure(2 * m)))


def _structure(k):
    """Flicker phase noise's structure function ln(πk) + γ (k ≥ 1; 0 at k = 0), f_h = 1/(2τ₀)."""
    k = np.asarray(k, dtype=float)
    return np.where(k > 0, np.log(np.pi * np.maximum(k, 1.0)) + 0.5772156649015329, 0.0)


def edf_totdev(alpha: int, m: int, n: int) -> float:
    """EDF of the total deviation at factor `m` over `n` phase points for noise type `alpha`
    (rate PSD ∝ f^α), for every factor totdev reads (1 ≤ m ≤ n − 1):

    - α = 0, −1, −2: b·N/m − c, N = `n` (NIST SP 1065 Table 7);
    - α = 2 (white angle noise): exact, that of Totvar's quadratic form
      ([`totvar_white_phase`][hrgjax.allan.totvar_white_phase]): ≈ n/1.94 at small m (Table
      7's white-rate line 1.5·N/m, used before, was 23× too small at m = 128 of N = 8193),
      4.0 at τ = T;
    - α = 1 (flicker angle noise): Stein's (N − 1)-point approximation for the Allan variance
      (as allantools), exp(√(ln((N − 1)/(2m))·ln((2m + 1)(N − 1)/4))), up to m = N/4; beyond,
      where it falls to 1 at m = (N − 1)/2 and is undefined past it, never below Table 7's
      white-rate line 1.5·N/m;
    - α ≤ 1: at most the Greenhall EDF of an overlapping Allan deviation averaging as many
      terms (N − 2, on N + 2m − 2 points): Table 7's line exceeds the number of terms at
      m = 1–2 (3002 at m = 1 over 2001 points, 1999 terms; Monte Carlo 1200–1600, Greenhall
      1565), and Stein's flicker value exceeds the Monte Carlo EDF from m ≈ N/60 on;
    - never below 1.

    Against the exact EDF of totdev's quadratic form (N = 201) white rate noise's is high by at
    most 17 % at m = 1 (Greenhall's own excess there) and 26 % at m ≈ 3N/4 (Table 7). On
    200 simulated records of N = 2001: rate random walk below the Monte Carlo EDF; flicker
    angle noise up to 1.4× it at m = 128 (Stein's value alone: 1.8×).

    **Raises:** `ValueError` for m outside 1 … n − 1."""
    alpha, m, n = int(alpha), int(m), int(n)
    _check_factor(m, n)
    if alpha == 2:
        return max(totvar_white_phase(m, n)[1], 1.0)
    table7 = {0: (1.50, 0.0), -1: (1.17, 0.22), -2: (0.93, 0.36)}
    line = 1.5 * n / m
    if alpha in table7:
        b, c = table7[alpha]
        edf = b * n / m - c
    elif alpha == 1:
        edf = _stein_flicker(m, n) if 2 * m < n - 1 else 0.0
        if 4 * m > n:
            edf = max(edf, line)
    else:
        edf = float(n - 1)
    cap = edf_greenhall(min(max(alpha, -2), 2), 2, m, n + 2 * m - 2, overlapping=True,
                        modified=False)  # fmt: skip
    return max(min(edf, cap), 1.0)


def _stein_flicker(m: int, n: int) -> float:
    """The (N − 1)-point EDF approximation of the Allan variance for flicker angle noise
    (Stein 1985; allantools' `edf_simple`), m < (N − 1)/2."""
    return math.exp(math.sqrt(math.log((n - 1) / (2 * m)) * math.log((2 * m + 1) * (n - 1) / 4)))
