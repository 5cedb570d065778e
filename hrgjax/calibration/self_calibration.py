r"""Calibration without a turntable: virtual precession at rest, and mode reversal in FTR.

**Virtual precession** (docs/modes.md). With the case at rest in the chamber, a commanded
node force turns the wave at ρ (a few tenths of a degree per second, electrical) in
whole-angle mode, so it visits every angle. The measured angle then moves at

$$\dot{\hat\theta} = S(\hat\theta)\,\rho + D_\theta(\hat\theta),$$

where $D_\theta$ is the wave's own drift at rest seen through the readout (damping
anisotropy, rate bias, the drive's and the readout's errors — what a static run at that
angle measures) and $S$ the commanded precession's gain seen through the readout (the
readout's scale factor × the forcers' gain on the node). Two sweeps, +ρ and −ρ, over the same
angles separate the two: terms odd in ρ (the forcers' gain, the loops' lag) go into $S$, the
rest into $D_\theta$. Both are Fourier series in 2θ (`harmonics`), fitted to the measured
angle itself (not to its noisy differences): sample i of run r is

$$\hat\theta_i = c_r + \sum_j s_j\int_{t_0}^{t_i}\rho\,b_j(\hat\theta)\,dt
  + \sum_j d_j\int_{t_0}^{t_i}b_j(\hat\theta)\,dt,\qquad b = (1, \cos2\theta, \sin2\theta, …),$$

linear least squares with one offset per run (each interval's integral exact for a wave
turning uniformly between its two measured angles).
The compensator's drift is $D = -D_\theta/k_{e,\rm nom}$ (the equivalent input rate at rest,
as every compensator's) at each calibrated temperature, linear in temperature between them
(held beyond: the drift there was 8–25× its in-range error, though below the raw gyro's;
[`correct`][hrgjax.calibration.AbstractCompensator.correct] counts those samples, and
`extrapolate=False` passes them through: docs/modes.md).
**What it cannot know: the scale factor.** The angular gain $k_e$ needs a rate (one
rotation, or the Earth's), and $S$ is not the whole-angle scale factor: it is the readout's
$d\hat\theta/d\theta$ times the forcers' gain on the node times the true over the estimated
amplitude (the AGC holds the *estimate*; with a pickoff gain mismatch g,
$S = (1 - 2g\cos2\theta)(1 + g\cos2\theta) \approx 1 - g\cos2\theta$), and these do not
separate at rest. So `scale_factor` is the nominal 1 and $S$ is kept as `gain_coef` for
inspection; the static drift, which needs no rate, is what the sweeps calibrate.

**Mode reversal** ([`mode_reversal`][hrgjax.calibration.mode_reversal]):
force-to-rebalance readings at θ and θ + 90° (electrical), **the case at rest**: the damping
anisotropy's bias changes sign, the rate bias does not. Half the difference is that bias as
it shows on the output, −½Δ(1/τ)·sin 2(θ − θ_τ)/k_e (the compensators' drift convention: the
equivalent input rate). An input rate does not cancel: the FTR scale factor carries
a/â ≈ 1 − g cos 2θ (g the pickoff gain mismatch, unknown), so a rate Ω puts −g cos 2θ·Ω into
the difference; `mode_reversal` and `mode_reversal_data` refuse a case turning faster than
[`STILL_RATE_DPS`][hrgjax.units.STILL_RATE_DPS], unless its rate is constant and no larger
than Earth's (`EARTH_RATE_DPS`: a bench on the Earth, whose vertical rate then enters the
bias reading and, through g, at most g·Ω_E the anisotropy).
"""

from __future__ import annotations

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_numbers, concrete_value, finite_number, is_concrete
from .._compiled import device, fused
from .._warn import user_stacklevel
from .._x64 import require_x64
from ..data import MeasuredData
from ..gyro import Gyro
from ..pattern_noise import STILL_RATE_DPS
from ..profiles import Profile
from ..units import DEG, DEG_PER_S, K_E_NOMINAL
from ._compensator import AbstractCompensator, check_number, check_whole, setting_field
from ._raw import check_raw
from ._runs import RunGroup, simulate_runs, switch_on_keys
from ._sweeps import CONSTANT_RATE_DPS as CONSTANT_RATE_DPS
from ._sweeps import EARTH_RATE_DPS as EARTH_RATE_DPS
from ._sweeps import MIN_COVERAGE_DEG as MIN_COVERAGE_DEG
from ._sweeps import at_rest, hold_var, sweep_design, sweep_std, sweeps_by_temperature
from .experiment import QUICK_TEMPERATURES, Plan, run_plan
from .reduce import check_k_e

