r"""A composite noise model identified from a record by its Allan variance at octave scales
with that estimator's own covariance: a generalised method of wavelet moments (GMWM;
Guerrier et al. 2013 — the overlapping Allan variance at τ = 2ʲτ₀ is twice the Haar wavelet
variance).

The terms — `quantization` Q, `angle_random_walk` N, `rate_random_walk` K, `rate_ramp` R and
up to two first-order `gauss_markov` terms (σ, T) — and their Allan variances for sampled data
are in [`octave_covariance`][hrgjax.allan.octave_covariance], with the
estimator's exact covariance of the octaves (finite record, overlapping estimates,
neighbouring octaves correlated): [`covariance`][hrgjax.allan.octave_covariance.covariance].

**Fit and selection.** Generalised least squares on the octaves with that covariance
(evaluated at the previous fit, three rounds), the coefficients² non-negative, each
Gauss–Markov correlation time profiled on a grid refined by a parabola in log T. Every
subset of the candidate terms with fewer parameters than octaves is fitted with one shared
covariance (the fullest model's) and ranked by J + penalty (J the χ²-distributed misfit;
[`PENALTY`][hrgjax.allan.composite.PENALTY] per linear term,
[`GM_PENALTY`][hrgjax.allan.composite.GM_PENALTY] per Gauss–Markov term, whose T is searched
and undefined when σ = 0). The best [`FINALISTS`][hrgjax.allan.composite.FINALISTS] are
refitted on log σ̂² with their own relative covariance D⁻¹ΩD⁻¹ (D the model; Newton on the
weighted squares, the covariance re-evaluated at the fit three times; one its covariance rejects is fitted
again from a start under the per-τ EDF weights), and of those their own covariance does not
reject (p ≥ [`FIT_ALPHA`][hrgjax.allan.composite.FIT_ALPHA]) the least J + log det + penalty
(the octaves' Gaussian likelihood) is kept: a term the data do not need is not reported. Its
intervals are (GᵀΩ⁻¹G)⁻¹ on log c² and log T; for each candidate term not selected, the
upper end of its interval with it forced in is kept as a bound.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from statistics import NormalDist

import numpy as np

from .._checks import check_1d, check_number, check_numbers, describe, is_concrete, is_finite_real
from .._io import atomic_write
from .._progress import bar
from ..imu.data import ACCEL_UNITS, GYRO_UNITS
from .kalibr import ABSENT_SHARE, entries_ratio, fold_gauss_markov, negligible
from .octave_covariance import SAMPLINGS, unit_avar
from .octave_covariance import covariance as covariance
from .octave_covariance import gm_white_level as gm_white_level
from .octave_fits import (
    best_fit,
    log_fit,
    model_avar,
    model_covariance,
    octave_rows,
    upper_bounds,
)
from .uncertainty import chi2_sf

LINEAR = ("quantization", "angle_random_walk", "rate_random_walk", "rate_ramp")
"""The terms linear in their coefficient² (the Gauss–Markov terms add a correlation time)."""
SYMBOLS = {"quantization": "Q", "angle_random_walk": "N", "rate_random_walk": "K",
           "rate_ramp": "R"}  # fmt: skip
UNIT_OF = {"quantization": "{u}·s", "angle_random_walk": "{u}·√s",
           "rate_random_walk": "{u}/√s", "rate_ramp": "{u}/s"}  # fmt: skip
PENALTY = 4.0
"""The misfit a linear term must remove to be kept. Under a term's absence its J drop is
½χ²₀ + ½χ²₁ (a non-negative coefficient), exceeded with probability 2.3 %."""
SCALE_LIMIT = 8
"""The octaves fitted: m ≤ n/SCALE_LIMIT (each estimate from ≥ 8 τ-averages' worth of
record): the last octaves of the printed curve (T/8 … T/2) are not fitted, so a term that
shows only there (a rate random walk crossing the white noise past T/8) is left out and
reported by its upper bound (`CompositeNoise.bounds`). With 4, the reduced studies of
`benchmarks/noise_identification.py` came out the same (docs/allan.md); 8 is kept until
the full studies are rerun."""
GM_PENALTY = 12.0
"""The misfit a Gauss–Markov term must remove: its correlation time is searched (and
undefined when σ = 0), so its drop under absence is the largest of many (Davies 1987); 12
keeps false detections in white + random-walk records near 5 %
(`benchmarks/noise_identification.py`)."""
FINALISTS = 6
"""The best subsets under the fullest model's covariance that are refitted with their own."""
FIT_ALPHA = 1e-3
"""A finalist whose misfit under its own covariance has p < FIT_ALPHA is kept only when no
other finalist fits."""
HOPELESS = 1e-12
"""A finalist's refit stops after the round whose misfit has p < HOPELESS (10⁹ below
`FIT_ALPHA`: the covariance's updates in the rounds after it move J by a few per cent, not
from ≈ 80 to the ≈ 30 that would fit); its J and covariance are then taken there. Where no
finalist fits, all are refitted to the end and the least bad is kept."""
T_GRID = 24
"""Correlation times tried per Gauss–Markov term: log-spaced from 2τ₀ to the longest octave
fitted (n/SCALE_LIMIT·τ₀; a longer T looks like a random walk there)."""
# -- the fit -------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class CompositeNoise:
    """A composite noise model identified from a record
    ([`identify_noise`][hrgjax.allan.identify_noise]).

    - `terms`: `{name: {"value", "low", "high", "unit"}}` for the terms the data need
      (quantization Q, angle_random_walk N, rate_random_walk K, rate_ramp R;
      `gauss_markov_1`, `gauss_markov_2`: `{"sigma": {...}, "correlation_time": {...}}`),
      intervals at level `ci`. A term the data do not need is absent.
    - `unit`: the rate unit of the record; `rate_hz`: its sample rate [Hz]; `n`: samples.
    - `taus` [s], `avar` [unit²]: the octaves fitted; `covariance` [unit⁴]: the estimator's
      covariance at the fit; `chi2`, `dof`, `p_value`: the misfit J, its degrees of
      freedom and P(χ²_dof > J) — a small p says the model leaves structure.
    - `selection`: each candidate subset tried: `terms`, `gauss_markov`, `J` and `score`
      (J + penalty) under the fullest model's covariance, and for the finalists
      `likelihood_score` (J + log det Ω + penalty under their own).
    - `bounds`: `{name: upper end [coefficient unit]}` of each candidate term not selected,
      from a fit with it forced in: the largest value the octaves do not reject at `ci`
      (one-sided (1 − ci)/2), each value tested under the octaves' covariance with the term
      at that value; inf where none is rejected. The octaves end at T/8 (`SCALE_LIMIT`):
      a term that rises above the others only past T/8 is left out and only bounded here
      (ARW + a rate random walk crossing at ≈ 210 s, 2 000 s at 100 Hz: K ≤ 0.112 against
      0.05, docs/allan.md).
    - `sampling`: what a rate sample was taken as (`"interval"`: the mean over its interval,
      `"point"`: an instantaneous sample; [`SAMPLINGS`][hrgjax.allan.octave_covariance.SAMPLINGS]).
    """

    terms: dict
    unit: str
    rate_hz: float
    n: int
    ci: float
    taus: np.ndarray
    avar: np.ndarray
    covariance: np.ndarray
    chi2: float
    dof: int
    p_value: float
    selection: tuple = ()
    bounds: dict = dataclasses.field(default_factory=dict)
    sampling: str = "interval"

    def model_avar(self, taus) -> np.ndarray:
        """The model's Allan variance at `taus` [s] (rounded to whole samples). [unit²]"""
        tau0, t = 1.0 / self.rate_hz, check_numbers("taus", taus, "τ values > 0 [s]")
        if not np.all(np.isfinite(t) & (np.asarray(t, dtype=float) > 0)):  # τ ≤ 0 read as τ₀
            raise ValueError(f"taus must be τ values > 0 [s] (finite); got {describe(taus)}")
        m = np.maximum(np.round(np.asarray(taus, dtype=float) / tau0), 1.0)
        out = np.zeros_like(m)
        for name, spec in self.terms.items():
            if name in LINEAR:
                out = out + spec["value"] ** 2 * unit_avar(name, m, tau0, sampling=self.sampling)
            else:
                s, t = spec["sigma"]["value"], spec["correlation_time"]["value"]
                out = out + s**2 * unit_avar("gauss_markov", m, tau0, tau0 / t, self.sampling)
        return out

    def term_avar(self, name, taus) -> np.ndarray:
        """One term's Allan variance at `taus` [s]. [unit²]"""
        if name not in self.terms:  # was a KeyError
            raise ValueError(f"term_avar: name must be one of the model's terms "
                             f"{list(self.terms)}; got {describe(name)}")  # fmt: skip
        one = dataclasses.replace(self, terms={name: self.terms[name]})
        return one.model_avar(taus)

    def adev(self, taus) -> np.ndarray:
        """The model's Allan deviation at `taus` [s]. [unit]"""
        return np.sqrt(self.model_avar(taus))

    def value(self, name: str) -> float:
        """A coefficient's value (0 where the term is absent); Gauss–Markov terms: σ."""
        spec = self.terms.get(name)
        if spec is None:
            return 0.0
        return spec["value"] if "value" in spec else spec["sigma"]["value"]

    def __str__(self) -> str:
        lines = [f"composite noise model [{self.unit or 'rate unit'}], {self.n} samples at "
                 f"{self.rate_hz:g} Hz, {100 * self.ci:.0f} % intervals; J = {self.chi2:.1f} "
                 f"on {self.dof} dof (p = {self.p_value:.2g})"]  # fmt: skip
        for name, spec in self.terms.items():
            parts = [("", spec)] if "value" in spec else list(spec.items())
            for sub, s in parts:
                label = f"{name}{'.' + sub if sub else ''}"
                lines.append(f"  {label:<34} {s['value']:.4g} [{s['low']:.4g}, {s['high']:.4g}]"
                             f" {s['unit']}")  # fmt: skip
        if not self.terms:
            lines.append("  (no term: the record is below every candidate's detection)")
        if self.p_value < 1e-3:
            lines.append("  the model leaves structure (p < 0.001): the record has noise the "
                         "candidates cannot describe, and these intervals assume they can")  # fmt: skip
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {
            "format": "hrgjax.noise_model", "unit": self.unit, "rate_hz": self.rate_hz,
            "n_samples": self.n, "ci": self.ci, "terms": self.terms, "chi2": self.chi2,
            "dof": self.dof, "p_value": self.p_value, "bounds": self.bounds,
            "sampling": self.sampling, "taus_s": self.taus.tolist(),
            "avar": self.avar.tolist(),
        }  # fmt: skip

    def to_json(self, path) -> None:
        """Write the model (terms with units and intervals, the octaves fitted) as JSON,
        atomically (missing folders are made)."""
        with atomic_write(path, "w", encoding="utf-8") as fh:
            json.dump(self.to_dict(), fh, indent=1, ensure_ascii=False)

    def to_kalibr(self, path=None, sensor: str = "gyroscope", rostopic: str = "/imu0") -> dict:
        """Kalibr's IMU noise parameters (`imu.yaml`) in SI continuous-time units (gyroscope:
        rad/s/√Hz and rad/s²/√Hz; accelerometer: m/s²/√Hz and m/s³/√Hz), with `update_rate`
        [Hz]. Kalibr models white noise and a random walk only, so the other terms are folded
        in, each marked so in the file:

        - `{sensor}_noise_density` = √(N² + 2Q²/Δt + white parts), Δt = 1/`rate_hz`:
          Kalibr's per-sample σ_c/√Δt then equals the record's, N²/Δt + 2Q²/Δt² (white angle
          noise Q differenced into rates). This holds at this record's update rate only:
          resampled to another Δt the white angle noise scales as 1/Δt, not 1/√Δt, and its
          samples' negative correlation (an MA(1)) is lost.
        - `{sensor}_random_walk` = √(K² + walk parts).
        - Each Gauss–Markov term (σᵢ, Tᵢ) goes whole into the white part (its long-τ level
          [`gm_white_level`][hrgjax.allan.composite.gm_white_level], 2σᵢ²Tᵢ for interval
          means) or the walk part (2σᵢ²/Tᵢ, its short-τ walk), whichever overstates its exact
          Allan variance less at the worst of the model's octaves `taus` (τ₀ … τ_max, the
          record's τ range): [`hrgjax.allan.kalibr`][hrgjax.allan.kalibr]. Both bound it
          from above, so the export does not understate it at any octave; a T of a few
          samples goes white, a T beyond √(τ₀τ_max) or so a walk. (Until 2026-11-30 every
          T > 4Δt went into the walk: the PSINS laser-gyro log's 0.08-s vibration term gave
          K 268 °/h/√s, 1 190× the model's Allan deviation at τ = 164 s; now white: the term
          14.4× at most, at τ₀, the whole export 6.3×.)

        The file's first comment states the worst: the ratio of the entries' Allan deviation
        to the model's over its octaves ([`entries_ratio`][hrgjax.allan.kalibr.entries_ratio]).
        A term the record did not need counts 0, except that where an entry would be 0 (N and
        Q, or K and every part, absent) N's or K's upper bound (`bounds`) is written (Kalibr
        refuses a 0); a bound of 0 (the octaves reject even 0) is written as
        [`negligible`][hrgjax.allan.kalibr.negligible]; with no finite bound, `ValueError`. The
        record's `unit` must be one Kalibr's units follow from
        ([`TO_SI`][hrgjax.allan.composite.TO_SI]). Kalibr reads both sensors' entries from
        one file: write each sensor's model and merge them. Written to `path` when given,
        atomically (missing folders are made). **Returns:** the entries."""
        if sensor not in ("gyroscope", "accelerometer"):
            raise ValueError(f"sensor must be 'gyroscope' or 'accelerometer'; got {sensor!r}")
        scale = _si_scale(self.unit, sensor)
        dt = 1.0 / self.rate_hz
        q = self.value("quantization")
        folds = [(g["sigma"]["value"], g["correlation_time"]["value"])
                 for name, g in self.terms.items() if name.startswith("gauss_markov")]  # fmt: skip
        folds = [(s, t, fold_gauss_markov(s, t, self.taus, dt, self.sampling)) for s, t in folds]
        extra = {"noise_density": 2.0 * q * q / dt + sum(f["white"] for *_, f in folds),
                 "random_walk": sum(f["walk"] for *_, f in folds)}  # fmt: skip
        values, notes, coef = {}, {}, {}
        for key, name in (
            ("noise_density", "angle_random_walk"),
            ("random_walk", "rate_random_walk"),
        ):
            v = self.value(name)
            if v <= 0 and extra[key] <= 0:
                v = self.bounds.get(name, math.inf)
                notes[key] = " (not detected: the record's upper bound)"
                if v == 0:
                    v = negligible(self, name)
                    notes[key] = (" (not detected, upper bound 0: written at <= "
                                  f"{100 * ABSENT_SHARE:g} % of the model's Allan variance)")  # fmt: skip
                if not 0 < v < math.inf:
                    raise ValueError(f"to_kalibr: {name} was not identified and has no finite "
                                     "bound; Kalibr needs a positive value")  # fmt: skip
            coef[key] = math.sqrt(v * v + extra[key])
            values[key] = coef[key] * scale
        folded = []
        if q > 0:
            folded.append(f"2Q^2/dt, Q = {q:.4g} {self.unit}*s white angle noise (valid at "
                          "this update_rate only)")  # fmt: skip
        gm = {form: ", ".join(f"(sigma {s:.4g}, T {t:.4g} s: worst {f['worst']:.3g}x at {f['at']:g} s)"
                              for s, t, f in folds if f["form"] == form)
              for form in ("white", "walk")}  # fmt: skip
        if gm["white"]:
            level = "2 sigma^2 T" if self.sampling == "interval" else "sigma^2 dt coth(dt/2T)"
            folded.append(f"{level}, Gauss-Markov rate(s) {gm['white']}")
        if folded:
            notes["noise_density"] = f" sqrt(N^2 + ...): {'; '.join(folded)} folded in as white"
        if gm["walk"]:
            notes["random_walk"] = (f" sqrt(K^2 + ...): 2 sigma^2/T, Gauss-Markov rate(s) "
                                    f"{gm['walk']} folded in as a walk")  # fmt: skip
        low, high, at = entries_ratio(self, coef["noise_density"], coef["random_walk"])
        out = {
            f"{sensor}_noise_density": values["noise_density"],
            f"{sensor}_random_walk": values["random_walk"],
            "rostopic": rostopic,
            "update_rate": float(self.rate_hz),
        }
        if path is not None:
            units = {"gyroscope": ("rad/s/sqrt(Hz)", "rad/s^2/sqrt(Hz)"),
                     "accelerometer": ("m/s^2/sqrt(Hz)", "m/s^3/sqrt(Hz)")}[sensor]  # fmt: skip
            with atomic_write(path, "w", encoding="utf-8") as fh:
                fh.write(f"# from hrgjax.allan.identify_noise: {self.n} samples at "
                         f"{self.rate_hz:g} Hz, unit {self.unit}\n# Allan deviation of these "
                         f"entries / the model's over its octaves {self.taus[0]:g}-"
                         f"{self.taus[-1]:g} s: {low:.3g}-{high:.3g} (highest at {at:g} s)\n")  # fmt: skip
                fh.write(f"{sensor}_noise_density: {out[f'{sensor}_noise_density']:.6g}"
                         f"  # [{units[0]}]{notes.get('noise_density', '')}\n")  # fmt: skip
                fh.write(f"{sensor}_random_walk: {out[f'{sensor}_random_walk']:.6g}"
                         f"  # [{units[1]}]{notes.get('random_walk', '')}\n")  # fmt: skip
                fh.write(f"rostopic: {rostopic}\nupdate_rate: {float(self.rate_hz)!r}\n")
        return out

    def to_noise(self, k_e: float | None = None):
        """hrgjax's [`Noise`][hrgjax.Noise] for simulating a gyro with this noise (rate unit
        rad/s, °/s or °/h): N → `angle_random_walk`, one Gauss–Markov term → `bias_instability`
        and `correlation_time`, Q → `angle_white` (× `k_e`, the gyro's angular gain: readout
        noise on the electrical wave angle, per sample at this record's rate). `k_e` is
        needed only when the model has Q (else `ValueError` asking for it). A rate random
        walk, a drift or a second Gauss–Markov term has no field in `Noise`: `ValueError`
        naming it. The simulator integrates the Gauss–Markov rate exactly over each interval
        (`hrgjax.noise.gauss_markov_bridge`): its rate samples are interval means, this
        module's default `sampling`, so identify → `to_noise` → simulate → identify returns
        σ and T. (σ and T are the continuous rate's under either `sampling`: a `"point"`
        model's terms are simulated here as that rate's interval means.)"""
        from ..noise import Noise

        scale = _si_scale(self.unit, "gyroscope")
        extra = [n for n in self.terms if n in ("rate_random_walk", "rate_ramp", "gauss_markov_2")]
        if extra:
            raise ValueError(
                f"to_noise: {', '.join(extra)} has no field in hrgjax.Noise (it simulates "
                "white angle and rate noise and one Gauss–Markov rate)"
            )
        q = self.value("quantization")
        if q and k_e is None:
            raise ValueError(
                "to_noise: the model has white angle noise Q; pass k_e, the gyro's angular "
                "gain (Q × k_e is the readout noise on the electrical wave angle)"
            )
        if k_e is not None:  # a traced k_e (a gradient through it) passes: checked when concrete
            check_number("to_noise: k_e", k_e)
            if is_concrete(k_e) and not (is_finite_real(k_e) and k_e > 0):
                raise ValueError(f"to_noise: k_e must be a positive number; got {describe(k_e)}")
        gm = self.terms.get("gauss_markov_1")
        return Noise(
            angle_white=(k_e * q if q else 0.0) * scale,
            angle_random_walk=self.value("angle_random_walk") * scale,
            bias_instability=0.0 if gm is None else gm["sigma"]["value"] * scale,
            correlation_time=100.0 if gm is None else gm["correlation_time"]["value"],
        )


