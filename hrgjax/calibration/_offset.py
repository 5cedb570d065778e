"""The session's offset: the duration-weighted mean compensated rate of the static runs and
its standard error (`hrgjax.calibration.session`'s module docstring defines it)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np


@dataclasses.dataclass(frozen=True)
class Offset:
    """A session's constant rate (module docstring): `value_dph` [°/h], `sigma_dph` (its 1σ
    standard error [°/h]; NaN with one static run), `n_runs` (static runs used; 0: not
    estimated, nothing removed), `source` (label of the compensator it was measured with).
    (value − truth)/σ is Student-t with `dof` = `n_runs` − 1 degrees of freedom: read
    intervals with [`half_width`][hrgjax.calibration.Offset.half_width], not ±1.96σ."""

    value_dph: float
    sigma_dph: float
    n_runs: int
    source: str = ""

    @property
    def estimated(self) -> bool:
        """Whether the session had static runs to measure it."""
        return self.n_runs > 0

    @property
    def dof(self) -> int:
        """Degrees of freedom of σ: `n_runs` − 1 (0: σ unknown)."""
        return max(self.n_runs - 1, 0)

    def half_width(self, level: float = 0.95) -> float:
        """Half-width [°/h] of the two-sided `level` interval: Student's t quantile with
        `dof` degrees of freedom times σ (12.7σ at 95 % with 2 runs, 2.23σ with 11, 2.00σ
        with 57); NaN when σ is unknown."""
        number = isinstance(level, int | float | np.integer | np.floating) and not isinstance(
            level, bool | np.bool_)  # fmt: skip
        if not (number and 0.0 < level < 1.0):
            raise ValueError(f"level must be in (0, 1); got {level!r}")
        if self.dof < 1 or not math.isfinite(self.sigma_dph):
            return math.nan
        from scipy import stats

        return float(stats.t.ppf(0.5 + 0.5 * level, self.dof)) * self.sigma_dph

    def to_json(self) -> dict:
        """`{"value", "sigma", "unit", "n_static_runs", "from", "dof", "half_width_95"}` (σ
        and the 95 % t half-width `null` when unknown)."""
        sigma = self.sigma_dph if math.isfinite(self.sigma_dph) else None
        half = self.half_width(0.95)
        return {
            "value": float(self.value_dph),
            "sigma": None if sigma is None else float(sigma),
            "unit": "°/h",
            "n_static_runs": int(self.n_runs),
            "from": self.source,
            "dof": int(self.dof),
            "half_width_95": float(half) if math.isfinite(half) else None,
        }

    def __str__(self) -> str:
        if not self.estimated:
            return "not estimated (no static runs): the angle errors include it"
        if not math.isfinite(self.sigma_dph):
            return f"{self.value_dph:+.4f} °/h (σ unknown: one static run)"
        runs = "run" if self.n_runs == 1 else "runs"
        return (
            f"{self.value_dph:+.4f} ± {self.sigma_dph:.4f} °/h (1σ, {self.n_runs} static {runs}; "
            f"95 %: ± {self.half_width(0.95):.4f}, t with {self.dof} dof)"
        )


def session_offset(errors: dict, source: str = "") -> Offset:
    """The session's offset from per-run errors taken with no offset removed.

    **Arguments:**

    - `errors`: [`run_errors`][hrgjax.calibration.run_errors] or
      [`corrected_run_errors`][hrgjax.calibration.corrected_run_errors] output
      (`offset_dph=0`).
    - `source`: label of the compensator, kept in the result.

    **Returns:** an [`Offset`][hrgjax.calibration.Offset]: the duration-weighted mean of the
    static runs' mean compensated rates [°/h] and its standard error from their scatter
    (module docstring); value 0 and `n_runs` 0 when there are no static runs.
    """
    missing = [k for k in ("static", "drift_error_dph", "duration_s") if k not in errors]
    if missing:
        raise ValueError(f"session_offset: errors must be run_errors' output (a dict with "
                         f"'static', 'drift_error_dph', 'duration_s'); it lacks {missing}")  # fmt: skip
    static = np.asarray(errors["static"], dtype=bool)
    lengths = {k: np.shape(errors[k]) for k in ("static", "drift_error_dph", "duration_s")}
    if len(set(lengths.values())) != 1 or len(lengths["static"]) != 1:
        raise ValueError(f"session_offset: errors' 'static', 'drift_error_dph' and 'duration_s' "
                         f"must be 1-D, one value per run; got shapes {list(lengths.values())}")  # fmt: skip
    rate = np.asarray(errors["drift_error_dph"], dtype=float)[static]
    weight = np.asarray(errors["duration_s"], dtype=float)[static]
    # a NaN drift (a run too short to give a rate) stays NaN, as the offset it makes
    if np.any(np.isinf(rate)) or not (np.all(np.isfinite(weight)) and np.all(weight > 0)):
        raise ValueError("session_offset: every static run needs a drift_error_dph that is not "
                         "infinite and a finite duration_s > 0 [s]")  # fmt: skip
    n = int(rate.size)
    if n == 0:
        return Offset(0.0, math.nan, 0, source)
    total = float(np.sum(weight))
    value = float(np.sum(weight * rate) / total)
    if n == 1:
        return Offset(value, math.nan, 1, source)
    s2 = float(np.sum(weight * (rate - value) ** 2)) / (n - 1)  # a run's variance: s²/T_i
    return Offset(value, math.sqrt(s2 / total), n, source)