PRECESSION_DPS = 0.5
"""Default commanded precession rate [°/s, electrical]: 180° in 6 min."""
SETTLE_S = 30.0
"""Default time left out at the start of each sweep [s]: the loops' transient (≥ 30/β)."""


def precession_plan(
    temperatures_c=QUICK_TEMPERATURES,
    precession_dps: float = PRECESSION_DPS,
    turns: int = 1,
    settle_s: float = SETTLE_S,
    dt_out: float = 1.0,
) -> Plan:
    """Two sweeps at each chamber temperature, case at rest: +`precession_dps` from −90°
    and −`precession_dps` from +90° (electrical), each over `turns` × 180° after `settle_s`
    [s] of settling — every angle the drift's 2θ and 4θ terms have, seen in both directions.
    At the default 0.5 °/s a sweep takes 6.5 min."""
    temps = _temperatures("precession_plan", temperatures_c)
    precession_dps = finite_number("precession_plan: precession_dps", precession_dps, "°/s")
    settle_s = finite_number("precession_plan: settle_s", settle_s, "s")
    if not (np.isfinite(precession_dps) and precession_dps > 0):
        raise ValueError(f"precession_dps must be a positive rate [°/s]; got {precession_dps!r}")
    if not (isinstance(turns, int) and turns >= 1):
        raise ValueError(f"turns must be a whole number ≥ 1 of half turns; got {turns!r}")
    if not (np.isfinite(settle_s) and settle_s >= 0):
        raise ValueError(f"settle_s must be ≥ 0 [s]; got {settle_s!r}")
    margin = precession_dps * settle_s
    duration = settle_s + 180.0 * turns / precession_dps
    rho = np.tile([precession_dps, -precession_dps], temps.size)
    start = np.tile([-90.0 - margin, -90.0 + 180.0 * turns + margin], temps.size)
    return Plan(temperature_c=device(np.repeat(temps, 2)), wave_angle0_deg=device(start),
                rate_dps=device(np.zeros(rho.size)), duration_s=float(duration),
                dt_out=float(dt_out), precession_dps=device(rho))  # fmt: skip


def _temperatures(who: str, temperatures_c) -> np.ndarray:
    """The chamber temperatures as a 1-D float array, or a one-line error (not numbers, not
    1-D — a table is not flattened —, empty or not finite)."""
    check_numbers(f"{who}: temperatures_c", temperatures_c, "finite temperatures [°C]")
    temps = np.atleast_1d(np.asarray(temperatures_c, dtype=float))
    if temps.ndim != 1 or temps.size == 0 or not np.all(np.isfinite(temps)):
        raise ValueError(f"{who}: temperatures_c must be finite temperatures [°C], shape (n,); "
                         f"got {temperatures_c!r}"[:300])  # fmt: skip
    return temps


def run_precession_plan(gyro: Gyro, plan: Plan, **options) -> MeasuredData:
    """Simulate every sweep of `plan` ([`precession_plan`][hrgjax.calibration.precession_plan])
    on `gyro` in whole-angle mode, one switch-on: [`run_plan`][hrgjax.calibration.run_plan]
    with its keywords (`key`, `bias_key`, `model`, `first_run`; chunks and progress as there);
    the data carry the commanded rate in the column `precession_dps`."""
    if gyro.control.mode != "wa":
        raise ValueError("virtual-precession sweeps run in whole-angle mode: give a gyro with "
                         f"Control(mode='wa'); got mode={gyro.control.mode!r}")  # fmt: skip
    if plan.precession_dps is None or np.any(np.asarray(plan.precession_dps) == 0):
        raise ValueError("a sweep plan commands a nonzero precession in every run "
                         "(precession_plan builds one)")  # fmt: skip
    return run_plan(gyro, plan, **options)


def angle_basis(theta, harmonics: int):
    """(…, 2·harmonics + 1): 1, cos 2θ, sin 2θ, …, cos 2Nθ, sin 2Nθ of θ [rad]."""
    cols = [jnp.ones_like(theta)]
    for n in range(1, harmonics + 1):
        cols += [jnp.cos(2 * n * theta), jnp.sin(2 * n * theta)]
    return jnp.stack(cols, axis=-1)


