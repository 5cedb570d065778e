"""The discovery's noise model: the pattern-angle [`NoiseModel`][hrgjax.pattern_noise.NoiseModel]
(defined once, in `hrgjax.pattern_noise`, beside the gyro's
[`hrgjax.Noise`][]: the bench design reads the same model) and its estimation from a log's
still stretches (or, where a log has none, its static stretches whatever the temperature
does: [`estimated`][hrgjax.discovery.noise.estimated]), which both data shapes use — the dwell windows' σ
([`slope_sigma`][hrgjax.pattern_noise.NoiseModel.slope_sigma]) and the continuous records'
whitening ([`increment_covariance`][hrgjax.pattern_noise.NoiseModel.increment_covariance])."""

from __future__ import annotations

from .._checks import describe, is_finite_real, numeric_problem
from ..data import MeasuredData
from ..pattern_noise import GM_TIMES as GM_TIMES
from ..pattern_noise import MIN_STRETCH as MIN_STRETCH
from ..pattern_noise import TEMPERATURE_TOLERANCE_C as TEMPERATURE_TOLERANCE_C
from ..pattern_noise import NoiseModel as NoiseModel
from ..pattern_noise import longest_still_s


def noise_model(data: MeasuredData, max_lag_s: float = 1024.0) -> NoiseModel:
    """The noise model of `data`'s still stretches
    ([`NoiseModel.estimate`][hrgjax.pattern_noise.NoiseModel.estimate]); used by both data
    shapes.

    **Raises:** `TypeError` for `data` that is not a `MeasuredData` or a `max_lag_s` that is
    not a number, `ValueError` for a `max_lag_s` not finite and > 0 [s] (it was reported as
    "the noise model needs a still stretch") or data with no still stretch."""
    if not isinstance(data, MeasuredData):
        raise TypeError(f"data must be an hrgjax.MeasuredData; got {type(data).__name__}")
    if not (is_finite_real(max_lag_s) and max_lag_s > 0):
        kind = TypeError if numeric_problem(max_lag_s) else ValueError
        raise kind(f"max_lag_s must be a finite number > 0 [s]; got {describe(max_lag_s)}")
    return NoiseModel.estimate(data, max_lag_s)


SHORT_STILL_S = 30.0
"""A log whose longest still stretch is shorter than this [s] reads its noise model from its
static stretches whatever the temperature does ([`estimated`][hrgjax.discovery.noise.estimated])."""
NOISE_STILL = "still stretches"
NOISE_GIVEN = "given (noise=)"
NOISE_DRIFTING = (
    "the static stretches along the temperature ramps (no hold: second differences up to "
    "256 s beside the ramp's drift; noise= gives it instead)"
)
"""Where a problem's noise model comes from (its `noise_report`'s `source`)."""


def estimated(data: MeasuredData) -> tuple[NoiseModel, str]:
    """The noise model of `data` and its source in words: its still stretches
    ([`NoiseModel.estimate`][hrgjax.pattern_noise.NoiseModel.estimate]); where there are
    none (a chamber that ramps without a hold), its static stretches whatever the
    temperature does
    ([`estimate_drifting`][hrgjax.pattern_noise.NoiseModel.estimate_drifting]).

    A log whose longest still stretch is shorter than `SHORT_STILL_S` (a ramp sampled
    fast leaves stretches of a few seconds within 0.1 °C: their lags cannot show the angle
    random walk, read as 0 at 10 Hz) takes the static stretches' model too.

    **Raises:** `ValueError` in one line when no stretch has the table still."""
    longest = longest_still_s(data)
    if longest >= SHORT_STILL_S:
        return NoiseModel.estimate(data), NOISE_STILL
    try:
        return NoiseModel.estimate_drifting(data), NOISE_DRIFTING
    except ValueError:
        if longest > 0.0:
            return NoiseModel.estimate(data), NOISE_STILL
        raise ValueError(
            f"the noise model needs a stretch of at least {MIN_STRETCH} samples with the table "
            "still (a static run or a hold), and this log has none; pass noise=hrgjax.Noise(...)"
        ) from None