TO_SI = {
    **{u: ("gyroscope", f) for u, f in GYRO_UNITS.items()},
    **{u: ("accelerometer", f) for u, f in ACCEL_UNITS.items()},
}
"""Rate units Kalibr's and `Noise`'s SI units follow from: unit → (sensor, factor to SI) —
`hrgjax.imu`'s gyro and accelerometer units."""


def _si_scale(unit, sensor):
    if unit not in TO_SI:
        raise ValueError(f"unit {unit!r} has no SI factor; give the record's unit as one of "
                         f"{sorted(TO_SI)}")  # fmt: skip
    kind, factor = TO_SI[unit]
    if kind != sensor:
        raise ValueError(f"unit {unit!r} is a unit of the {kind}, not of the {sensor}")
    return factor


def identify_noise(
    y,
    rate_hz: float,
    *,
    unit: str = "",
    terms=("quantization", "angle_random_walk", "rate_random_walk"),
    gauss_markov: int = 2,
    ci: float = 0.95,
    sampling: str = "interval",
    oadev=None,
) -> CompositeNoise:
    """Identify a composite noise model in rate samples `y` [unit] taken at `rate_hz` [Hz]
    (module docstring): the terms the record needs among `terms` (names of
    [`LINEAR`][hrgjax.allan.composite.LINEAR]) and up to `gauss_markov` (0–2) first-order
    Gauss–Markov terms, each with an interval at level `ci`.

    `rate_ramp` is not a default candidate: over one record a rate random walk's wander and a
    drift give the same rise at the longest octaves, and offered both, white + random-walk
    records took a drift in 25 % (`benchmarks/noise_identification.py`). Remove a known drift
    first (Stable32 does), or ask for it where the sensor has one.

    `sampling`: what a sample of `y` is — `"interval"` (default) the mean rate over its
    interval, Δθ/Δt of an angle output (a rate-integrating gyro such as an HRG, hrgjax's
    simulator, an IMU's integrated increments); `"point"` an instantaneous sample of the
    rate (a sampled-rate sensor). The Gauss–Markov and rate-random-walk terms' Allan
    variances and covariance differ between the two
    ([`octave_covariance`][hrgjax.allan.octave_covariance]). Under the wrong one: an
    interval-mean Gauss–Markov record fitted as point samples is biased in T and σ and
    rejected when long (T = 10 s read 13.0 s, J 18 751 on 15 dof); a point-sampled one
    fitted as interval means is accepted with its white noise N inflated — N² gains
    σ²τ₀²/(3T) (N 0.05 read 0.188 at σ = 1, T = 10 s, 1 Hz) — so say which the sensor is.

    The octaves fitted end at n/`SCALE_LIMIT` samples (T/8): a term that shows only beyond
    them is not selected and is reported by its upper bound in `bounds`; for such a term
    take a longer record or read [`fit_noise`][hrgjax.allan.fit_noise] on the whole curve.

    `oadev`: the record's overlapping Allan deviation where the caller has it already
    ([`deviation`][hrgjax.allan.deviation]`(y, rate_hz)`, octave τ and the default noise rule,
    as the CLI prints it): its octaves up to n/`SCALE_LIMIT` samples are used instead of
    computing them again (at 4·10⁶ samples the deviation is 4–7 s of the 5–8 s).

    **Returns:** a [`CompositeNoise`][hrgjax.allan.CompositeNoise].

    **Raises:** `ValueError` naming the argument for unknown terms, a `gauss_markov` outside
    0–2, a bad rate, level or `sampling`, a record shorter than 64 samples (four octaves),
    or an `oadev` that is not the oadev of `y` at `rate_hz` on a grid holding the octaves."""
    if not (is_finite_real(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be a positive sample rate [Hz]; got {describe(rate_hz)}")
    if isinstance(terms, str) or not hasattr(terms, "__iter__"):  # a str was read letterwise
        raise ValueError(f"terms must be a list of names among {list(LINEAR)}; got "
                         f"{describe(terms)}")  # fmt: skip
    bad = [t for t in terms if t not in LINEAR]
    if bad:
        raise ValueError(f"terms must be among {list(LINEAR)}; got {bad}")
    gm_ok = isinstance(gauss_markov, int | np.integer) and not isinstance(gauss_markov, bool)
    if not gm_ok or gauss_markov not in (0, 1, 2):  # 1.0 failed in range()
        raise ValueError(f"gauss_markov must be 0, 1 or 2 terms; got {describe(gauss_markov)}")
    if not terms and gauss_markov == 0:
        raise ValueError("terms: give at least one candidate (or gauss_markov ≥ 1)")
    if not isinstance(unit, str):
        raise TypeError(f"unit must be the record's rate unit as a str; got {describe(unit)}")
    if not (is_finite_real(ci) and 0.0 < ci < 1.0):
        raise ValueError(f"ci must be a confidence level in (0, 1); got {describe(ci)}")
    if not isinstance(sampling, str) or sampling not in SAMPLINGS:
        raise ValueError(f"sampling must be one of {list(SAMPLINGS)}; got {describe(sampling)}")
    check_numbers("y", y, "real rate samples, 1-D")  # complex: its real part was fitted
    check_1d("y", y, "one rate sample per interval")
    y = np.asarray(y, dtype=float)
    if y.ndim != 1 or y.size < 64:
        raise ValueError(f"y must be 1-D with at least 64 samples; got shape {y.shape}")
    if not np.all(np.isfinite(y)):
        i = int(np.argmin(np.isfinite(y)))
        raise ValueError(f"y has a missing or non-finite value at index {i}; the noise model "
                         "needs a gap-free record: split the record at its gaps")  # fmt: skip
    rate_hz = float(rate_hz)
    octaves = 2 ** np.arange(int(math.log2(y.size // SCALE_LIMIT)) + 1)
    res = None if oadev is None else octave_rows(oadev, y, rate_hz, octaves)
    return _identify(y, rate_hz, unit, terms, gauss_markov, float(ci), sampling, res)


def _identify(y, rate_hz, unit, terms, gauss_markov, ci, sampling, res=None):
    """[`identify_noise`][hrgjax.allan.identify_noise] on checked arguments (`sampling`
    passed to every Allan variance and covariance; `res` the octaves' oadev, when had),
    behind a bar over its steps: the deviation, 4 rounds of the fullest fit, the
    selection, each finalist's own fit, the bounds."""
    steps = (res is None) + 4 + 1 + FINALISTS + 1  # the finalists' count is set once known
    with bar(steps, "noise model", unit="step") as progress:
        return _identify_steps(y, rate_hz, unit, terms, gauss_markov, ci, sampling, res, progress)


def _identify_steps(y, rate_hz, unit, terms, gauss_markov, ci, sampling, res, progress):
    """`_identify`'s work, each step counted on `progress`."""
    from .result import deviation

    n, tau0 = y.size, 1.0 / rate_hz
    ms = 2 ** np.arange(int(math.log2(n // SCALE_LIMIT)) + 1)
    if res is None:
        res = deviation(y, rate_hz, kind="oadev", taus=ms * tau0, unit=unit)
        progress.update(1)
    avar, ms = res.dev**2, res.m
    t_grid = np.geomspace(2 * tau0, ms[-1] * tau0, T_GRID)
    cols = {t: unit_avar(t, ms, tau0, sampling=sampling) for t in terms}
    gm_cols = dict(zip(t_grid, unit_avar("gauss_markov", ms, tau0, tau0 / t_grid, sampling),
                       strict=True))  # fmt: skip

    # round 0: each octave's variance from its EDF (independent; the noise type identified
    # per octave), then the model's own. (A start from white noise's EDF everywhere lands
    # the fullest fit in another optimum more often: the benchmark's coverage fell 86 → 83 %.)
    omega = omega0 = np.diag(2 * avar**2 / np.maximum(res.edf, 1.0))
    full = best_fit(avar, omega, cols, gm_cols, list(terms), gauss_markov, None, tau0, ms,
                    sampling=sampling)  # fmt: skip
    progress.update(1)
    for _ in range(3):
        omega = model_covariance(full, ms, n, tau0, avar, sampling=sampling)
        full = best_fit(avar, omega, cols, gm_cols, list(terms), gauss_markov, None, tau0, ms,
                    sampling=sampling)  # fmt: skip
        progress.update(1)
    # selection: every subset ranked with the fullest model's covariance; the best few then
    # each with its own, by the Gaussian likelihood of the octaves (J + log det) + penalty —
    # a covariance from too large a model hides misfit at long τ, one from too small a model
    # exaggerates it
    tried = _select(avar, omega, cols, gm_cols, terms, gauss_markov, tau0, ms, sampling)
    progress.update(1)

    def fitted_finalists(give_up):
        progress.total = progress.n + len(tried[:FINALISTS]) + 1  # these, then the bounds
        progress.refresh()
        out = []
        for row in tried[:FINALISTS]:
            # each finalist fitted on log σ̂² with its own covariance: J there and the
            # relative covariance's log det score it (in log space the covariance barely
            # moves with the level, so the likelihood cannot trade misfit for a smaller Ω)
            got = _own_fit(row["fit"], avar, ms, n, tau0, sampling, cols, give_up)
            if got is None or got[3] < FIT_ALPHA:
                # rejected by its own covariance: the start may be an optimum the fullest
                # model's covariance made (a wrong fullest fit ranks its own kind first), so
                # it is fitted again from the subset's fit under the per-τ EDF weights; a fit
                # its covariance accepts is kept first, then the better likelihood
                g = row["gauss_markov"]
                start = best_fit(avar, omega0, cols, gm_cols, row["terms"], g, g, tau0, ms,
                                 sampling=sampling)  # fmt: skip
                other = None if start is None else _own_fit(start, avar, ms, n, tau0, sampling,
                                                            cols, give_up)  # fmt: skip
                rank = lambda f: (f[3] >= FIT_ALPHA, -f[2])  # noqa: E731
                if other is not None and (got is None or rank(other) > rank(got)):
                    got = other
            progress.update(1)
            if got is None:  # its covariance degenerate at the fit: not a model
                continue
            fit, om, likelihood, row["p_value"], cov = got
            row["likelihood_score"] = likelihood + row["score"] - row["J"]
            out.append((row["likelihood_score"], row["p_value"], fit, om, cov))
        return out

    finalists = fitted_finalists(HOPELESS)
    if not any(f[1] >= FIT_ALPHA for f in finalists):  # none fits: the least bad is chosen
        finalists = fitted_finalists(None)  # among the finalists fitted to the end
    # a model its own covariance rejects (p < FIT_ALPHA) is not kept while another fits
    fitting = [f for f in finalists if f[1] >= FIT_ALPHA] or finalists
    if not fitting:
        raise RuntimeError("identify_noise: no candidate model could be fitted with its own "
                           "covariance (degenerate); try fewer terms or a longer record")  # fmt: skip
    _, _, fit, omega, cov = min(fitting, key=lambda f: f[0])
    bounds = upper_bounds(fit, avar, omega, cols, ms, n, tau0, terms, ci, sampling)
    progress.update(1)
    for row in tried:
        row.pop("fit")
    terms_out = _intervals(fit, cov, ci, unit)
    dof = int(ms.size - len(fit["names"]) - 2 * len(fit["gm"]))
    chi2 = float(fit["J"])
    p = chi2_sf(chi2, max(dof, 1))
    return CompositeNoise(
        terms=terms_out, unit=unit, rate_hz=float(rate_hz), n=n, ci=float(ci),
        taus=ms * tau0, avar=avar, covariance=omega, chi2=chi2, dof=dof, p_value=float(p),
        selection=tuple(tried), bounds=bounds, sampling=sampling,
    )  # fmt: skip


def _own_fit(start, avar, ms, n, tau0, sampling, cols=None, give_up=None):
    """A finalist refitted from `start` on log σ̂² with its own covariance: `(fit, Ω,
    J + log det of the relative covariance, p-value of J, covariance of p)`, or None where
    its covariance is degenerate."""
    try:
        fit, om, cov = log_fit(start, avar, ms, n, tau0, cols=cols, give_up=give_up,
                               sampling=sampling)  # fmt: skip
    except np.linalg.LinAlgError:
        return None
    model = model_avar(fit, ms, tau0, sampling=sampling)
    logdet = float(np.linalg.slogdet(om / np.outer(model, model))[1])
    dof = max(int(ms.size - len(fit["names"]) - 2 * len(fit["gm"])), 1)
    return fit, om, fit["J"] + logdet, chi2_sf(fit["J"], dof), cov


def _select(avar, omega, cols, gm_cols, terms, gauss_markov, tau0, ms, sampling):
    """Every subset of the candidates fitted with one covariance, by J + penalty."""
    tried = []
    for k in range(len(terms) + 1):
        for subset in itertools.combinations(terms, k):
            for g in range(gauss_markov + 1):
                if (not subset and g == 0) or len(subset) + 2 * g >= len(ms):
                    continue  # nothing, or no degree of freedom left
                fit = best_fit(avar, omega, cols, gm_cols, list(subset), g, g, tau0, ms,
                               sampling=sampling)  # fmt: skip
                if fit is None:
                    continue
                score = fit["J"] + PENALTY * len(subset) + GM_PENALTY * g
                tried.append({"terms": list(subset), "gauss_markov": g, "J": fit["J"],
                              "score": score, "fit": fit})  # fmt: skip
    return sorted(tried, key=lambda r: r["score"])


def _exp(v: float) -> float:
    """e^v, inf beyond float's range (the upper end of a term the data hardly see)."""
    try:
        return math.exp(v)
    except OverflowError:
        return math.inf


def _intervals(fit, cov, ci, unit):
    """Values and intervals of the selected terms from the covariance of p = (log c²,
    log T): exp(p ± zσ), the coefficients as √c²."""
    names, gm, c = fit["names"], fit["gm"], fit["c"]
    z = NormalDist().inv_cdf(0.5 + ci / 2)
    u = unit or "rate unit"

    def coef(i, unit_s, root=True):
        v, s = math.log(c[i]) if root else math.log(gm[i - len(names) - len(gm)]), 0.0
        s = math.sqrt(max(cov[i, i], 0.0))
        e = 0.5 if root else 1.0
        return {"value": _exp(e * v), "low": _exp(e * (v - z * s)),
                "high": _exp(e * (v + z * s)), "unit": unit_s}  # fmt: skip

    out = {}
    for i, t in enumerate(names):
        out[t] = coef(i, UNIT_OF[t].format(u=u))
    for j in range(len(gm)):
        out[f"gauss_markov_{j + 1}"] = {
            "sigma": coef(len(names) + j, u),
            "correlation_time": coef(len(names) + len(gm) + j, "s", root=False),
        }
    return out