def fit_sweeps(t, wave_angle, precession, weight, harmonics: int = 2):
    r"""The sweeps' least squares (module docstring), differentiable: `t` [s], `wave_angle`
    [rad, measured], `precession` [rad/s, commanded] of R runs × n samples, `weight` (R, n)
    1 for a sample used, 0 for one left out (the settling); every run's integrals start at
    its first used sample. **Returns** `(s, d)`: the gain S and drift $D_\theta$ [rad/s,
    electrical] coefficients on [`angle_basis`][hrgjax.calibration.self_calibration.angle_basis],
    shape (2·harmonics + 1,) each."""
    a, y, j = sweep_design(t, wave_angle, precession, weight, harmonics)
    scale = jnp.sqrt(jnp.sum(a * a, axis=0)) + 1e-300  # columns equilibrated
    coef = jnp.linalg.lstsq(a / scale[None, :], y)[0] / scale
    return coef[:j], coef[j : 2 * j]


_WHO = "PrecessionCompensator"


class PrecessionCompensator(AbstractCompensator):
    """The compensator a virtual-precession self-calibration gives (module docstring):
    the drift as a Fourier series in the measured angle at each calibrated temperature,
    linear in temperature between them (held beyond the ends, where `correct` counts the
    samples beyond `calibrated_range`, the span of `temperatures_c`; `extrapolate=False`
    passes them through); the nominal scale factor.

    **Arguments:**

    - `harmonics`: N, number of 2nθ harmonics fitted (2: the 2θ and 4θ terms).
    - `settle_s`: time left out at the start of every sweep [s].
    - `temperature_bin`: sweeps are grouped by mean temperature rounded to this [°C].
    - `k_e`: nominal angular gain.
    - `temperatures_c`: calibrated temperatures [°C] (set by `fit`).
    - `drift_coef`: (K, 2N + 1) coefficients of the drift (equivalent input rate [rad/s]);
      `gain_coef`: of the commanded precession's gain S (module docstring); `None` before
      `fit`. The scale factor is the nominal 1: the sweeps do not calibrate it.
    - `drift_std`, `gain_std`: their standard errors, same shapes and units (drift [rad/s],
      gain [–]), from the fit's own residuals (`_sweeps.sweep_std`: white angle noise and an
      angle random walk through the least squares, or `fit`'s `noise`; docs/modes.md gives
      their coverage); NaN from fewer than 6 sweeps (3 temperatures) without `noise`, or a
      sweep under 16 samples; `None` before `fit` (and loaded from a file saved before they were
      kept: `save_compensator` and `export_json` keep them since 2026-12-03).
    """

    harmonics: int = setting_field(_WHO, "harmonics", 2)
    settle_s: float = setting_field(_WHO, "settle_s", SETTLE_S)
    temperature_bin: float = setting_field(_WHO, "temperature_bin", 1.0)
    k_e: float = setting_field(_WHO, "k_e", K_E_NOMINAL)
    temperatures_c: tuple[float, ...] = eqx.field(static=True, default=())
    drift_coef: jax.Array | None = None
    gain_coef: jax.Array | None = None
    drift_std: jax.Array | None = None
    gain_std: jax.Array | None = None

    def __check_init__(self):
        check_k_e(self.k_e)
        check_whole(_WHO, "harmonics", self.harmonics, 1, " (number of 2nθ harmonics)")
        check_number(_WHO, "settle_s", self.settle_s, " [s]", minimum=0.0)
        check_number(_WHO, "temperature_bin", self.temperature_bin, " [°C]", minimum=0.0,
                     strict=True)  # fmt: skip

    @property
    def name(self) -> str:
        """Short label used in tables."""
        return "virtual precession"

    @property
    def extrapolates(self) -> bool:
        """`True`: held at its end temperatures (8–25× its in-range error at −40 and +60 °C
        from sweeps at 0/20/40 °C, below the raw gyro's)."""
        return True

    @property
    def calibrated_range(self) -> tuple[float, float] | None:
        """(T_min, T_max) [°C]: the span of `temperatures_c` (`None` before `fit`)."""
        if not self.temperatures_c:
            return None
        return (float(min(self.temperatures_c)), float(max(self.temperatures_c)))

    @fused
    def _at(self, coef, theta, temperature_c):
        if coef is None:
            raise ValueError("this PrecessionCompensator is not fitted; use comp = comp.fit(data)")
        theta, temperature_c = jnp.broadcast_arrays(
            jnp.asarray(theta, dtype=float), jnp.asarray(temperature_c, dtype=float)
        )
        basis = angle_basis(theta, self.harmonics)  # (…, J)
        if len(self.temperatures_c) == 1:
            return jnp.sum(basis * coef[0], axis=-1)
        temps = jnp.asarray(self.temperatures_c, dtype=float)
        tc = jnp.clip(temperature_c, temps[0], temps[-1])
        i = jnp.clip(jnp.searchsorted(temps, tc, side="right") - 1, 0, temps.shape[0] - 2)
        frac = ((tc - temps[i]) / (temps[i + 1] - temps[i]))[..., None]
        return jnp.sum(basis * (coef[i] + (coef[i + 1] - coef[i]) * frac), axis=-1)

    def drift(self, theta, temperature_c):
        return self._at(self.drift_coef, theta, temperature_c)

    @property
    def readout_gain_mismatch(self) -> np.ndarray:
        """The pickoff gain mismatch g at each calibrated temperature [–], read from the
        sweeps' gain S ≈ (1 + g_f)(1 − g cos 2θ) (module docstring; g_f the forcers' common
        gain, which scales the whole of S) as −S₁/S₀, the cos 2θ term over the constant:
        free of g_f (−S₁ alone is (1 + g_f) g: 5 % off at g_f = 5 %). It **assumes matched
        forcers**: a forcer gain mismatch g_m adds to it (S's cos 2θ term is −(g + g_m)) and
        cannot be told apart at rest."""
        if self.gain_coef is None:
            raise ValueError("this PrecessionCompensator is not fitted; use comp = comp.fit(data)")
        coef = np.asarray(self.gain_coef)
        return -coef[:, 1] / coef[:, 0]

    def scale_factor(self, theta, temperature_c):
        """The nominal 1: sweeps at rest do not calibrate the scale factor (module docstring)."""
        return jnp.ones_like(theta + temperature_c)

    def fit(self, data, *, key=None, raw=None, noise=None) -> PrecessionCompensator:
        """Fit to virtual-precession sweeps at rest (`data` with a `precession_dps` column,
        from [`run_precession_plan`][hrgjax.calibration.run_precession_plan]
        or a gyro's own sweeps); `key` and `raw` are not used (`raw` beside the samples is
        refused: pass them once). `noise`: the gyro's known angle noise for `drift_std`
        (`NoiseModel.from_gyro`, or an Allan analysis); without it σ is read from the data.

        **Raises:** `ValueError` for data without the column, force-to-rebalance output (a
        `rebalance_rate_dps` column with `rebalance_on` absent or 1), a sweep left with fewer
        than 20 samples after `settle_s`, a temperature without sweeps in both directions,
        sweeps too short for the harmonics, sweeps in one direction
        covering less than `MIN_COVERAGE_DEG` (120°) of the 180° (electrical) period, or a
        fitted constant gain S₀ further than `GAIN_TOLERANCE` from 1 (the column in the
        wrong unit: S₀ ≈ 180/π for rad/s)."""
        require_x64("PrecessionCompensator.fit")
        check_raw("PrecessionCompensator.fit", data, raw, windows=False)
        if not isinstance(data, MeasuredData):
            raise TypeError("PrecessionCompensator.fit needs MeasuredData (the sweeps' samples)")
        if "precession_dps" not in data:
            raise ValueError(
                "self-calibration needs virtual-precession data: a 'precession_dps' column "
                "(the commanded rate [°/s]; run_precession_plan or hrgjax simulate --precession)"
            )
        if "rebalance_rate_dps" in data and np.any(
            data["rebalance_on"] != 0 if "rebalance_on" in data else True
        ):
            raise ValueError(
                "self-calibration reads whole-angle sweeps; these data are force-to-rebalance "
                "output (a rebalance_rate_dps column with the loop on: the wave is held and "
                "follows the commanded precession exactly, so the drift would read 0) — run "
                "the sweeps in whole-angle mode (Control(mode='wa'), run_precession_plan)"
            )
        groups = sweeps_by_temperature(data, self.temperature_bin, self.settle_s)
        temps, drift, sf, arrays = [], [], [], []
        for temp, runs in groups:
            t, th, rho, w = _padded(runs)
            s, d = fit_sweeps(device(t), device(th), device(rho), device(w), self.harmonics)
            _check_gain(float(s[0]), temp)
            temps.append(temp)
            drift.append(-np.asarray(d) / self.k_e)
            sf.append(np.asarray(s))
            arrays.append((t, th, rho, w))
        fitted = PrecessionCompensator(harmonics=self.harmonics, settle_s=self.settle_s,
                                       temperature_bin=self.temperature_bin, k_e=self.k_e,
                                       temperatures_c=tuple(temps))  # fmt: skip
        std = [(d / self.k_e, s) for s, d in sweep_std(arrays, self.harmonics, noise)]
        new = [np.stack(drift), np.stack(sf), *(np.stack(x) for x in zip(*std, strict=True))]
        return eqx.tree_at(lambda c: (c.drift_coef, c.gain_coef, c.drift_std, c.gain_std),
                           fitted, [jnp.asarray(x) for x in new],
                           is_leaf=lambda x: x is None)  # fmt: skip


