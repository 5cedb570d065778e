r"""The statistics of a deviation under the record's own fitted noise *mixture*: mtotdev's
bias divisor and oadev's EDF from the IEEE 952 terms (quantisation, angle random walk, bias
instability, rate random walk) fitted to the record's octave Allan variance, in place of
those of the one power-law type read at each τ.

A real gyro's rate is a sum of noises, and at the τ where two of them cross, the type read
there (lag-1 ACF, B1, R(n)) is one of them or a type between, flipping from record to record.
The estimator's bias and EDF of that one type are then wrong — the mixture's lie between
the components'. For independent components the mixture's values are exact:

- mtotdev/ttotdev: E[Mod Totvar] = Σᵢ b(αᵢ, m)·Mod σ²ᵢ(m), so
  b_mix(m) = Σᵢ b(αᵢ, m)·Mod σ²ᵢ(m) / Σᵢ Mod σ²ᵢ(m)
  ([`mixture_bias`][hrgjax.allan.mixture.mixture_bias]; b of each component
  [`mtotvar_bias`][hrgjax.allan.total.mtotvar_bias], Mod σ²ᵢ = the term's Allan variance ×
  [`modvar_ratio`][hrgjax.allan.mixture.modvar_ratio]);
  and the raw estimator's EDF from Var Mod Totvar = Σᵢⱼ 2 tr(AΣᵢAΣⱼ): each term's own
  variance (its one-type EDF) and the cross terms' correlations ρᵢⱼ of the estimator's
  quadratic form ([`mixture_mtotdev_edf`][hrgjax.allan.mixture.mixture_mtotdev_edf]; not yet
  used by [`deviation`][hrgjax.allan.deviation]: the bias-corrected estimate's variance
  also holds the fitted divisor's, anti-correlated with the raw estimate's, and is up to
  1.2× the raw one's at a crossover, docs/allan.md *Mixtures*);
- oadev: EDF(τ) = 2σ²(τ)²/Var σ̂²(τ), with Var σ̂² the exact Gaussian variance of the
  overlapping estimate under the model
  ([`covariance`][hrgjax.allan.octave_covariance.covariance], the bias instability as a
  sum of Gauss–Markov terms): [`mixture_oadev_edf`][hrgjax.allan.mixture.mixture_oadev_edf].

[`fit_mixture`][hrgjax.allan.mixture.fit_mixture] fits the terms
([`fit_noise`][hrgjax.allan.fit_noise], generalised least squares under the octave
estimates' exact covariance) to the record's overlapping Allan variance at octaves,
computed here in NumPy (no call back into [`deviation`][hrgjax.allan.deviation]), and
refuses a fit it cannot trust: fewer than [`MIN_OCTAVES`][hrgjax.allan.mixture.MIN_OCTAVES]
octaves, no exact covariance, or a misfit χ² whose p-value is below
[`FIT_P_MIN`][hrgjax.allan.mixture.FIT_P_MIN] (a noise outside the IEEE 952 basis — a
Gauss–Markov bump, a sinusoid, a drift —  that the four terms do not describe).
[`deviation`][hrgjax.allan.deviation] then keeps the one-type values.
"""

from __future__ import annotations

import math

import numpy as np

from .octave_covariance import covariance
from .uncertainty import chi2_sf, edf_greenhall

MIXTURE_TERMS = ("quantization", "angle_random_walk", "bias_instability", "rate_random_walk")
"""The IEEE 952 terms of the fitted mixture (the rate ramp left out: mtotdev's bias for a
drift is not a power-law one, and a drift shows as a rejected or random-walk fit)."""

TERM_ALPHA = {"quantization": 2, "angle_random_walk": 0, "bias_instability": -1,
              "rate_random_walk": -2}  # fmt: skip
"""Each term's power-law exponent α (rate PSD ∝ f^α)."""

MIN_OCTAVES = 5
"""The fewest octave τ (n_terms > 1) the fit needs (a record of ≥ 64 samples): four terms
and at least one degree of freedom for the misfit test."""

FIT_P_MIN = 1e-3
"""A fit whose misfit χ² (whitened by the estimates' exact covariance) has a p-value below
this is refused: the record holds a noise the four terms do not describe."""

MAX_EDF_TAUS = 64
"""oadev's mixture EDF is computed for grids of up to this many τ (each τ's variance from
its own one-τ layout, ≈ 1–3 ms); beyond (`taus="all"`), the one-type EDF is kept."""

RATIO_EXACT_TO = 1024
"""[`modvar_ratio`][hrgjax.allan.mixture.modvar_ratio] is summed exactly up to this m; beyond
it the value at this m (within 3e-7 of the limit: ½, 0.674624, 0.825)."""


