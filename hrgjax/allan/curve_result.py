"""[`AllanResult`][hrgjax.allan.AllanResult]: a deviation curve with its statistics, as
[`deviation`][hrgjax.allan.deviation] returns it (its own module so that the fits that
take one, `hrgjax.allan.noise_terms`, need not import `deviation`'s)."""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class AllanResult:
    """A deviation curve with its uncertainty (NumPy arrays, one entry per τ).

    - `kind`: the deviation (one of [`KINDS`][hrgjax.allan.KINDS]); `ci`: the confidence level.
    - `taus` [s]; `m`: averaging factors (τ = m/rate_hz).
    - `dev`: the deviation [rate unit; tdev: rate unit × s, an angle];
      `dev_low`, `dev_high`: the χ² interval at level `ci` (NIST SP 1065 eq. 45).
    - `edf`: equivalent degrees of freedom (Greenhall–Riley, for the type read; oadev under
      the default rule where `mixture` is True: the exact EDF under the record's fitted IEEE
      952 mixture, [`mixture_oadev_edf`][hrgjax.allan.mixture.mixture_oadev_edf]; totdev: SP 1065 Table 7,
      [`edf_totdev`][hrgjax.allan.edf_totdev]; mtotdev, ttotdev:
      [`edf_mtotdev`][hrgjax.allan.total.edf_mtotdev] (fitted to the exact EDF; Table 8
      under `noise_rule="stable32"`); with gaps: the gap-free segments'
      pooled EDF). totdev where a rate noise is read by B1 on ≤ 8 averages (τ ≥ T/8, default
      rule, `bias_correction=True`): the smallest EDF of the rate noises within one step of
      the α read (`SPAN_REACH`), and `dev_low`, `dev_high` span their intervals, each with
      its own bias correction (B1 cannot tell neighbouring types apart there). There
      `confidence_interval(dev, edf, ci)` does not give back (`dev_low`, `dev_high`): for
      another confidence level pass `ci` to `deviation`, which forms the span at that level.
    - `n_terms`: the number of differences each estimate averages.
    - `alpha`: the power-law noise identified at each τ, the exponent α of the rate PSD
      S_y(f) ∝ f^α: 2 white angle (phase) noise, 1 flicker angle, 0 white rate (angle random
      walk), −1 flicker rate (bias instability), −2 rate random walk (lag-1 autocorrelation,
      Riley & Greenhall 2004; the B1 and R(n) ratios where the record is short at that τ:
      [`noise_id`][hrgjax.allan.noise_id]).
    - `bias_factor`: what `dev` was multiplied by to remove the estimator's bias (totdev:
      1/√[`totvar_bias`][hrgjax.allan.totvar_bias], 1/√(1 − a·τ/T) for flicker and
      random-walk rate noise (NIST SP 1065 §5.2.11), computed for white and flicker angle
      noise (1 there under `noise_rule="stable32"`, as Stable32); mtotdev, ttotdev: 1/√b(α, m),
      [`mtotvar_bias`][hrgjax.allan.total.mtotvar_bias] (Stable32's b(α) under its rule),
      where `mixture` is True 1/√b_mix, the bias of the record's fitted noise mixture
      ([`mixture_bias`][hrgjax.allan.mixture.mixture_bias]); 1 elsewhere and where the
      correction was off).
    - `mixture`: per τ, True where the bias divisor (mtotdev, ttotdev) or the EDF (oadev)
      comes from the IEEE 952 mixture fitted to the record's octave Allan variance
      ([`hrgjax.allan.mixture`][hrgjax.allan.mixture]) rather than from the one type in
      `alpha`; False where it was not used (other kinds, `noise_rule="stable32"`, gaps, no
      bias correction, more than 64 τ for oadev) or the fit was refused (too few octaves, a
      misfit: a noise outside the four terms, such as a strong Gauss–Markov bump), where the
      values are the type read's as before. `alpha` is the type read either way.
    - `unit`: the samples' unit as given to [`deviation`][hrgjax.allan.deviation] (a rate
      unit for `data="rate"`, an angle unit for `data="phase"`); `data`: which of the two.
      The deviation's own unit is `dev_unit`: the rate unit (`rate_unit`: an angle unit
      per second for angle samples, °/s for °) and for tdev and ttotdev that times a
      second, an angle (°/h·s for rates in °/h, ° for angles in °); the table, the CSV
      header, the JSON `units` and [`allan_figure`][hrgjax.plots.allan_figure] name it.
    - `segments`: for a rate record with gaps, the (start, length) of each gap-free run of
      samples [samples], an (R, 2) integer array
      ([`fit_noise`][hrgjax.allan.fit_noise] builds the estimates' covariance from it);
      `None` for a gap-free record or angle data.

    `print(result)` shows it as a table; `to_dict`, `to_json(path)` and `to_csv(path)` write
    it with its units.
    """

    kind: str
    ci: float
    taus: np.ndarray
    m: np.ndarray
    dev: np.ndarray
    dev_low: np.ndarray
    dev_high: np.ndarray
    edf: np.ndarray
    n_terms: np.ndarray
    alpha: np.ndarray
    bias_factor: np.ndarray | None = None
    unit: str = ""
    segments: np.ndarray | None = None
    mixture: np.ndarray | None = None
    data: str = "rate"

    @property
    def rate_unit(self) -> str:
        """The rate unit the deviation is taken in: `unit` for rate samples, `unit`/s for
        angle samples ("" where no unit was given)."""
        return self.unit if self.data == "rate" else per_second(self.unit)

    @property
    def dev_unit(self) -> str:
        """The unit of `dev`, `dev_low` and `dev_high`:
        `hrgjax.allan.curve_result.deviation_unit` of the kind."""
        return deviation_unit(self.kind, self.rate_unit)

    def _columns(self) -> dict:
        return {
            "tau_s": self.taus, "m": self.m, "dev": self.dev, "dev_low": self.dev_low,
            "dev_high": self.dev_high, "edf": self.edf, "n_terms": self.n_terms,
            "alpha": self.alpha,
        }  # fmt: skip

    def __str__(self) -> str:
        unit = f" [{self.dev_unit}]" if self.dev_unit else ""
        head = f"{self.kind}{unit}, ±{self.ci:.3f} χ² interval"
        cols = (
            f"{'tau [s]':>12} {'m':>8} {'dev':>12} {'low':>12} {'high':>12} {'edf':>9} {'alpha':>6}"
        )
        mixed = np.zeros(len(self.taus), bool) if self.mixture is None else self.mixture
        rows = [
            f"{t:12.5g} {int(m):8d} {d:12.5g} {lo:12.5g} {hi:12.5g} {e:9.4g}"
            f"{'*' if x else ' '}{int(a):+6d}"
            for t, m, d, lo, hi, e, a, x in zip(self.taus, self.m, self.dev, self.dev_low,
                                                self.dev_high, self.edf, self.alpha, mixed,
                                                strict=True)
        ]  # fmt: skip
        if np.any(mixed):
            what = "edf" if self.kind == "oadev" else "bias divisor"
            rows.append(f"* {what} from the record's fitted IEEE 952 noise mixture")
        return "\n".join([head, cols, *rows])

    def to_dict(self) -> dict:
        """The curve as plain lists, with its kind, level, `unit` (the samples'), `data`
        (rate or phase) and column `units` (`dev`'s: `dev_unit`)."""
        dev = self.dev_unit
        out = {"kind": self.kind, "ci": self.ci, "unit": self.unit, "data": self.data,
               "units": {"tau_s": "s", "dev": dev, "dev_low": dev, "dev_high": dev,
                         "alpha": "S_y ∝ f^alpha"}}  # fmt: skip
        cols = self._columns()
        if self.bias_factor is not None:
            cols["bias_factor"] = self.bias_factor
        if self.mixture is not None:
            cols["mixture"] = self.mixture
        return out | {k: np.asarray(v).tolist() for k, v in cols.items()}

    def to_json(self, path) -> None:
        """Write [`to_dict`][hrgjax.allan.AllanResult.to_dict] to `path` (JSON), atomically
        (missing folders are made)."""
        import json

        from .._io import atomic_write

        with atomic_write(path, "w", encoding="utf-8") as fh:
            json.dump(self.to_dict(), fh, indent=1)

    def to_csv(self, path) -> None:
        """Write one row per τ to `path` (CSV: `tau_s, m, dev, dev_low, dev_high, edf,
        n_terms, alpha` and, where the result has it, `mixture` (1/0), the deviation's unit
        `dev_unit` in the header's `dev` column names), atomically (missing folders are made). The printed
        table marks the rows whose `mixture` is True with `*` after the EDF."""
        from .._io import atomic_write

        cols = self._columns()
        if self.mixture is not None:  # 1 where the interval or divisor rests on the mixture
            cols["mixture"] = np.asarray(self.mixture, dtype=int)
        unit = f" [{self.dev_unit}]" if self.dev_unit else ""
        names = [f"{k}{unit}" if k.startswith("dev") else k for k in cols]
        with atomic_write(path, "w", encoding="utf-8") as fh:
            fh.write(",".join(names) + "\n")
            for row in zip(*cols.values(), strict=True):
                fh.write(",".join(repr(float(v)) if isinstance(v, float | np.floating)
                                  else str(int(v)) for v in row) + "\n")  # fmt: skip