GAIN_TOLERANCE = 0.2
"""Largest |S₀ − 1| `PrecessionCompensator.fit` accepts, S₀ the constant term of the fitted
gain of the commanded precession: S₀ = 1 + g_f, the forcers' common gain error (a few
percent at most on a working gyro — an error of tens of percent is not a gyro, it is a
`precession_dps` column in the wrong unit: rad/s gives S₀ = 180/π ≈ 57.3)."""


def _check_gain(s0: float, temp: float) -> None:
    """Refuse a fitted constant gain S₀ (at `temp` [°C]) implausibly far from 1."""
    if abs(s0 - 1.0) <= GAIN_TOLERANCE:
        return
    if abs(s0 * DEG - 1.0) <= GAIN_TOLERANCE:
        hint = "S₀ ≈ 180/π: the precession_dps column looks like rad/s; give °/s"
    elif abs(s0 / DEG - 1.0) <= GAIN_TOLERANCE:
        hint = ("S₀ ≈ π/180: the precession_dps column looks 57.3× too large (or "
                "wave_angle_deg in rad); give °/s and °")  # fmt: skip
    else:
        hint = "check the precession_dps column's unit (°/s, electrical) and sign"
    raise ValueError(
        f"precession_dps: at {temp:g} °C the sweeps' fitted gain S₀ = {s0:.4g}, expected "
        f"1 ± {GAIN_TOLERANCE:g} (the forcers' gain); {hint}"
    )


