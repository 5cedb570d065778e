"""The discovery's noise model: the pattern-angle [`NoiseModel`][hrgjax.pattern_noise.NoiseModel]
(defined once, in `hrgjax.pattern_noise`, beside the gyro's
[`hrgjax.Noise`][]: the bench design reads the same model) and its estimation from a log's
still stretches, which both data shapes use — the dwell windows' σ
([`slope_sigma`][hrgjax.pattern_noise.NoiseModel.slope_sigma]) and the continuous records'
whitening ([`increment_covariance`][hrgjax.pattern_noise.NoiseModel.increment_covariance])."""

from __future__ import annotations

from .._checks import describe, is_finite_real, numeric_problem
from ..data import MeasuredData
from ..pattern_noise import GM_TIMES as GM_TIMES
from ..pattern_noise import MIN_STRETCH as MIN_STRETCH
from ..pattern_noise import TEMPERATURE_TOLERANCE_C as TEMPERATURE_TOLERANCE_C
from ..pattern_noise import NoiseModel as NoiseModel


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
