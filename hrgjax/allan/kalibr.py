r"""Kalibr's white noise and random walk from a composite noise model's Gauss–Markov terms,
and how far the export's Allan deviation lies from the model's (used by
[`CompositeNoise.to_kalibr`][hrgjax.allan.CompositeNoise.to_kalibr]).

Kalibr models white rate noise (Allan variance N²/τ) and a rate random walk (K²τ/3): a
valley on a log–log plot. A first-order Gauss–Markov rate (σ, T) is a hill: for interval
means it rises as its short-time walk 2σ²τ/(3T) for τ ≪ T and falls as white noise 2σ²T/τ
for τ ≫ T. No white + walk pair follows it at every τ; each of the two alone bounds it from
above at every τ and is exact on its own side of T.

**The rule** ([`fold_gauss_markov`][hrgjax.allan.kalibr.fold_gauss_markov]). Over the
octaves the model was fitted on (τ₀ … τ_max, the record's own τ range), each term goes
whole into the white noise (N² += [`gm_white_level`][hrgjax.allan.composite.gm_white_level],
2σ²T for interval means) or into the walk (K² += 2σ²/T), whichever overstates the term's
exact Allan variance (for the model's `sampling`) less at its worst octave. The export
then never understates a Gauss–Markov term at an octave: a filter tuned with it is not
overconfident about that term at any averaging time the record resolved. (White angle
noise Q is the exception, below: at τ = Δt its fold gives √(2/3) = 0.816× Q's own Allan
deviation, so a model with Q is exported at ≥ 0.816× at τ₀ = Δt, ≥ 1× from 2Δt on.) A
term's overstatement is at most the stated factor: the white form's worst is at τ₀ (≈ √3·T/τ₀ in deviation for T ≫ τ₀), the
walk's at τ_max (≈ τ_max/(√3·T)), so the choice switches near T ≈ √(τ₀·τ_max). The worst
ratio in Allan deviation over 15 octaves at 100 Hz (τ₀ = Δt, τ_max = 2¹⁴Δt; interval
means; `benchmarks/kalibr_fold.py`): T = Δt/4 1.26, Δt 2.44, 4Δt 7.6, 8Δt 14.5, 64Δt 111
(white); 128Δt 74, 1024Δt 9.7, 2¹⁴Δt 1.41, 10⁶Δt 1.006 (walk).

Not chosen: the white + walk pair fitted by least squares in log Allan variance over the
octaves follows the hill's wings, not its peak: it understates the term there, by up to
6× in deviation (0.165× at T = 64Δt), which makes a filter overconfident. The pair with
the least worst ratio that still bounds the term (a linear programme in N², K²) beats the
rule by at most 2.2× (52 against 111 at T = 64Δt), only within a decade of the switch, and
buys it by raising the other entry until it too reaches the worst ratio at the far end of
the octaves (at T = 8Δt a walk 14× the term's deviation at τ_max, for 5 % at τ₀).

Other terms: white angle noise Q is written as white at the record's rate (`to_kalibr`:
N² += 2Q²/Δt, so that the per-sample σ is the record's, 2Q²/Δt² on each rate sample). Its
Allan variance is then 2Q²/(Δt·τ) against Q's own 3Q²/τ² (either sampling): 0.816× in
deviation at τ = Δt (the MA(1) rates' negative correlation, which white noise lacks, adds
half again there), 1.15× at 2Δt, √(2τ/3Δt) beyond. Folded as 3Q²/Δt it would bound Q at
every τ but overstate each sample's σ by √(3/2); a term the record did not need and whose upper bound is 0 (the octaves
reject even a zero one: the model already lies above them) is written at
[`ABSENT_SHARE`][hrgjax.allan.kalibr.ABSENT_SHARE] of the model's Allan variance
([`negligible`][hrgjax.allan.kalibr.negligible]), since Kalibr refuses a 0.
"""

from __future__ import annotations

import math

import numpy as np

from .._checks import describe, is_finite_real
from .octave_covariance import gm_white_level, unit_avar

ABSENT_SHARE = 0.01
"""The share of the model's Allan variance at which `to_kalibr` writes a term absent from
the model whose upper bound is 0, at the octave where the term's Allan variance is largest
relative to the model's: it raises the model's Allan deviation by at most 0.5 % [1]."""

KALIBR = {"white": "angle_random_walk", "walk": "rate_random_walk"}
"""Kalibr's two forms and the composite model's terms with their Allan variances."""


