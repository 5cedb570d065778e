r"""IEEE 952 noise terms fitted to an Allan deviation.

On an Allan-deviation plot: quantisation $\sqrt3 Q/\tau$, angle random walk $N/\sqrt\tau$,
bias instability flat at $0.6643B$, rate random walk $K\sqrt{\tau/3}$, rate ramp
$R\tau/\sqrt2$ ([`NOISE_TERMS`][hrgjax.allan.NOISE_TERMS]);
[`fit_noise`][hrgjax.allan.fit_noise] fits them to an
[`AllanResult`][hrgjax.allan.AllanResult] by non-negative generalised least squares under
the overlapping estimator's own covariance
([`covariance`][hrgjax.allan.octave_covariance.covariance]).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from statistics import NormalDist

import numpy as np

from .._checks import check_numbers, describe
from .._nnls import nnls as _nnls
from .._progress import bar
from .curve_result import AllanResult
from .octave_covariance import covariance, gapped_covariance, unit_avar
from .uncertainty import chi2_sf

NOISE_TERMS = (
    ("quantization", "Q", "rate unit·s", lambda t: 3.0 / t**2),
    ("angle_random_walk", "N", "rate unit·√s", lambda t: 1.0 / t),
    ("bias_instability", "B", "rate unit", lambda t: np.full_like(t, 2 * math.log(2) / math.pi)),
    ("rate_random_walk", "K", "rate unit/√s", lambda t: t / 3.0),
    ("rate_ramp", "R", "rate unit/s", lambda t: t**2 / 2.0),
)
"""IEEE 952 terms of the Allan variance: (name, symbol, unit, σ²(τ) per unit coefficient²)
— 3Q²/τ², N²/τ, (2 ln 2/π)B², K²τ/3, R²τ²/2 (the bias instability's flat part, 0.664 B)."""


_COVARIANCE_TERMS = ("quantization", "angle_random_walk", "rate_random_walk", "rate_ramp")
"""The terms whose estimator covariance is exact ([`covariance`][hrgjax.allan.octave_covariance.covariance]);
the bias instability's (flicker rate noise) is that of a sum of Gauss–Markov terms
(`flicker_as_gauss_markov` in this module)."""
_MAX_TAUS = 64  # Ω's layout grows ≈ as S³ (85 s for 254 τ, 1.5 s for 64): beyond, the EDF fallback
_ROUNDS = 4  # the covariance re-evaluated at the fit this many times: settled in 2–3 for two
# terms, not for four (four bands, 8192 samples: K 0.01234 after 4, 0.01308 after 32 from
# the mixture EDF's start; 0.01110 → 0.01308 from the one-type EDF's), which the start moves


@dataclasses.dataclass(frozen=True)
class NoiseFit:
    """IEEE 952 noise coefficients fitted to an Allan deviation
    ([`fit_noise`][hrgjax.allan.fit_noise]).

    - `value`, `sigma`, `low`, `high`: `{name: float}` for quantization Q [rate unit·s],
      angle_random_walk N [rate unit·√s], bias_instability B [rate unit], rate_random_walk K
      [rate unit/√s] and rate_ramp R [rate unit/s] — for rates in °/h, N in °/h·√s is
      N/60 in °/√h. A term the data do not show is 0 with an upper bound. `low`/`high`: the
      interval at the result's `ci` on the coefficient² (its ends' square roots), found by
      inverting the estimate's law — its variance own·θ² + rest at truth θ, the term's own
      part skewed like a χ² of 2/own degrees of freedom ([`fit_noise`][hrgjax.allan.fit_noise]);
      for a term at 0, `low` 0 and `high` √(zσ(c²)).
    - `chi2`, `dof`: the misfit of the Allan variance (whitened by the covariance the fit
      used) and its degrees of freedom.
    - `method`: how the σ were obtained — `"gls"`: generalised least squares under the
      overlapping estimator's exact Gaussian covariance for the record's length (with gaps:
      for its gap-free runs, `AllanResult.segments`), evaluated at the fit; `"gls, flicker approximated"`: the same with the bias instability's
      flicker noise taken as a sum of Gauss–Markov terms; `"independent: <reason>"`: the τ
      points taken as independent with EDF weights (σ too narrow: K's z-RMS ≈ 1.8), and why
      the covariance could not be used.
    """

    value: dict
    sigma: dict
    low: dict
    high: dict
    chi2: float
    dof: int
    method: str = "gls"

    def adev(self, taus) -> np.ndarray:
        """The fitted Allan deviation at `taus` [s]."""
        t = np.asarray(check_numbers("taus", taus, "τ values > 0 [s]"), dtype=float)
        if not np.all(np.isfinite(t) & (t > 0)):  # τ ≤ 0: NaN or a wrong value
            raise ValueError(f"taus must be τ values > 0 [s] (finite); got {describe(taus)}")
        return np.sqrt(sum(self.value[n] ** 2 * f(t) for n, _, _, f in NOISE_TERMS))


def flicker_as_gauss_markov(ms, tau0: float) -> list:
    """Flicker rate noise (the bias instability's flat Allan variance (2 ln 2/π)·B² with
    B = 1) over the averaging factors `ms` of samples every `tau0` [s] as a sum of first-order
    Gauss–Markov terms `[(σ², T [s])]`, correlation times 4× apart from ¼ of the shortest τ
    to 8× the longest, σ² by least squares on the flat variance, kept non-negative (ripple ≤ 3 %
    between the shortest and longest τ): the covariance
    [`covariance`][hrgjax.allan.octave_covariance.covariance] takes it as such."""
    ms = np.asarray(ms, dtype=float)
    lo, hi = math.log2(ms.min()) - 2, math.log2(ms.max()) + 3
    ts = tau0 * 2.0 ** np.arange(lo, hi + 1e-9, 2.0)
    dense = np.unique(np.round(np.geomspace(ms.min(), ms.max(), 200)))
    cols = unit_avar("gauss_markov", dense, tau0, tau0 / ts).T / (2 * math.log(2) / math.pi)
    keep = np.ones(ts.size, dtype=bool)
    while True:  # least squares, the terms it makes negative dropped (edge terms only)
        w = np.zeros(ts.size)
        w[keep] = np.linalg.lstsq(cols[:, keep], np.ones(dense.size), rcond=None)[0]
        if np.all(w >= 0):
            return [(float(s2), float(t)) for s2, t in zip(w, ts, strict=True) if s2 > 0]
        keep &= w > 0


def _record(result: AllanResult):
    """`((n, τ₀), "")`: the gap-free record of n rate samples every τ₀ behind an oadev
    result, from its factors and counts (oadev averages n + 1 − 2m second differences), or
    for a rate record with gaps its runs `segments` ((R, 2): start, length) in place of n,
    checked against the counts (Σᵣ max(Lᵣ + 1 − 2m, 0)) — or `(None, why)` where the
    estimator's covariance does not apply."""
    if result.kind != "oadev":
        return None, "adev (non-overlapping estimates: their covariance is not implemented)"
    if result.m is None or result.n_terms is None:
        return None, "the result carries no averaging factors or counts"
    m = np.asarray(result.m, dtype=float)
    counts = np.asarray(result.n_terms, dtype=float)
    if m.shape != result.taus.shape or counts.shape != m.shape or np.any(m < 1) or np.any(m % 1):
        return None, "the result's averaging factors are not positive integers, one per τ"
    tau0 = result.taus / m
    if not np.allclose(tau0, tau0[0], rtol=1e-9, atol=0.0):
        return None, "τ/m differs between τ (not one sampling interval)"
    n = counts + 2 * m - 1
    segments = getattr(result, "segments", None)
    if segments is not None:
        segments = np.asarray(segments)
        ok = segments.ndim == 2 and segments.shape[1] == 2 and segments.shape[0] > 0
        held = np.maximum(segments[:, 1:2] + 1 - 2 * m[None, :], 0).sum(0) if ok else None
        if not ok or np.any(segments < 0) or np.any(held != counts):
            return None, "the result's segments do not hold its counts of terms"
    elif np.any(n != n[0]):
        why = "a record with gaps and no runs (angle data): fewer terms than a gap-free one's"
        return None, why
    if m.size > _MAX_TAUS:
        return None, f"more than {_MAX_TAUS} τ (fit an octave or decade grid)"
    return (segments if segments is not None else int(n[0]), float(tau0[0])), ""


def _cov(coef: dict, gm: list, ms, n, tau0: float, layouts=None, progress=None) -> np.ndarray:
    """The estimates' covariance for the record `n`: a length, or runs (`_record`; `layouts`
    the fit's own store of the runs' layouts, `progress` its bar: `gapped_covariance`)."""
    if isinstance(n, np.ndarray):
        return gapped_covariance(coef, gm, ms, n, tau0, layouts=layouts, progress=progress)
    return covariance(coef, gm, ms, n, tau0)


def _omega(coef2: dict, flicker, ms, n, tau0, var, layouts=None, progress=None):
    """The estimates' covariance [unit⁴] at the fit `coef2` ({term: coefficient²}), each
    variance floored at 1e-6 of its own (or of the estimate's 2σ̂⁴/n) so it stays invertible."""
    lin = {t: c for t, c in coef2.items() if t in _COVARIANCE_TERMS}
    gm = [(coef2.get("bias_instability", 0.0) * s2, t) for s2, t in flicker]
    om = _cov(lin, gm, ms, n, tau0, layouts, progress)
    size = int(n[:, 1].sum()) if isinstance(n, np.ndarray) else n
    return om + np.diag(1e-6 * np.maximum(np.diag(om), 2 * var**2 / max(size, 1)))


def _pearson3_cdf(x: float, theta: float, own: float, rest: float) -> float:
    """P(ĉ² ≤ x) for a coefficient² of truth θ whose estimate has the variance own·θ² + rest:
    its own part θ·χ²_ν/ν (ν = 2/own, third cumulant 2·own²·θ³) plus the rest's symmetric
    noise, as the Pearson type III law (a shifted, scaled χ²) with these three cumulants."""
    v = own * theta * theta + rest
    if v <= 0:
        return float(x >= theta)
    k3 = 2 * own * own * theta**3
    if k3 <= 1e-12 * v**1.5:
        return NormalDist(theta, math.sqrt(v)).cdf(x)
    scale = k3 / (4 * v)
    k = 8 * v**3 / (k3 * k3)
    u = (x - theta) / scale + k  # χ²_k at x
    if u <= 0:
        return 0.0
    if k > 1e4:  # Wilson–Hilferty: χ²_k is then normal in its cube root to < 1e-6
        s = 2 / (9 * k)
        # (u/k)^(1/3) − 1 without cancellation: u/k = 1 + r with r tiny when k is large
        cube = math.expm1(math.log1p((x - theta) / (scale * k)) / 3)
        return NormalDist().cdf((cube + s) / math.sqrt(s))
    return 1.0 - chi2_sf(u, k)  # P(χ²_k ≤ u)


def _skewed_interval(c2: float, own: float, rest: float, ci: float) -> tuple:
    """The `ci` interval (θ_low, θ_high) on a coefficient² from its estimate `c2` > 0 by
    inverting the estimate's law: θ where P_θ(ĉ² ≤ c2) is (1 + ci)/2 and (1 − ci)/2. The law
    is `_pearson3_cdf`'s: variance own·θ² + rest [unit⁴], the term's own part skewed like a
    χ² of 2/own degrees of freedom. With rest = 0 this is the χ² interval
    (ν c2/χ²_ν((1 + ci)/2), ν c2/χ²_ν((1 − ci)/2)); with own → 0 it is c2 ± z√rest. A
    lower end that does not exist (the estimate within the noise of 0) is 0."""

    def root(p):  # P_θ falls as θ grows: bracket θ in log steps of e², then bisect log θ
        lo = hi = math.log(c2)
        while _pearson3_cdf(c2, math.exp(lo), own, rest) < p:
            lo -= 2.0
            if lo < math.log(c2) - 60:
                return 0.0
        while _pearson3_cdf(c2, math.exp(hi), own, rest) > p:
            hi += 2.0
        while hi - lo > 1e-10:
            mid = 0.5 * (lo + hi)
            if _pearson3_cdf(c2, math.exp(mid), own, rest) > p:
                lo = mid
            else:
                hi = mid
        return math.exp(0.5 * (lo + hi))

    return root((1 + ci) / 2), root((1 - ci) / 2)


def fit_noise(result: AllanResult, terms=None) -> NoiseFit:
    r"""Fit the IEEE 952 terms to an Allan deviation by non-negative generalised least squares
    on the Allan variance $\sigma^2(\tau) = 3Q^2/\tau^2 + N^2/\tau + (2\ln2/\pi)B^2 + K^2\tau/3
    + R^2\tau^2/2$ under the estimates' own covariance — what allantools leaves to the user.

    The fit starts from EDF weights (var σ̂² ≈ 2σ⁴/edf, the σ⁴ of the model, iterated); for
    an `oadev` result of a gap-free record (its n and τ₀ read off `m` and `n_terms`; any τ
    grid of up to 64 points — octaves, decades, arbitrary factors) it is then refitted by
    GLS under the exact Gaussian covariance Ω of the overlapping estimates for the record's
    length ([`covariance`][hrgjax.allan.octave_covariance.covariance]: finite record,
    neighbouring τ 0.5–0.8 correlated) evaluated at the fit, four times, and the
    coefficients' covariance is (AᵀΩ⁻¹A)⁻¹. A rate record with gaps gets the same from its
    gap-free runs (`AllanResult.segments`;
    [`gapped_covariance`][hrgjax.allan.octave_covariance.gapped_covariance]: the runs'
    differences correlated only through the flicker's tails): one missing sample in 4 000
    leaves σ as it was, where the independent τ made σ of N 0.71× too small
    (`benchmarks/coverage_fit_gaps.py`). The bias instability (flicker rate noise) has no
    closed form there: it enters Ω as a sum of Gauss–Markov terms (`flicker_as_gauss_markov`
    in this module). Where Ω cannot be had — `adev` (non-overlapping estimates), angle data
    with gaps, a result without its factors and counts, more than 64 τ — the τ points are
    taken as independent with EDF weights, intervals too narrow, and `method` says so with
    the reason.

    The interval on each coefficient² is the estimate's law inverted: for truth θ the
    estimate ĉ² = L·σ̂² (L the fit's rows) has the variance own·θ² + rest — own = LΩ₁Lᵀ with
    Ω₁ the term's own covariance at unit coefficient² (EDF: 2f²/edf per τ), rest the other
    terms' share at the fit — and its own part is skewed like θχ²_ν/ν with ν = 2/own (at long
    τ few degrees of freedom). As a Pearson III law (a shifted χ² with these three
    cumulants) the ends are the θ that put ĉ² at its (1 ± ci)/2 quantiles: the χ² interval
    where the term alone makes its estimate's noise, c² ± z√rest where the others do.

    Coverage (`benchmarks/coverage_allan.py --fit-noise --n 400`, seeds 0 and 7: 800
    records of 20 000 s at 1 Hz per case, oadev octaves, known truth): 95 % intervals held
    93.2–95.5 % for N, B and K on white + random walk, + flicker, white + flicker records
    (each seed 92–97 %); with c² ± zσ(c²) 85.8–96.5 %, K 89 and 86 % where B is fitted
    beside it (it reads 5–6 % low there), now 94–95 %. 68.27 % intervals held 61–73 % (pooled
    62–71 %; N and B 62–67 %, their z-RMS up to 1.11: σ a few % small, with flicker partly
    the simulation's, whose Allan variance is 17 % above flat at 1 s). Median width as the
    symmetric interval's (1.00–1.03). K's z-RMS 1.03–1.07 (τ independent: 1.6–1.8); on
    records of 4 096 samples 1.12, of 1 024 1.30 (the covariance is evaluated at a
    noisy fit).

    **Arguments:** `result` from [`deviation`][hrgjax.allan.deviation] with kind `adev` or
    `oadev` (the terms are Allan-variance slopes); `terms`: names of
    [`NOISE_TERMS`][hrgjax.allan.NOISE_TERMS] to fit (default all five).

    **Returns:** a [`NoiseFit`][hrgjax.allan.NoiseFit]; intervals at the result's `ci` on
    each coefficient² (the law above inverted; a term at 0: from 0 to √(zσ(c²))), their
    ends' square roots. Every term
    asked for is fitted, present or not: on records of white noise and a rate random walk
    alone its bias instability B came out clear of 0 in 15–25 % of them
    (`benchmarks/noise_identification.py`). It is the IEEE 952 line fit, for reading the
    textbook coefficients off a curve; for a noise model with only the terms the record
    needs, use [`identify_noise`][hrgjax.allan.identify_noise].
    """
    return fit_terms(result, terms)


def fit_terms(result: AllanResult, terms=None, *, intervals: bool = True) -> NoiseFit:
    """[`fit_noise`][hrgjax.allan.fit_noise] (same arguments, same fit); `intervals=False`
    skips the intervals — `low` and `high` NaN, and none of the terms' own covariances they
    need (one Ω per fitted term, ≈ 4 of its 9) is built — for callers that use only `value`,
    `chi2` and `method` ([`fit_mixture`][hrgjax.allan.mixture.fit_mixture])."""
    if not isinstance(result, AllanResult):
        raise TypeError(f"result must be an AllanResult; got {type(result).__name__}")
    if result.kind not in ("adev", "oadev"):
        raise ValueError(
            f"result.kind must be 'adev' or 'oadev' (Allan variance); got {result.kind!r}"
        )
    names = [n for n, *_ in NOISE_TERMS]
    if terms is not None and (isinstance(terms, str) or not hasattr(terms, "__iter__")):
        raise ValueError(f"terms must be a list of names among {names}; got {describe(terms)}")
    terms = names if terms is None else list(terms)
    bad = [t for t in terms if t not in names]
    if bad or not terms:  # a str was read letterwise, [] failed in np.stack
        raise ValueError(f"terms must be among {names} (at least one); got {bad or terms}")
    fitted = [n for n in names if n in terms]
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
    chi2 = float(np.sum(((basis @ coef - var) * w) ** 2))
    weights = cov @ (basis * (w * w)[:, None]).T  # c² = weights @ σ̂², the estimator's rows
    unit = {n: f(t) for n, _, _, f in NOISE_TERMS}

    def own_cov(name):  # Cov(σ̂²) of one term alone at unit coefficient² (EDF: independent)
        return np.diag(2 * unit[name] ** 2 / edf)

    rec, why = _record(result)
    segments = rec[0] if rec is not None and isinstance(rec[0], np.ndarray) else None
    lengths = 0 if segments is None else int(np.unique(segments[:, 1]).size)
    # a gapped record's Ω loops over its distinct run lengths, 6–10 times: seconds to minutes
    # at 10⁵–10⁶ samples (benchmarks/gapped_fit_speed.py), so it goes behind a bar
    steps = (_ROUNDS + 1 + len(fitted) * intervals) * lengths
    desc = "noise fit: covariance of the gapped runs"
    with bar(steps, desc, unit="length") if lengths else contextlib.nullcontext() as progress:
        method = f"independent: {why}"
        if rec is not None:
            n, tau0 = rec
            ms = np.asarray(result.m, dtype=int)
            flicker = flicker_as_gauss_markov(ms, tau0) if "bias_instability" in fitted else []
            layouts = {}  # a gapped record's run layouts, each built once for the fit's 6-7 Ω

            def whitened(c):  # Ω at the fit c: its inverse Cholesky factor, A whitened, scales
                coef2 = dict(zip(fitted, c, strict=True))
                omega = _omega(coef2, flicker, ms, n, tau0, var, layouts, progress)
                w_inv = np.linalg.inv(np.linalg.cholesky(omega))
                a = w_inv @ basis
                return w_inv, a, np.linalg.norm(a, axis=0)

            try:
                gls = coef
                for _ in range(_ROUNDS):
                    chol_inv, a, scale = whitened(gls)
                    gls = _nnls(a / scale, chol_inv @ var) / scale
                chol_inv, a, scale = whitened(gls)
                gls_cov = np.linalg.pinv((a / scale).T @ (a / scale)) / np.outer(scale, scale)
            except np.linalg.LinAlgError:
                method = "independent: the covariance at the fit is degenerate"
            else:
                coef, cov = gls, gls_cov
                chi2 = float(np.sum((chol_inv @ (basis @ coef - var)) ** 2))
                weights = cov @ a.T @ chol_inv

                def own_cov(name, n=n):  # Ω of one term alone at unit coefficient²
                    if name == "bias_instability":
                        return _cov({}, flicker, ms, n, tau0, layouts, progress)
                    return _cov({name: 1.0}, [], ms, n, tau0, layouts, progress)

                method = "gls, flicker approximated" if flicker else "gls"
        if progress is not None:  # the rest: Ω of each term at a value, one per term above 0
            more = int(np.count_nonzero(coef > 0)) if method.startswith("gls") and intervals else 0
            progress.total = progress.n + more * lengths
            progress.refresh()
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
            if not intervals:
                low[n] = high[n] = math.nan
            elif c > 0:
                own = float(weights[i] @ own_cov(n) @ weights[i])  # Var of c²'s own part per c⁴
                lo, hi = _skewed_interval(c, own, max(cov[i, i] - own * c * c, 0.0), result.ci)
                low[n], high[n] = math.sqrt(lo), math.sqrt(hi)
            else:  # at the bound: an upper limit only, from the fit's σ of the coefficient²
                low[n], high[n] = 0.0, math.sqrt(z * sc)
    return NoiseFit(value, sigma, low, high, chi2, int(t.size - np.count_nonzero(coef)), method)