def _g(term: str, t) -> np.ndarray:
    """Generalised covariance of the phase X = Σy (samples) of a unit term (interval means)."""
    t = np.abs(np.asarray(t, dtype=float))
    if term == "angle_random_walk":
        return -0.5 * t
    if term == "rate_random_walk":
        return t**3 / 12.0
    # flicker rate noise: t² ln|t| (its Allan variance is flat at every integer m)
    return t * t * np.log(np.where(t > 0, t, 1.0))


def _ratio_one(term: str, m: int) -> float:
    j = np.arange(-(m - 1), m, dtype=float)
    w = m - np.abs(j)

    def h(t):  # Σ_j (m − |j|) G(t + j): the m-point average's sum
        return float(np.dot(w, _g(term, t + j)))

    num = 6.0 * h(0.0) - 8.0 * h(float(m)) + 2.0 * h(2.0 * m)
    den = (2.0 * _g(term, 2.0 * m) - 8.0 * _g(term, float(m))) * m * m
    return float(num / den)


def modvar_ratio(term: str, m) -> np.ndarray:
    """Mod σ²(m)/σ²(m), the modified over the Allan variance at factors `m` (≥ 1) of one IEEE
    952 term of [`MIXTURE_TERMS`][hrgjax.allan.mixture.MIXTURE_TERMS] for rate samples that
    are interval means (exact for sampled data): quantisation 1/m, angle random walk
    (m² + 1)/(2m²), bias instability (a continuous 1/f rate, whose phase has the generalised
    covariance t²·ln|t|) 1 at m = 1, 0.738 at 2, → 0.6746; rate random walk 1, 0.859, → 0.825
    (the second differences of m-point phase averages, summed against the term's generalised
    covariance). [dimensionless]"""
    m = np.asarray(m, dtype=int)
    if term == "quantization":
        return 1.0 / m.astype(float)
    if term not in MIXTURE_TERMS:
        raise ValueError(f"term must be one of {list(MIXTURE_TERMS)}; got {term!r}")
    capped = np.minimum(m, RATIO_EXACT_TO)
    values = {int(k): _ratio_one(term, int(k)) for k in np.unique(capped)}
    return np.asarray([values[int(k)] for k in capped.ravel()]).reshape(m.shape)


def _unit_avar(term: str, taus) -> np.ndarray:
    from .noise_terms import NOISE_TERMS

    return {n: f for n, _, _, f in NOISE_TERMS}[term](np.asarray(taus, dtype=float))


def _raw_shares(value: dict, m: np.ndarray, tau0: float) -> dict:
    """{term: (E[Mod Totvar]ᵢ = b(αᵢ, m)·Mod σ²ᵢ(m), Mod σ²ᵢ(m))} of the terms of `value`
    with a coefficient > 0, at factors `m` (arrays of m's shape)."""
    from .total import mtotvar_bias

    out = {}
    for term in MIXTURE_TERMS:
        c = float(value.get(term, 0.0))
        if c <= 0:
            continue
        modvar = c * c * _unit_avar(term, m * tau0) * modvar_ratio(term, m)
        b = np.asarray([mtotvar_bias(TERM_ALPHA[term], int(k)) for k in m.ravel()])
        out[term] = (b.reshape(m.shape) * modvar, modvar)
    return out


def mixture_bias(value: dict, m, tau0: float) -> np.ndarray:
    """b_mix(m) = Σᵢ b(αᵢ, m)·Mod σ²ᵢ(m)/Σᵢ Mod σ²ᵢ(m): E[Mod Totvar]/Mod σ² of mtotdev's raw
    estimator at factors `m` for independent IEEE 952 terms of coefficients `value`
    ({name: coefficient}, as [`NoiseFit.value`][hrgjax.allan.NoiseFit]: Q [unit·s],
    N [unit·√s], B [unit], K [unit/√s]; other names ignored) sampled every `tau0` [s]; b of
    each term [`mtotvar_bias`][hrgjax.allan.total.mtotvar_bias] at its α
    ([`TERM_ALPHA`][hrgjax.allan.mixture.TERM_ALPHA]). NaN where every term is 0.
    [dimensionless]"""
    m = np.asarray(m, dtype=int)
    num, den = np.zeros(m.shape), np.zeros(m.shape)
    for raw, modvar in _raw_shares(value, m, tau0).values():
        num += raw
        den += modvar
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)


MTOTDEV_RHO_R = (3.0, 3.5, 4.0, 4.5, 5.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0, 64.0)
"""The r = n/m (phase points per τ) of [`MTOTDEV_RHO`][hrgjax.allan.mixture.MTOTDEV_RHO]'s rows."""

