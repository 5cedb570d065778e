r"""IEEE 952 noise terms fitted to an Allan deviation.

On an Allan-deviation plot: quantisation $\sqrt3 Q/\tau$, angle random walk $N/\sqrt\tau$,
bias instability flat at $0.6643B$, rate random walk $K\sqrt{\tau/3}$, rate ramp
$R\tau/\sqrt2$ ([`NOISE_TERMS`][hrgjax.allan.NOISE_TERMS]);
[`fit_noise`][hrgjax.allan.fit_noise] fits them to an
[`AllanResult`][hrgjax.allan.AllanResult] by weighted non-negative least squares.
"""

from __future__ import annotations

import dataclasses
import math
from statistics import NormalDist

import numpy as np

from .._nnls import nnls as _nnls
from .result import AllanResult

NOISE_TERMS = (
    ("quantization", "Q", "rate unit·s", lambda t: 3.0 / t**2),
    ("angle_random_walk", "N", "rate unit·√s", lambda t: 1.0 / t),
    ("bias_instability", "B", "rate unit", lambda t: np.full_like(t, 2 * math.log(2) / math.pi)),
    ("rate_random_walk", "K", "rate unit/√s", lambda t: t / 3.0),
    ("rate_ramp", "R", "rate unit/s", lambda t: t**2 / 2.0),
)
"""IEEE 952 terms of the Allan variance: (name, symbol, unit, σ²(τ) per unit coefficient²)
— 3Q²/τ², N²/τ, (2 ln 2/π)B², K²τ/3, R²τ²/2 (the bias instability's flat part, 0.664 B)."""


@dataclasses.dataclass(frozen=True)
class NoiseFit:
    """IEEE 952 noise coefficients fitted to an Allan deviation
    ([`fit_noise`][hrgjax.allan.fit_noise]).

    - `value`, `sigma`, `low`, `high`: `{name: float}` for quantization Q [rate unit·s],
      angle_random_walk N [rate unit·√s], bias_instability B [rate unit], rate_random_walk K
      [rate unit/√s] and rate_ramp R [rate unit/s] — for rates in °/h, N in °/h·√s is
      N/60 in °/√h. A term the data do not show is 0 with an upper bound. `low`/`high`: the
      interval at the result's `ci`, from the fit's covariance.
    - `chi2`, `dof`: the weighted misfit of the Allan variance and its degrees of freedom.
    """

    value: dict
    sigma: dict
    low: dict
    high: dict
    chi2: float
    dof: int

    def adev(self, taus) -> np.ndarray:
        """The fitted Allan deviation at `taus` [s]."""
        t = np.asarray(taus, dtype=float)
        return np.sqrt(sum(self.value[n] ** 2 * f(t) for n, _, _, f in NOISE_TERMS))


def fit_noise(result: AllanResult, terms=None) -> NoiseFit:
    r"""Fit the IEEE 952 terms to an Allan deviation by weighted non-negative least squares
    on the Allan variance $\sigma^2(\tau) = 3Q^2/\tau^2 + N^2/\tau + (2\ln2/\pi)B^2 + K^2\tau/3
    + R^2\tau^2/2$, each τ weighted by its EDF (var σ̂² ≈ 2σ⁴/edf, the σ⁴ of the model,
    iterated) — what allantools leaves to the user.

    **Arguments:** `result` from [`deviation`][hrgjax.allan.deviation] with kind `adev` or
    `oadev` (the terms are Allan-variance slopes); `terms`: names of
    [`NOISE_TERMS`][hrgjax.allan.NOISE_TERMS] to fit (default all five).

    **Returns:** a [`NoiseFit`][hrgjax.allan.NoiseFit]; intervals at the result's `ci`,
    from the fit's covariance with the τ points taken as independent — overlapping estimates
    at neighbouring octaves are 0.5–0.8 correlated, so the intervals are too narrow (in
    simulated white + rate-random-walk records the K interval at 3σ held in 5 of 6) and
    every term asked for is fitted, present or not: on records of white noise and a rate
    random walk alone its bias instability B came out clear of 0 in 15–25 % of them
    (`benchmarks/noise_identification.py`). It is the IEEE 952 line fit, for reading the
    textbook coefficients off a curve; for a noise model with honest intervals and only the
    terms the record needs, use [`identify_noise`][hrgjax.allan.identify_noise].
    """
    if not isinstance(result, AllanResult):
        raise TypeError(f"result must be an AllanResult; got {type(result).__name__}")
    if result.kind not in ("adev", "oadev"):
        raise ValueError(
            f"result.kind must be 'adev' or 'oadev' (Allan variance); got {result.kind!r}"
        )
    names = [n for n, *_ in NOISE_TERMS]
    terms = names if terms is None else list(terms)
    bad = [t for t in terms if t not in names]
    if bad:
        raise ValueError(f"terms must be among {names}; got {bad}")
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
        low[n] = math.sqrt(max(c - z * sc, 0.0))
        high[n] = math.sqrt(c + z * sc)
    chi2 = float(np.sum(((basis @ coef - var) * w) ** 2))
    return NoiseFit(value, sigma, low, high, chi2, int(t.size - np.count_nonzero(coef)))
