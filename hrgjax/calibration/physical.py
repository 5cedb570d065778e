r"""`PhysicalCompensator`: the grey box — resonator temperature laws fitted through the simulator.

The model gyro is the averaged simulator with the loops closed ideally (amplitude held,
quadrature nulled; PHYSICS.md §10) and these laws, ΔT = T − 20 °C:

| parameter | law | fitted |
|---|---|---|
| angular gain | $k_e(T) = k_{e0}(1 + \kappa\,\Delta T)$ | $k_{e0}$, κ [1/°C] |
| rate bias | $b_0 + b_1\Delta T + b_2\Delta T^2$ | [rad/s], [rad/s/°C], [rad/s/°C²] |
| damping anisotropy | $\Delta(1/\tau)(T) = d_0\,e^{\lambda\Delta T}$ | $d_0$ [1/s], λ [1/°C] |
| damping axis | $\theta_\tau(T) = \theta_{\tau0} + \theta_{\tau1}\Delta T$ | [rad], [rad/°C] (electrical) |
| readout gain mismatch | $g(T) = g_0 + g_1\Delta T$ | [–], [1/°C] |
| readout cross-talk | $c$ | [–] |

`fit` simulates every calibration run (same times, rates, temperatures, measured initial
angle) and reduces the simulated wave angle with the same window slopes as the measured one;
Levenberg–Marquardt (`optimistix`) minimises the weighted rate residuals. A static run is one
window, a rotation is cut into `window_s` windows and a ramp (table at rest, temperature
moving) into `RAMP_WINDOW_S` windows, each a drift at its own temperature. Weights: the
residual scatter of each kind of window (at rest, moving), an at-rest window of length L
weighted by √(L / 60 s) (white rate noise: a long dwell tells more), re-estimated after the
fit with each kind's own degrees of freedom (`scatter_per_dof`); the parameter covariance
is the Gauss–Newton $(J^\top W J)^{-1}$ scaled by the reduced χ² (≈ 1 with those weights),
each σ widened by √(ν/(ν − 2)) for the degrees of freedom ν its kinds' σ's rest on
(`t_factors`: a fit's error over a σ estimated from 18 static windows is a Student t, and
read as a normal σ it covered 93 % at ±2σ; `fit_stats`' `rest_dof`, `moving_dof`).
Starting values come from harmonic fits at each temperature held for at least three
windows (a ramp's windows are not a level).

The compensator's D and SF follow from the fitted gyro itself: the readout map
$\theta\mapsto\hat\theta$ is inverted at the measured angle, the rest-state pattern rate comes
from the averaged vector field, and $\mathrm{SF} = (d\hat\theta/d\theta)\,k_e(T)/k_{e,\rm nom}$.
It also knows $\partial\hat\theta/\partial T$, the apparent rate a changing readout mismatch
gives while the temperature changes, which the empirical compensators cannot learn from bench
data taken at constant temperatures.

This module is the compensator and its fit; the parts live in private modules and their
public names are re-exported here: the parameters and model equations
(`calibration._physical_model`), the known plant (`calibration._plant`), the bench runs as
the fit's groups and weights (`calibration._physical_groups`), the least squares
(`calibration._physical_fit`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_numbers, concrete_value
from .._compiled import device
from .._x64 import require_x64
from ..data import MeasuredData
from ..gyro import Gyro
from ..profiles import Profile
from ..resonator.averaged import averaged_vector_field, input_rate
from ..resonator.slow import reduced_rate, split_problem
from ..units import DEG, DEG_PER_H, PHYSICAL_WINDOW_S
from ._compensator import (
    FROM_FIELD,
    AbstractCompensator,
    FromField,
    as_levels,
    as_range,
    check_number,
    check_whole,
    require_temperatures,
    setting,
    setting_field,
    split_targets,
    temperature_levels,
)
from ._physical_fit import LOOP_PASSES as LOOP_PASSES
from ._physical_fit import fit_values, less_pull, loop_pull
from ._physical_fit import scatter_per_dof as scatter_per_dof
from ._physical_fit import t_factors as t_factors
from ._physical_groups import FIT_COMPILE_S as FIT_COMPILE_S
from ._physical_groups import FIT_EVALUATIONS as FIT_EVALUATIONS
from ._physical_groups import FIT_MERGED_STEPS_MAX as FIT_MERGED_STEPS_MAX
from ._physical_groups import FIT_STEP_S as FIT_STEP_S
from ._physical_groups import SHARED_LENGTH_RUNS as SHARED_LENGTH_RUNS
from ._physical_groups import WEIGHT_WINDOW_S as WEIGHT_WINDOW_S
from ._physical_groups import fit_groups, window_weights
from ._physical_groups import steps_estimate as steps_estimate
from ._physical_model import MODEL_OMEGA as MODEL_OMEGA
from ._physical_model import MODEL_TAU as MODEL_TAU
from ._physical_model import NAMES, SCALE, model_gyro, readout_angle, true_angle
from ._physical_model import PARAMETERS as PARAMETERS
from ._physical_start import initial_values
from ._plant import PLANT_RESONATOR as PLANT_RESONATOR
from ._plant import known_plant
from ._plant import plant_from_json as plant_from_json
from ._plant import plant_to_json as plant_to_json
from ._raw import check_raw
from .reduce import K_E_NOMINAL, check_k_e, reduce
from .reduce import RAMP_WINDOW_S as RAMP_WINDOW_S

LAW_TEMPERATURES = 3
"""Distinct temperatures the grey box's laws need in the calibration data: the rate bias is
quadratic in T (3 coefficients); with fewer, its T² term (and more) is not identified."""
ROTATION_TEMPERATURES = 2
"""Distinct temperatures its rotation runs need: k_e(T) is linear in T and only the rotations
measure it (at rest it multiplies the bias, whose own law absorbs it)."""


class _FittedLaws(eqx.Module):
    """A fitted `PhysicalCompensator`'s arithmetic (its `_program_form`): its D(θ, T),
    SF(θ, T), ∂θ̂/∂T and compensated rate, without what does not enter them (fit
    statistics, covariance, fit settings), the scale factor's table rate `sf_rate` [rad/s]
    an array (`at_rate`: whether it is used; False: the slow-rate limit)."""

    k_e: float = eqx.field(static=True)
    values: jax.Array
    plant: Gyro | None
    sf_rate: jax.Array
    at_rate: bool = eqx.field(static=True)

    def gyro(self) -> Gyro:
        """The fitted model gyro (`PhysicalCompensator.gyro`)."""
        return model_gyro(self.values, plant=self.plant)

    def _derivatives(self, theta_meas, temperature_c, gain: bool = True):
        """(∂θ̂/∂θ, θ̇ at rest [rad/s], the gain −∂θ̇/∂Ω) at the measured angle [rad] and
        temperature [°C]; `gain=False` (the drift): the gain is not computed (`None` with a
        plant)."""
        g = self.gyro().at(temperature_c)
        theta = true_angle(g, theta_meas)
        slope = jax.jvp(lambda th: readout_angle(g, th), (theta,), (jnp.ones_like(theta),))[1]
        rest = Profile.static(1.0, temperature_c)
        if self.plant is None:
            theta_dot = averaged_vector_field(0.0, theta[None], (g, rest))[0]
            return slope, theta_dot, g.resonator.k_e
        # the PI loops on their slow manifold: the rest drift, and the gain −∂θ̇/∂Ω with
        # the loops' lag (a 2θ ripple ∝ Ω) in it
        rate = lambda w: reduced_rate(g, w, theta)
        w0 = input_rate(g, rest, 0.0)
        if not gain:
            return slope, rate(w0), None
        if not self.at_rate:
            theta_dot, d_rate = jax.jvp(rate, (w0,), (jnp.ones_like(w0),))
            return slope, theta_dot, -d_rate
        # both rates from one traced slow manifold (a batch of two), not two
        theta_dot, moved = jax.vmap(rate)(jnp.stack([w0, w0 + self.sf_rate]))
        return slope, theta_dot, -(moved - theta_dot) / self.sf_rate

    def readout_temperature_sensitivity(self, theta, temperature_c):
        """∂θ̂/∂T [rad/°C] at the measured angle θ [rad] and temperature [°C]."""
        gyro = self.gyro()
        true = true_angle(gyro.at(temperature_c), theta)
        meas = lambda temp: readout_angle(gyro.at(temp), true)
        return jax.jvp(meas, (temperature_c,), (jnp.ones_like(temperature_c),))[1]

    def drift(self, theta, temperature_c):
        """D(θ, T) [rad/s]; θ electrical [rad], T [°C]."""
        slope, theta_dot, _ = self._derivatives(theta, temperature_c, gain=False)
        return -slope * theta_dot / self.k_e

    def scale_factor(self, theta, temperature_c):
        """SF(θ, T) (1 = nominal)."""
        slope, _, k_e = self._derivatives(theta, temperature_c)
        return slope * k_e / self.k_e

    def _drift_and_scale_factor(self, theta, temperature_c):
        """`corrected_rate`'s drift and scale factor from one `_derivatives` (one traced
        slow manifold with a plant, not one for each)."""
        slope, rest_rate, k_e = self._derivatives(theta, temperature_c)
        return -slope * rest_rate / self.k_e, slope * k_e / self.k_e

    corrected_rate = AbstractCompensator.corrected_rate  # with the hook above


def _check_initial(who: str, initial) -> None:
    """Refuse starting values that are not `None` or one finite real number per parameter
    (1-D, the order of `PARAMETERS`), in one line naming `who`'s `initial` (a traced vector:
    its shape only)."""
    if initial is None:
        return
    form = (f"None or {len(NAMES)} finite real numbers, 1-D, in the order of PARAMETERS "
            f"({', '.join(NAMES)}) [SI]")  # fmt: skip
    check_numbers(f"{who}: initial", initial, form, shape=(len(NAMES),))
    if (value := concrete_value(initial)) is not None and not np.all(np.isfinite(value)):
        bad = int(np.flatnonzero(~np.isfinite(value))[0])
        raise ValueError(f"{who}: initial must be {form}; got {value[bad]} at index {bad} "
                         f"({NAMES[bad]})")  # fmt: skip


_WHO = "PhysicalCompensator"


class PhysicalCompensator(AbstractCompensator):
    """Grey-box compensator (module docstring).

    **Arguments:**

    - `k_e`: nominal angular gain of the data reduction.
    - `values`: fitted parameters in the order of
      [`PARAMETERS`][hrgjax.calibration.physical.PARAMETERS] (SI); `None` before `fit`.
    - `covariance`: their covariance; `stats`: fit statistics as pairs (see `fit_stats`).
    - `window_s`: rotation-run window [s] (default
      [`PHYSICAL_WINDOW_S`][hrgjax.units.PHYSICAL_WINDOW_S], 10 s, as the CLI's); `max_steps`:
      LM step limit.
    - `plant`: `None` (default), the ideal-loop grey box: its gain mismatch, cross-talk and
      (to ppm) k_e are *effective* values that hold the real loops' lag at the calibration's
      rates. Or the gyro's known loops and resonator constants (a [`hrgjax.Gyro`][]; the
      grey box keeps its `control` and `PLANT_RESONATOR` — ω, τ, Δω, θ_ω, χ — measured
      elsewhere or from the design): the fit then models the PI loops' lag (`loop_pull`)
      and its parameters are the physical ones; the compensator's drift and scale factor
      hold the loops ([`hrgjax.resonator.slow`][]).
    - `sf_rate`: with a plant, the table rate [rad/s] at which the scale factor takes the
      loops' lag — `fit` sets it to the calibration's mean rotation rate. The lag's 2θ
      ripple turns its phase with the rate (by 2·atan(2k_eΩ/β): 5.5° at 5 °/s with 2 rad/s
      loops), so one SF(θ, T) holds it exactly at one rate; 0: the slow-rate limit.
    - `initial`: optional starting values of `fit` (order of
      [`PARAMETERS`][hrgjax.calibration.physical.PARAMETERS], SI; 1-D, one finite number
      each, checked here); `None` (default): from harmonic fits of the reduced drift and
      scale factor at each temperature. A fitted compensator has `None` here.
    - `temperature_range` ((T_min, T_max) [°C], of the calibration samples) and
      `n_temperature_levels` (of its windows): set by `fit` (`None`: unknown). The laws
      extrapolate (`extrapolates` is `True`: beyond the bench's range its error stayed
      near its in-range one, as its predicted error says), so
      [`correct`][hrgjax.calibration.AbstractCompensator.correct] applies it everywhere and
      counts the samples outside.
    """

    k_e: float = setting_field(_WHO, "k_e", K_E_NOMINAL)
    window_s: float = setting_field(_WHO, "window_s", PHYSICAL_WINDOW_S)
    max_steps: int = setting_field(_WHO, "max_steps", 64)
    values: jax.Array | None = None
    covariance: jax.Array | None = None
    stats: tuple = eqx.field(static=True, default=())
    plant: Gyro | None = eqx.field(default=None, converter=known_plant)
    sf_rate: float = setting_field(_WHO, "sf_rate", 0.0)
    initial: jax.Array | None = None
    temperature_range: tuple[float, float] | None = eqx.field(
        static=True, default=None, converter=as_range
    )
    n_temperature_levels: int | None = eqx.field(static=True, default=None, converter=as_levels)

    def __check_init__(self):
        check_k_e(self.k_e)
        check_number("PhysicalCompensator", "window_s", self.window_s,
                     " of seconds (the rotation-run window)", minimum=0.0, strict=True)  # fmt: skip
        check_whole("PhysicalCompensator", "max_steps", self.max_steps, 1,
                    " (Levenberg–Marquardt steps)")  # fmt: skip
        check_number("PhysicalCompensator", "sf_rate", self.sf_rate, " [rad/s]")
        _check_initial("PhysicalCompensator", self.initial)
        if self.plant is not None:  # its split inside the slow manifold's domain
            temps = None if self.temperature_range is None else np.linspace(
                *self.temperature_range, 33)  # fmt: skip
            if problem := split_problem(self.plant, temps, "PhysicalCompensator.plant"):
                raise ValueError(problem)

    @property
    def fit_stats(self) -> dict:
        """χ²/dof, residual RMS of at-rest (static and ramp) and moving windows [°/h], LM
        steps, window count, and the degrees of freedom of the at-rest and moving windows'
        σ (`rest_dof`, `moving_dof`: windows less their leverages; fits saved before have
        none)."""
        return dict(self.stats)

    @property
    def name(self) -> str:
        """Short label used in tables."""
        return "physical"

    @property
    def extrapolates(self) -> bool:
        """`True`: physical laws in T, applied beyond the calibrated range (counted)."""
        return True

    def gyro(self) -> Gyro:
        """The fitted model gyro: fitted laws, with ideal loops (no `plant`) or the plant's
        loops and resonator constants."""
        return self._program_form().gyro()

    def parameters(self) -> dict[str, tuple[float, float]]:
        """{name: (value, standard error)} in SI units. Without a `plant`, g, cross-talk and
        (to ppm) k_e are the ideal-loop model's *effective* values, which hold the real
        loops' lag (`equations` says so): tens of σ from the physical ones on a real gyro."""
        err = np.sqrt(np.diag(np.asarray(self.covariance)))
        return {
            n: (float(v), float(e))
            for n, v, e in zip(NAMES, np.asarray(self.values), err, strict=True)
        }

    def _program_form(self) -> _FittedLaws:
        """The fitted laws as the compiled programs take them (`_FittedLaws`): what enters D,
        SF and ∂θ̂/∂T, the scale factor's table rate as an array — so every fit of one plant
        shares the programs of `drift_dph`, `scale_factor_at` and `correct` (the fit
        statistics and the table rate, static here, would make each fit compile them anew)."""
        if self.values is None:
            raise ValueError("this PhysicalCompensator is not fitted; use comp = comp.fit(data)")
        if type(self) is not PhysicalCompensator:  # a subclass may override the laws
            return self
        return _FittedLaws(
            k_e=self.k_e,
            values=self.values,
            plant=self.plant,
            sf_rate=device(np.float64(self.sf_rate), float),
            at_rate=self.sf_rate != 0.0,
        )

    def readout_temperature_sensitivity(self, theta, temperature_c):
        return self._program_form().readout_temperature_sensitivity(theta, temperature_c)

    def drift(self, theta, temperature_c):
        return self._program_form().drift(theta, temperature_c)

    def scale_factor(self, theta, temperature_c):
        return self._program_form().scale_factor(theta, temperature_c)

    def _drift_and_scale_factor(self, theta, temperature_c):
        form = self._program_form()  # a subclass (its own laws) is its own form
        if form is self:
            return AbstractCompensator._drift_and_scale_factor(self, theta, temperature_c)
        return form._drift_and_scale_factor(theta, temperature_c)

    def equations(self) -> str:
        """The fitted laws with 1σ uncertainties, as text."""
        p = self.parameters()
        f = lambda n, s=1.0, fmt=".4g": f"{p[n][0] * s:{fmt}} ± {p[n][1] * s:.2g}"
        lines = [
            f"k_e(T)      = {f('k_e0', 1, '.6f')} · (1 + ({f('k_e_tc', 1e6)}) ppm/°C · ΔT)",
            f"bias(T)     = {f('bias0', 1 / DEG_PER_H)} + ({f('bias1', 1 / DEG_PER_H)}) ΔT"
            f" + ({f('bias2', 1 / DEG_PER_H)}) ΔT²   [°/h]",
            f"Δ(1/τ)(T)   = {f('delta_inv_tau0')} 1/s · exp(({f('delta_inv_tau_lam')}) ΔT)",
            f"θ_τ(T)      = {f('theta_tau0', 1 / DEG)}° + ({f('theta_tau1', 1 / DEG)})°/°C · ΔT",
            f"g(T)        = {f('gain_mismatch0', 100)} % + ({f('gain_mismatch1', 100)}) %/°C · ΔT",
            f"cross-talk  = {f('cross_talk', 100)} %",
        ]
        if self.plant is None:
            lines.append(
                "± 1σ of the ideal-loop model. A real gyro's closed loops add a 2θ ripple ∝ Ω "
                "that this model reads as readout gain mismatch and cross-talk (and k_e to "
                "ppm): g and cross-talk are effective values; give the gyro's loops "
                "(plant=, CLI --plant) for the physical ones (docs/calibration.md, 'How far "
                "to trust the error bars')."
            )
        else:
            lines.append(
                "± 1σ of the model with the plant's PI loops (their lag modelled): physical "
                "values, given the plant's loops, ω, τ, Δω, θ_ω and χ."
            )
        return "\n".join(lines)

    def fit(
        self,
        data,
        initial: jax.Array | None | FromField = FROM_FIELD,
        *,
        key: jax.Array | None = None,
        raw: MeasuredData | None = None,
    ) -> PhysicalCompensator:
        """Fit the laws to bench data by Levenberg–Marquardt through the averaged simulator
        ([`AbstractCompensator.fit`][hrgjax.calibration.AbstractCompensator.fit]).

        **Arguments:**

        - `data`: [`hrgjax.MeasuredData`][] with static and rotation runs (the raw samples
          are needed: the simulator reproduces each run), or reduced windows with the
          samples as `raw` (the samples are then reduced again with this compensator's
          `window_s`; the windows themselves are not used).
        - `raw`: the raw samples, when `data` are windows: the session they were reduced
          from (checked, [`AbstractCompensator.fit`][hrgjax.calibration.AbstractCompensator.fit]).
        - `key`: the common interface's; not used (the fit is deterministic).
        - `initial`: *deprecated*, give `PhysicalCompensator(initial=…)`: starting values
          (order of `PARAMETERS`); default: the `initial` field.

        **Returns:** a new fitted `PhysicalCompensator` (values, covariance, stats).

        **Raises:** `RuntimeError` without float64; `TypeError` without the raw samples;
        `ValueError` for `raw` beside `MeasuredData` or not the windows' session, without
        static or rotation runs, with fewer than 3 distinct temperatures
        in the data (levels within 0.5 °C counted once; a ramp's 300-s windows count each) or
        fewer than 2 among the rotation runs — the laws in T need them, checked before the fit
        — or when the data leave parameters unidentified (a singular normal matrix; the
        message names them).
        """
        require_x64("PhysicalCompensator.fit")
        check_raw("PhysicalCompensator.fit", data, raw)
        if raw is not None:
            data = raw
        if not isinstance(data, MeasuredData):
            raise TypeError(
                "PhysicalCompensator.fit needs MeasuredData (the raw samples): pass them as "
                "data or as raw="
            )
        initial = setting(self, "initial", initial)
        _check_initial("PhysicalCompensator.fit", initial)
        windows = reduce(data, self.k_e, window_s=self.window_s)
        split_targets(windows)
        _require_law_temperatures(data, windows, self.k_e, self.window_s)
        groups = fit_groups(data, self.window_s, self.k_e)
        x0 = np.asarray(initial if initial is not None else initial_values(windows, self.k_e))
        plant = self.plant  # normalised by the field's converter (known_plant)
        if plant is not None and (problem := split_problem(
                plant, np.asarray(data["temperature_c"]), "PhysicalCompensator.plant")):  # fmt: skip
            raise ValueError(problem)
        if plant is None:
            values, steps, res, sigma, jac = fit_values(
                groups, device(x0), self.k_e, self.max_steps
            )
        else:
            measured, values = groups, x0
            for _ in range(LOOP_PASSES):
                pull = loop_pull(measured, device(values), device(self.k_e, float), plant)
                groups = less_pull(measured, pull)
                values, steps, res, sigma, jac = fit_values(groups, device(values), self.k_e,
                                                      self.max_steps)  # fmt: skip
        values, steps, jac = np.asarray(values), int(steps), np.asarray(jac) * SCALE
        weights = window_weights(groups)
        res = {k: np.asarray(v)[weights[k] > 0] for k, v in res.items()}  # real windows only
        sigma = {k: float(v) for k, v in sigma.items()}
        r = np.concatenate([res[k] / sigma[k] for k in (True, False)])
        dof = max(r.size - len(NAMES), 1)
        chi2 = float(r @ r) / dof
        cov = _covariance(jac, chi2)  # raises first where the data leave J rank-deficient
        factors, nu = t_factors(jac, weights, sigma)  # each σ from few windows: a t, widened
        cov = cov * np.outer(factors, factors)
        rest = res[True] / weights[True][weights[True] > 0]  # the windows' rates, unweighted
        stats = {
            "chi2_per_dof": chi2,
            "static_rms_dph": float(np.sqrt(np.mean(rest**2))) / DEG * 3600,
            "moving_rms_dph": sigma[False] / DEG * 3600,
            "lm_steps": int(steps),
            "n_windows": int(r.size),
            "rest_dof": float(nu[True]),
            "moving_dof": float(nu[False]),
        }
        return PhysicalCompensator(
            k_e=self.k_e,
            window_s=self.window_s,
            max_steps=self.max_steps,
            values=device(values),
            covariance=device(cov),
            stats=tuple(stats.items()),
            plant=plant,
            sf_rate=0.0 if plant is None else _mean_rotation_rate(data),
            temperature_range=(float(np.min(data["temperature_c"])),
                               float(np.max(data["temperature_c"]))),
            n_temperature_levels=int(temperature_levels(windows.temperature_c).size),
        )  # fmt: skip