# fmt: off
MTOTDEV_RHO_M = {
    1: (0.9760, 0.9184, 0.7176, 0.9802, 0.8169, 0.9006),
    2: (0.8837, 0.6936, 0.3600, 0.9341, 0.6132, 0.8114),
    3: (0.8594, 0.6527, 0.3226, 0.9277, 0.5957, 0.8053),
}
MTOTDEV_RHO = (
    (0.9316, 0.8458, 0.7391, 0.9798, 0.9261, 0.9827),  # r = 3.0 (m = 128, n/m = 3.01)
    (0.9242, 0.8294, 0.7046, 0.9775, 0.9121, 0.9778),  # r = 3.5 (m = 110, n/m = 3.50)
    (0.9102, 0.7876, 0.6088, 0.9676, 0.8610, 0.9603),  # r = 4.0 (m = 96, n/m = 4.01)
    (0.9023, 0.7563, 0.5216, 0.9570, 0.7978, 0.9353),  # r = 4.5 (m = 86, n/m = 4.48)
    (0.8929, 0.7297, 0.4497, 0.9485, 0.7350, 0.9051),  # r = 5.0 (m = 77, n/m = 5.00)
    (0.8745, 0.6925, 0.3845, 0.9403, 0.6708, 0.8656),  # r = 6.0 (m = 64, n/m = 6.02)
    (0.8589, 0.6607, 0.3439, 0.9329, 0.6302, 0.8364),  # r = 8.0 (m = 48, n/m = 8.02)
    (0.8504, 0.6429, 0.3213, 0.9282, 0.6072, 0.8191),  # r = 12.0 (m = 32, n/m = 12.03)
    (0.8474, 0.6367, 0.3134, 0.9265, 0.5991, 0.8129),  # r = 16.0 (m = 24, n/m = 16.04)
    (0.8451, 0.6319, 0.3072, 0.9252, 0.5926, 0.8078),  # r = 24.0 (m = 16, n/m = 24.06)
    (0.8441, 0.6300, 0.3048, 0.9247, 0.5900, 0.8056),  # r = 32.0 (m = 12, n/m = 32.08)
    (0.8435, 0.6300, 0.3042, 0.9246, 0.5881, 0.8033),  # r = 64.0 (m = 6, n/m = 64.17)
)
# fmt: on
"""`MTOTDEV_RHO_M` (m = 1, 2, 3) and `MTOTDEV_RHO` (m ≥ 4, by r = n/m:
[`MTOTDEV_RHO_R`][hrgjax.allan.mixture.MTOTDEV_RHO_R]): ρᵢⱼ = tr(AΣᵢAΣⱼ)/√(tr(AΣᵢ)²·tr(AΣⱼ)²)
of mtotdev's raw quadratic form A for unit discrete power laws i, j, the pairs (α) (2, 0),
(2, −1), (2, −2), (0, −1), (0, −2), (−1, −2); from the dense forms over 385 phase points
(`benchmarks/coverage_mtotdev.py --rho 385`), within 0.004 of those over 97–1 025 points
at the same m (m ≤ 3) or r (m ≥ 4)."""


def mtotdev_rho(m: int, n: int) -> np.ndarray:
    """ρᵢⱼ (4 × 4, in [`MIXTURE_TERMS`][hrgjax.allan.mixture.MIXTURE_TERMS]' order, 1 on the
    diagonal) of mtotdev's raw estimator at factor `m` over `n` phase points: the cross term
    2 tr(AΣᵢAΣⱼ) of Var Mod Totvar over √(Varᵢ·Varⱼ) (tables
    [`MTOTDEV_RHO`][hrgjax.allan.mixture.MTOTDEV_RHO]; m ≥ 4 interpolated in 1/r, r = n/m,
    r ≥ 64 the last row). [dimensionless]"""
    m = int(m)
    if m in MTOTDEV_RHO_M:
        pairs = np.asarray(MTOTDEV_RHO_M[m])
    else:
        table = np.asarray(MTOTDEV_RHO)
        inv = 1.0 / np.asarray(MTOTDEV_RHO_R)[::-1]  # increasing
        at = min(max(m / float(n), inv[0]), inv[-1])
        pairs = np.asarray([np.interp(at, inv, col[::-1]) for col in table.T])
    rho = np.eye(len(MIXTURE_TERMS))
    rho[np.triu_indices(len(MIXTURE_TERMS), 1)] = pairs
    return np.maximum(rho, rho.T)