ALLAN_VARIANCE_KINDS = ("adev", "oadev", "totdev")
"""The kinds whose value estimates the Allan deviation σ(τ) itself (totdev: with its bias
correction), on which a noise model's Allan deviation
([`NoiseFit.adev`][hrgjax.allan.NoiseFit], [`CompositeNoise.adev`][hrgjax.allan.CompositeNoise])
may be drawn; mdev, tdev, the Hadamard and the modified total kinds estimate other
variances (tdev is an angle, τ·mdev/√3)."""


def per_second(unit: str) -> str:
    """`unit` per second ("°" → "°/s", "m/s" → "m/s²"; "" stays "")."""
    if not unit:
        return ""
    if unit.endswith("/s"):
        return unit + "²"
    return f"({unit})/s" if "/" in unit else unit + "/s"


def times_second(unit: str) -> str:
    """`unit` times a second ("°/s" → "°", "m/s²" → "m/s", "°/h" → "°/h·s"; "" stays "")."""
    if not unit:
        return ""
    for tail, short in (("/s", ""), ("/s²", "/s"), ("/s^2", "/s")):
        if unit.endswith(tail) and len(unit) > len(tail):
            return unit[: -len(tail)] + short
    return unit + "·s"


def deviation_unit(kind: str, rate_unit: str) -> str:
    """The unit of a `kind` deviation of rates in `rate_unit`: the rate unit, and for tdev and
    ttotdev (τ·mdev/√3, τ·mtotdev/√3: an angle) the rate unit times a second."""
    return times_second(rate_unit) if kind in ("tdev", "ttotdev") else rate_unit