def _require_law_temperatures(data: MeasuredData, windows, k_e: float, window_s: float) -> None:
    """Refuse, before the fit, data with fewer distinct temperatures than the laws in T need
    (`LAW_TEMPERATURES` in all, `ROTATION_TEMPERATURES` among the rotations). The fit sees a
    ramp (at rest, temperature moving) as `RAMP_WINDOW_S` windows, each at its own
    temperature: counted so when the runs' own levels are too few."""
    what = "the physical model's rate bias law (quadratic in T)"
    remedy = "; add runs at 3 or more temperatures (or ramps between them)"
    temperatures = windows.temperature_c
    if temperature_levels(temperatures).size < LAW_TEMPERATURES:
        ramps = reduce(data, k_e, window_s=window_s, ramp_window_s=RAMP_WINDOW_S)
        temperatures = ramps.temperature_c
    require_temperatures(temperatures, LAW_TEMPERATURES, what, remedy)
    moving = windows.temperature_c[~windows.static]
    require_temperatures(moving, ROTATION_TEMPERATURES, "the physical model's k_e(T) (linear "
                         "in T)", "; add rotation runs at another temperature",
                         where="the calibration data's rotation runs")  # fmt: skip


SINGULAR_RCOND = 1e-10
"""Smallest singular value of the fit's scaled Jacobian, relative to its largest, of an
identified parameter direction: below it JᵀJ (condition number its square, beyond 1/ε of
float64) is singular in all but rounding. The covariance comes from the SVD of J
(`_covariance`), which does not square the condition: its σ's meet the exact (JᵀJ)⁻¹ of the
same J (rational arithmetic) to 1e-10 relative at cond(J) = 4e8 and 9e-10 at 4e9, where
inverting JᵀJ gave 0.94–0.99× and 0.26–0.67× (benchmarks/precision.py); the cut is no longer
where σ's lose precision, but a direction this weak rests on the Jacobian's own accuracy."""