def mixture_mtotdev_edf(value: dict, m, n: int, tau0: float) -> np.ndarray:
    """EDF of mtotdev's (and ttotdev's) raw estimator at factors `m` over `n` phase points
    sampled every `tau0` [s] under independent IEEE 952 terms of coefficients `value` (as
    [`mixture_bias`][hrgjax.allan.mixture.mixture_bias]). For a quadratic form of a sum of
    independent Gaussian terms Var Q = Σᵢⱼ 2 tr(AΣᵢAΣⱼ): the diagonal each term's own
    2Eᵢ²/EDFᵢ (Eᵢ = b(αᵢ, m)·Mod σ²ᵢ, its share of E[Mod Totvar]; EDFᵢ
    [`edf_mtotdev`][hrgjax.allan.total.edf_mtotdev] at its α), the cross terms
    ρᵢⱼ·√(Varᵢ·Varⱼ) ([`mtotdev_rho`][hrgjax.allan.mixture.mtotdev_rho]), so
    EDF = (Σᵢ Eᵢ)²/Σᵢⱼ ρᵢⱼ·(Eᵢ/√EDFᵢ)(Eⱼ/√EDFⱼ), between (ΣEᵢ)²/(ΣEᵢ/√EDFᵢ)² (ρ = 1) and
    (ΣEᵢ)²/Σ Eᵢ²/EDFᵢ (ρ = 0). Within 4.5 % of the dense form's exact EDF on four gyro
    mixtures (`benchmarks/coverage_mixture.py`'s, 1 025 points), as the Monte Carlo's raw
    estimate. Not used by [`deviation`][hrgjax.allan.deviation]: with the divisor b_mix
    fitted to the same record the corrected estimate's EDF is up to 1.2× lower (module
    docstring). NaN where every term is 0. [dimensionless]"""
    from .total import edf_mtotdev

    m = np.asarray(m, dtype=int)
    shares = _raw_shares(value, m, tau0)
    index = [MIXTURE_TERMS.index(t) for t in shares]
    out = np.full(m.size, np.nan)
    for i, k in enumerate(m.ravel()):
        e = np.asarray([raw.ravel()[i] for raw, _ in shares.values()])
        if not e.size or not e.sum() > 0:
            continue
        edf = np.asarray([edf_mtotdev(TERM_ALPHA[t], int(k), int(n)) for t in shares])
        s = e / np.sqrt(edf)
        rho = mtotdev_rho(int(k), int(n))[np.ix_(index, index)]
        out[i] = max(e.sum() ** 2 / float(s @ rho @ s), 1.0)
    return out.reshape(m.shape)


def mixture_oadev_edf(value: dict, m, n: int, tau0: float) -> np.ndarray:
    """EDF of the overlapping Allan variance at factors `m` over `n` rate samples every `tau0`
    [s] under independent IEEE 952 terms of coefficients `value` (as
    [`mixture_bias`][hrgjax.allan.mixture.mixture_bias]): 2σ²(τ)²/Var σ̂²(τ), the variance
    the exact Gaussian one of [`covariance`][hrgjax.allan.octave_covariance.covariance] (the
    bias instability as a sum of Gauss–Markov terms,
    `noise_terms.flicker_as_gauss_markov`, ripple
    ≤ 3 %, over the record's octaves), each τ on its own one-τ layout. At least 1.
    [dimensionless]"""
    from .noise_terms import flicker_as_gauss_markov

    m = np.asarray(m, dtype=int)
    coef2 = {t: float(value.get(t, 0.0)) ** 2 for t in MIXTURE_TERMS}
    lin = {t: c for t, c in coef2.items() if t != "bias_instability" and c > 0}
    b2 = coef2["bias_instability"]
    # the flicker's terms span the record's octaves (not the grid's: one τ's EDF is then the
    # same on every grid)
    octaves = 2 ** np.arange(int(math.floor(math.log2(max(n / 2, 1)))) + 1)
    gm = [(b2 * s2, t) for s2, t in flicker_as_gauss_markov(octaves, tau0)] if b2 > 0 else []
    model = sum(c * _unit_avar(t, m * tau0) for t, c in coef2.items())
    out = np.empty(m.size)
    for i, k in enumerate(m.ravel()):
        var = covariance(lin, gm, [int(k)], int(n), tau0)[0, 0]
        out[i] = 2.0 * model.ravel()[i] ** 2 / var if var > 0 else np.nan
    return np.maximum(out.reshape(m.shape), 1.0)