def _padded(runs):
    """Runs stacked to one length, the shorter padded with zero-weight samples: times going
    on by 1 s, the last angle held, no precession."""
    n = max(len(r[0]) for r in runs)

    def pad(x, tail):
        return np.concatenate([x, tail[: n - len(x)]])

    ramp = np.arange(1.0, n + 1.0)
    t = np.stack([pad(r[0], r[0][-1] + ramp) for r in runs])
    th = np.stack([pad(r[1], np.full(n, r[1][-1])) for r in runs])
    rho = np.stack([pad(r[2], np.zeros(n)) for r in runs])
    w = np.stack([pad(r[3].astype(float), np.zeros(n)) for r in runs])
    return t, th, rho, w


class ModeReversal(eqx.Module):
    """Force-to-rebalance readings at two held angles θ and θ + 90° (electrical).

    - `angles_deg`: the two held angles [°].
    - `readings`: the mean FTR output held at each [rad/s], shape (…, 2) (a batched record:
      one pair per member).
    - `bias`: their mean, the rate bias with the damping anisotropy's bias cancelled [rad/s]
      (the case at rest).
    - `anisotropy`: half their difference [rad/s]: the damping anisotropy's bias at θ **as it
      shows on the output**, −½Δ(1/τ)·sin 2(θ − θ_τ)/k_e — the equivalent input rate, the
      sign convention of the compensators' drift (each reading is SF·(Ω − b) with
      b = ½Δ(1/τ)·sin 2(θ − θ_τ)/k_e the bias in the FTR law of docs/modes.md, so half the
      difference is −b).
    - `readings_std`, `bias_std`, `anisotropy_std`: their standard errors [rad/s] from each
      hold's own samples (`_sweeps.hold_var`: the readout's white angle noise, which cancels in a
      mean of rates but for its ends, and white rate noise; docs/modes.md gives their
      coverage); NaN for a hold of fewer than 16 samples. A rate wander slower than the hold
      (a Gauss–Markov bias) is read as bias and is not in them.
    """

    angles_deg: tuple[float, float] = eqx.field(static=True)
    readings: jax.Array
    bias: jax.Array
    anisotropy: jax.Array
    readings_std: jax.Array | None = None
    bias_std: jax.Array | None = None
    anisotropy_std: jax.Array | None = None