def _covariance(jac: np.ndarray, chi2: float) -> np.ndarray:
    """The parameters' covariance (J^T J)^-1 · χ²/dof in SI (`jac` in the scaled units of
    `SCALE`), as V diag(1/s²) Vᵀ from the SVD of J with its columns scaled to unit norm
    (never JᵀJ, whose condition number is J's squared); a one-line error naming the
    parameters the data leave unidentified when J^T J is singular (`SINGULAR_RCOND`)."""
    finite = np.all(np.isfinite(jac))
    s = np.linalg.svd(jac, compute_uv=False) if finite else np.zeros(1)
    if finite and s.size == jac.shape[1] and s[-1] > SINGULAR_RCOND * s[0]:
        norm = np.linalg.norm(jac, axis=0)  # > 0: J has full column rank
        _, s, vt = np.linalg.svd(jac / norm, full_matrices=False)
        w = vt.T / (s * norm[:, None])  # (J^T J)^-1 = w w^T
        return (w @ w.T) * chi2 * np.outer(SCALE, SCALE)
    raise ValueError(_not_identified(jac))


def _not_identified(jac: np.ndarray) -> str:
    """The message for a singular J^T J: the parameters in its null space (the right
    singular vectors below `SINGULAR_RCOND`, else the weakest one)."""
    _, s, vt = np.linalg.svd(np.nan_to_num(jac), full_matrices=True)
    s = np.concatenate([s, np.zeros(vt.shape[0] - s.size)])
    null = vt[s <= max(s.max(initial=0.0), 1e-300) * SINGULAR_RCOND]
    if not null.size:  # singular in the LU, not below the cut: the weakest direction
        null = vt[np.argmin(s)][None]
    names = [n for i, n in enumerate(NAMES) if np.max(np.abs(null[:, i])) > 0.1]
    which = ", ".join(names) if names else "some parameters"
    return (
        f"PhysicalCompensator.fit: the calibration data do not identify {which} (the fit's "
        "normal matrix JᵀJ is singular); add runs that move them — other temperatures, "
        "wave angles or table rates"
    )


def _mean_rotation_rate(data: MeasuredData) -> float:
    """Mean table rate of the moving runs [rad/s] (0 without any)."""
    rates = [float(np.mean(st.rate[i])) for st in data.stacked() for i in range(len(st))
             if not st.static[i]]  # fmt: skip
    return float(np.mean(rates)) if rates else 0.0