def octave_oadev(x, tau0: float):
    """`(m, σ̂², n_terms)`: the overlapping Allan variance of the phase `x` (angle units, its
    first point 0) at the octave factors with at least 2 terms, in NumPy."""
    x = np.asarray(x, dtype=float)
    n_phase = x.size
    ms = 2 ** np.arange(int(math.floor(math.log2(max(n_phase, 2)))) + 1)
    ms = ms[n_phase - 2 * ms > 1]
    var = np.asarray([np.mean((x[2 * k :] - 2 * x[k:-k] + x[: -2 * k]) ** 2) / (2 * (k * tau0) ** 2)
                      for k in ms])  # fmt: skip
    return ms, var, n_phase - 2 * ms


def fit_mixture(x, tau0: float):
    """The IEEE 952 mixture ([`MIXTURE_TERMS`][hrgjax.allan.mixture.MIXTURE_TERMS]) fitted to
    the overlapping Allan variance of the gap-free phase `x` (angle units, x₀ = 0; rate
    samples every `tau0` [s]) at its octaves: `(NoiseFit, "")`, or `(None, why)` where the
    fit cannot be trusted (fewer than [`MIN_OCTAVES`][hrgjax.allan.mixture.MIN_OCTAVES]
    octaves, no exact covariance, every term 0, or a misfit p-value below
    [`FIT_P_MIN`][hrgjax.allan.mixture.FIT_P_MIN])."""
    from .curve_result import AllanResult
    from .noise_terms import fit_terms
    from .uncertainty import ONE_SIGMA

    ms, var, counts = octave_oadev(x, tau0)
    if ms.size < MIN_OCTAVES:
        return None, f"{ms.size} octaves, fewer than {MIN_OCTAVES}"
    if not np.all(var > 0):
        return None, "an octave's Allan variance is 0"
    n_phase = len(x)
    # EDF weights only start the fit (white rate noise's); it is then refitted by GLS
    edf = np.asarray([edf_greenhall(0, 2, int(k), n_phase, True, False, discrete=True) for k in ms])
    dev = np.sqrt(var)
    result = AllanResult(kind="oadev", ci=ONE_SIGMA, taus=ms * tau0, m=ms, dev=dev,
                         dev_low=dev, dev_high=dev, edf=edf, n_terms=counts,
                         alpha=np.zeros(ms.size, dtype=int))  # fmt: skip
    with np.errstate(all="ignore"):
        fit = fit_terms(result, terms=list(MIXTURE_TERMS), intervals=False)
    if not fit.method.startswith("gls"):
        return None, f"no exact covariance ({fit.method})"
    if not any(fit.value[t] > 0 for t in MIXTURE_TERMS):
        return None, "every term fitted 0"
    p = chi2_sf(fit.chi2, fit.dof) if fit.dof > 0 else 1.0
    if not p >= FIT_P_MIN:
        return None, f"misfit p-value {p:.2g} < {FIT_P_MIN:g} (noise outside the IEEE 952 terms)"
    return fit, ""


def mixture_statistics(kind: str, x, tau0: float, m):
    """`(used, values)` for [`deviation`][hrgjax.allan.deviation] under
    `noise_rule="hrgjax"`: the mixture fitted to the gap-free phase `x` (angle units,
    x₀ = 0, samples every `tau0` [s]; [`fit_mixture`][hrgjax.allan.mixture.fit_mixture]) and
    from it, at factors `m`, mtotdev's and ttotdev's bias b_mix
    ([`mixture_bias`][hrgjax.allan.mixture.mixture_bias]) or oadev's EDF
    ([`mixture_oadev_edf`][hrgjax.allan.mixture.mixture_oadev_edf], grids of up to
    [`MAX_EDF_TAUS`][hrgjax.allan.mixture.MAX_EDF_TAUS] τ); `used` (bool per τ) is False
    where the fit was refused or the value could not be had, and `values` None where none
    was. The fit (≈ 10–50 ms of CPU on 10³–10⁵ samples) runs only where its
    result is used: not for other kinds nor for oadev grids of more than `MAX_EDF_TAUS` τ."""
    m = np.asarray(m, dtype=int)
    none = np.zeros(m.size, dtype=bool), None
    if not (kind in ("mtotdev", "ttotdev") or (kind == "oadev" and m.size <= MAX_EDF_TAUS)):
        return none  # nothing here would use the fit: not fitted
    fit, _ = fit_mixture(x, tau0)
    if fit is None:
        return none
    value = {t: float(fit.value[t]) for t in MIXTURE_TERMS}
    if kind in ("mtotdev", "ttotdev"):
        values = mixture_bias(value, m, tau0)
    else:
        values = mixture_oadev_edf(value, m, len(x) - 1, tau0)
    used = np.isfinite(values) & (values > 0)
    return used, np.where(used, values, 1.0)