def mode_reversal(t, rebalance_rate, profile: Profile, settle_s: float = 20.0) -> ModeReversal:
    """Reduce an FTR run held at two angles 90° apart (electrical;
    [`Profile.held_angles`][hrgjax.Profile.held_angles]) to the rate bias and the damping
    anisotropy's bias: each hold's mean output after `settle_s` [s], their mean and half
    difference. `t` [s] and `rebalance_rate` [rad/s] as in the record (jax arrays pass:
    the reduction is differentiable).

    **The case must be at rest** (the profile's rate within
    [`STILL_RATE_DPS`][hrgjax.units.STILL_RATE_DPS]): the FTR scale factor carries
    a/â ≈ 1 − g cos 2θ (g the pickoff gain mismatch), so an input rate Ω reads differently
    at the two holds and puts −g cos 2θ·Ω into the anisotropy (33 % of it at 0° and 36 °/h on the
    default gyro); g is not known, so this cannot be corrected. **Earth's rate** passes: a
    rate constant over the profile and no larger than `EARTH_RATE_DPS` (Ω_E sin φ on a
    vertical sensitive axis, `hrgjax.units.EARTH_RATE`). It then enters the `bias` reading
    (the rate bias plus Ω_E sin φ, times the scale factor), and the `anisotropy` picks up
    −g cos 2θ·Ω_E sin φ (≤ 0.07 °/h on the default gyro, g = 0.46 %; none at θ = ±45°).

    **Raises:** `ValueError` for a profile without two holds 90° apart, a case that turns,
    or a hold with no sample of `t` after its `settle_s` (coarse output times, or a record
    that starts late); warns (`ShortSettleWarning`) for `settle_s` < `MIN_SETTLE_S`."""
    if not isinstance(profile, Profile):
        raise TypeError(f"mode_reversal: profile must be an hrgjax.Profile (Profile.held_angles"
                        f"(…)); got {type(profile).__name__}")  # fmt: skip
    check_numbers("mode_reversal: t", t, "the record's sample times [s], shape (…, N)")
    check_numbers("mode_reversal: rebalance_rate", rebalance_rate, "rates [rad/s], shape (…, N)")
    t_shape, r_shape = tuple(np.shape(t)), tuple(np.shape(rebalance_rate))
    if not t_shape or r_shape[-1:] != t_shape[-1:]:
        raise ValueError(f"mode_reversal: rebalance_rate must have one value per sample of t, "
                         f"shape (…, N) as t's {t_shape}; got shape {r_shape}")  # fmt: skip
    profile = _held_values(profile)  # the holds, their angles: the knots' concrete values
    _check_at_rest(np.asarray(profile.rate) / DEG_PER_S, "the profile's rate")
    if len(windows := profile.hold_windows(settle_s)) != 2:
        raise ValueError(f"mode_reversal needs a profile with two holds longer than settle_s = "
                         f"{float(settle_s):g} s; it has {len(windows)}")  # fmt: skip
    _check_settle("mode_reversal", float(settle_s))
    theta0 = float(profile.wave_angle0) / DEG
    with jax.ensure_compile_time_eval():  # under jit (a sweep over temperature) too
        turn = float(profile.commanded_angle_at(profile.t[-1])) / DEG - theta0
    if abs(abs(turn) - 90.0) > 1e-6:
        raise ValueError(f"the holds must be 90° apart (electrical); these are {turn:g}° apart")
    if (times := concrete_value(t)) is not None:  # a traced t: its windows filled or not
        for (start, end), angle in zip(windows, (theta0, theta0 + turn), strict=True):
            if np.any(np.sum((times >= start) & (times <= end), axis=-1) == 0):
                raise ValueError(
                    f"mode_reversal: no sample of t in the hold at {angle:g}° ({start:g} … "
                    f"{end:g} s, after settle_s = {float(settle_s):g} s): give output times inside "
                    "every hold (a finer dt_out, or ts covering it) or a shorter settle_s"
                )
    t, r = jnp.broadcast_arrays(jnp.asarray(t), jnp.asarray(rebalance_rate))
    masks = jnp.stack([((t >= a) & (t <= b)).astype(r.dtype) for a, b in windows], axis=-2)
    readings = jnp.sum(masks * r[..., None, :], -1) / jnp.sum(masks, -1)  # (…, 2): a batch too
    std = jnp.sqrt(hold_var(r, masks, readings, jnp))
    pair = 0.5 * jnp.sqrt(jnp.sum(std**2, axis=-1))  # the holds' noise independent
    return ModeReversal(
        angles_deg=(round(theta0, 9), round(theta0 + turn, 9)),
        readings=readings,
        bias=0.5 * (readings[..., 0] + readings[..., 1]),
        anisotropy=0.5 * (readings[..., 0] - readings[..., 1]),
        readings_std=std,
        bias_std=pair,
        anisotropy_std=pair,
    )


def _held_values(profile: Profile) -> Profile:
    """`profile` with concrete values only: the knots `mode_reversal` reads (the holds, their
    angles, the rate) their eager values (`jax.grad` outside `jit` carries them; a traced
    one refused in one line), the fields it does not read (a swept temperature) zeros."""
    read, out = ("t", "rate", "wave_angle0", "precession"), {}
    for name in (*read, "temperature", "accel", "rebalance"):
        if (x := getattr(profile, name)) is not None and not is_concrete(x):
            out[name] = concrete_value(x) if name in read else np.zeros(x.shape)
            if out[name] is None:
                raise ValueError(f"mode_reversal: profile.{name} is traced here (jit, vmap or "
                                 "hg.sweep over the held angles, times or rate), but the holds and "
                                 "their angles are read from its values: build the profile from "
                                 "concrete ones (a swept temperature is fine)")  # fmt: skip
    return eqx.tree_at(lambda p: [getattr(p, n) for n in out], profile, list(out.values()))