def _factors(taus, dt):
    m = np.asarray(taus, dtype=float)
    if m.ndim != 1 or m.size == 0 or not np.all(np.isfinite(m) & (m > 0)):
        raise ValueError(f"taus must be a 1-D array of positive times [s]; got {describe(taus)}")
    return np.unique(np.maximum(np.round(m / dt), 1.0))


def fold_gauss_markov(sigma, correlation_time, taus, dt, sampling="interval") -> dict:
    """Kalibr's form of one first-order Gauss–Markov rate, σ = `sigma` [unit] and T =
    `correlation_time` [s], over the octaves `taus` [s] (rounded to whole samples) of a
    record sampled every `dt` [s] as `sampling` (`"interval"` or `"point"`) — module
    docstring. **Returns:** `{"form": "white" or "walk", "white": added to N² [unit²·s],
    "walk": added to K² [unit²/s], "worst": the largest ratio over `taus` of the form's
    Allan deviation to the term's exact one (≥ 1: both forms bound it), "at": that τ [s]}`,
    the form whose worst is smaller (white on a tie).

    **Raises:** `ValueError` for a negative σ, a T or `dt` not positive, or `taus` not a
    1-D array of positive times."""
    for name, v, ok in (("sigma", sigma, "≥ 0 [unit]"), ("correlation_time",
                        correlation_time, "> 0 [s]"), ("dt", dt, "> 0 [s]")):  # fmt: skip
        if not (is_finite_real(v) and (v >= 0 if name == "sigma" else v > 0)):
            raise ValueError(f"{name} must be a finite number {ok}; got {describe(v)}")
    m = _factors(taus, dt)
    levels = {"white": gm_white_level(sigma, correlation_time, dt, sampling),
              "walk": 2.0 * sigma * sigma / correlation_time}  # fmt: skip
    if sigma == 0:
        return {"form": "white", "white": 0.0, "walk": 0.0, "worst": 1.0, "at": float(m[0] * dt)}
    term = sigma**2 * unit_avar("gauss_markov", m, dt, dt / correlation_time, sampling)
    best = None
    for form in ("white", "walk"):
        ratio = np.sqrt(levels[form] * unit_avar(KALIBR[form], m, dt, sampling=sampling) / term)
        i = int(np.argmax(ratio))
        if best is None or ratio[i] < best["worst"]:
            best = {"form": form, "worst": float(ratio[i]), "at": float(m[i] * dt)}
    other = "walk" if best["form"] == "white" else "white"
    return {**best, best["form"]: float(levels[best["form"]]), other: 0.0}


def entries_ratio(model, noise_density, random_walk):
    """The ratio of the Allan deviation of Kalibr's entries — white noise `noise_density`
    [unit·√s] and random walk `random_walk` [unit/√s], in `model`'s rate unit — to the
    model's own ([`CompositeNoise`][hrgjax.allan.CompositeNoise] `model`) at its octaves
    `model.taus` (inf where the model is 0). **Returns:** `(lowest, highest, τ of the
    highest [s])`."""
    dt = 1.0 / model.rate_hz
    m = _factors(model.taus, dt)
    export = sum(c * c * unit_avar(KALIBR[form], m, dt, sampling=model.sampling)
                 for form, c in (("white", noise_density), ("walk", random_walk)))  # fmt: skip
    with np.errstate(divide="ignore", invalid="ignore"):  # a model of no term: inf
        ratio = np.sqrt(export / model.model_avar(m * dt))
    i = int(np.argmax(ratio))
    return float(np.min(ratio)), float(ratio[i]), float(m[i] * dt)


def negligible(model, name: str) -> float:
    """The value of term `name` (`"angle_random_walk"` or `"rate_random_walk"`, absent from
    `model`) whose Allan variance is [`ABSENT_SHARE`][hrgjax.allan.kalibr.ABSENT_SHARE] of
    the model's at the octave where it is largest relative to it [N: unit·√s; K: unit/√s];
    0 where the model is 0 at an octave."""
    if name not in KALIBR.values():
        raise ValueError(f"name must be one of {list(KALIBR.values())}; got {name!r}")
    dt = 1.0 / model.rate_hz
    m = _factors(model.taus, dt)
    share = model.model_avar(m * dt) / unit_avar(name, m, dt, sampling=model.sampling)
    return math.sqrt(ABSENT_SHARE * float(np.min(share)))