def _check_at_rest(rate_dps, what: str) -> None:
    """Refuse mode reversal with the case turning (`rate_dps`: its rates [°/s], the profile's
    knots or a run's samples): within `STILL_RATE_DPS` (readback jitter), or constant to
    `CONSTANT_RATE_DPS` and no larger than Earth's (`EARTH_RATE_DPS`), is at rest."""
    rate_dps = np.asarray(rate_dps, dtype=float)
    if at_rest(rate_dps):
        return
    peak, spread = float(np.max(np.abs(rate_dps))), float(np.ptp(rate_dps))
    varies = f" and varies by {spread:.3g} °/s" if peak <= EARTH_RATE_DPS else ""
    raise ValueError(
        f"mode reversal needs the case at rest (|rate| ≤ STILL_RATE_DPS = {STILL_RATE_DPS:g} "
        f"°/s, or a constant rate no larger than Earth's, {EARTH_RATE_DPS:.4g} °/s); {what} "
        f"reaches {peak:g} °/s{varies}: the FTR scale factor differs at the two holds by the "
        "unknown readout gain mismatch (≈ 1 − g cos 2θ), so the rate does not cancel and "
        "biases the anisotropy"
    )


MIN_SETTLE_S = 10.0
"""Shortest `settle_s` [s] mode reversal takes without a `ShortSettleWarning` (a faster loop
may filter it): 20/β at the default rebalance bandwidth β = 2 rad/s. The loop's transient after
the slew, (1 + βt)e^{−βt}, is in a hold read sooner: the default gyro's bias at ±45° read 0.2877,
0.2949, 0.29533 °/h at settle_s = 0, 2, 10; with 2 % forcer gain error and a 10-s slew it was
2.4×, 0.5 %, 1e-6 of the anisotropy off at 0, 5, 10 s (`tests/test_self_calibration.py`)."""


class ShortSettleWarning(UserWarning):
    """`settle_s` below `MIN_SETTLE_S`: the rebalance loop's transient may be in the reading."""


def _check_settle(who: str, settle_s: float) -> None:
    """Warn (`ShortSettleWarning`, at the user's line) for `settle_s` [s] < `MIN_SETTLE_S`."""
    if settle_s < MIN_SETTLE_S:
        warnings.warn(
            f"{who}: settle_s = {settle_s:g} s is shorter than MIN_SETTLE_S = {MIN_SETTLE_S:g} s: "
            "the rebalance loop's transient after the slew (a few 1/β, 0.5 s at the default "
            "2 rad/s) is in the hold's mean (2.6 % of the bias at settle_s = 0 on the default "
            f"gyro); give settle_s ≥ {MIN_SETTLE_S:g} s",
            ShortSettleWarning,
            stacklevel=user_stacklevel(),
        )


def run_reversal_plan(
    gyro: Gyro,
    temperatures_c=QUICK_TEMPERATURES,
    angle_deg: float = 0.0,
    dwell_s: float = 180.0,
    slew_s: float = 20.0,
    *,
    key: jax.Array | None = None,
    bias_key: jax.Array | None = None,
    first_run: int = 0,
) -> MeasuredData:
    """Mode reversal at each chamber temperature, case at rest: one force-to-rebalance run
    per temperature held at `angle_deg` and at `angle_deg` + 90° (electrical) for `dwell_s`
    [s] each, moved by a `slew_s` [s] commanded precession
    ([`Profile.held_angles`][hrgjax.Profile.held_angles]). The data carry the FTR output
    `rebalance_rate_dps` and the schedule `precession_dps`; reduce them with
    [`mode_reversal_data`][hrgjax.calibration.mode_reversal_data]."""
    if gyro.control.mode != "ftr":
        raise ValueError("mode reversal holds the wave: give a gyro in force-to-rebalance mode "
                         "(gyro.in_mode('ftr'))")  # fmt: skip
    temps = _temperatures("run_reversal_plan", temperatures_c)
    profiles = [
        Profile.held_angles([angle_deg, angle_deg + 90.0], dwell_s, slew_s, t) for t in temps
    ]
    batch = jax.tree_util.tree_map(lambda *x: np.stack(x), *profiles)
    ts = np.arange(int(np.floor(float(profiles[0].t[-1]) + 1e-9)) + 1, dtype=float)  # 1 s
    keys, bias_key = switch_on_keys(gyro, key, bias_key, temps.size, "run_reversal_plan")
    return simulate_runs(
        gyro,
        [RunGroup(ts, np.arange(temps.size), min(32, temps.size))],
        lambda take, _: jax.tree_util.tree_map(lambda x: device(x[take]), batch),
        keys,
        bias_key,
        "averaged",
        samples=np.full(temps.size, ts.size),
        failure=lambda take, message: f"run_reversal_plan: {message}",
        unit="run",
        first_run=first_run,
    )


def mode_reversal_data(data: MeasuredData, settle_s: float = 20.0) -> list[dict]:
    """[`mode_reversal`][hrgjax.calibration.mode_reversal] on every run of FTR data held at
    two angles (the holds found where `precession_dps` is 0): per run
    `{"run", "temperature_c", "angles_deg", "readings_dph", "bias_dph", "anisotropy_dph"}`
    [°, °/h] and their standard errors `readings_std_dph`, `bias_std_dph`,
    `anisotropy_std_dph` [°/h] (as `ModeReversal`'s; None for a hold under 16 samples);
    `anisotropy_dph` as `ModeReversal.anisotropy` (the bias as it shows on the
    output). **Raises:** `ValueError` without the FTR output or the schedule, for a run
    with other than two holds 90° apart, or one whose case turns (`table_rate_dps` beyond
    [`STILL_RATE_DPS`][hrgjax.units.STILL_RATE_DPS], unless constant and within Earth's
    rate: mode reversal needs the case at rest, see `mode_reversal`); warns as it."""
    if not isinstance(data, MeasuredData):
        raise TypeError(f"mode_reversal_data: data must be hrgjax.MeasuredData; got "
                        f"{type(data).__name__}")  # fmt: skip
    settle_s = finite_number("mode_reversal_data: settle_s", settle_s, "s")
    if settle_s < 0:
        raise ValueError(f"mode_reversal_data: settle_s must be >= 0 [s]; got {settle_s:g}")
    _check_settle("mode_reversal_data", settle_s)
    for name in ("rebalance_rate_dps", "precession_dps"):
        if name not in data:
            raise ValueError(f"mode reversal needs force-to-rebalance data with a {name!r} column "
                             "(hrgjax simulate --mode ftr --plan reversal)")  # fmt: skip
    out = []
    for idx in data.run_indices():
        t = data["time_s"][idx]
        rho = data["precession_dps"][idx]
        still = rho == 0
        if "rebalance_on" in data:  # a schedule's whole-angle stretches are not holds
            still &= data["rebalance_on"][idx] == 1
        # holds: maximal stretches of zero commanded precession
        edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]])))
        holds = [(t[a] + settle_s, t[b - 1]) for a, b in zip(edges[::2], edges[1::2], strict=True)
                 if t[b - 1] - t[a] > settle_s]  # fmt: skip
        run = int(data["run"][idx[0]])
        _check_at_rest(data["table_rate_dps"][idx], f"run {run}'s table_rate_dps")
        if len(holds) != 2:
            raise ValueError(f"run {run}: mode reversal needs two holds; found {len(holds)}")
        wave = data["wave_angle_deg"][idx]
        held = [float(np.mean(wave[(t >= a) & (t <= b)])) for a, b in holds]
        turn = held[1] - held[0]  # FTR holds the estimate at the commanded angle
        if abs(abs(turn) - 90.0) > 0.5:
            raise ValueError(f"run {run}: the holds are {turn:.3g}° apart; mode reversal needs 90°")
        rate = data["rebalance_rate_dps"][idx] * 3600.0
        masks = np.stack([(t >= a) & (t <= b) for a, b in holds]).astype(float)
        readings = [float(np.mean(rate[m > 0])) for m in masks]
        std = np.sqrt(hold_var(rate, masks, np.asarray(readings), np))
        pair = None if np.any(np.isnan(std)) else 0.5 * float(np.sqrt(np.sum(std**2)))
        out.append({
            "run": run,
            "temperature_c": float(np.mean(data["temperature_c"][idx])),
            "angles_deg": [round(held[0], 3), round(held[1], 3)],
            "readings_dph": readings,
            "bias_dph": 0.5 * (readings[0] + readings[1]),
            "anisotropy_dph": 0.5 * (readings[0] - readings[1]),
            "readings_std_dph": [None if np.isnan(v) else float(v) for v in std],
            "bias_std_dph": pair,
            "anisotropy_std_dph": pair,
        })  # fmt: skip
    return out
