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
is the Gauss–Newton $(J^\top W J)^{-1}$ scaled by the reduced χ² (≈ 1 with those weights).
Starting values come from harmonic fits at each temperature held for at least three
windows (a ramp's windows are not a level).

The compensator's D and SF follow from the fitted gyro itself: the readout map
$\theta\mapsto\hat\theta$ is inverted at the measured angle, the rest-state pattern rate comes
from the averaged vector field, and $\mathrm{SF} = (d\hat\theta/d\theta)\,k_e(T)/k_{e,\rm nom}$.
It also knows $\partial\hat\theta/\partial T$, the apparent rate a changing readout mismatch
gives while the temperature changes, which the empirical compensators cannot learn from bench
data taken at constant temperatures.
"""

from __future__ import annotations

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._compiled import Check, device, first_failure, program
from .._least_squares import least_squares_with_jacobian
from .._x64 import require_x64
from ..data import MeasuredData
from ..gyro import Gyro
from ..profiles import Profile
from ..resonator.averaged import averaged_vector_field, input_rate, measured_estimates
from ..resonator.control import Control
from ..resonator.params import Resonator, TemperatureLaw
from ..resonator.readout import Readout
from ..resonator.slow import reduced_rate
from ..simulate import simulate
from ..units import DEG, DEG_PER_H, PHYSICAL_WINDOW_S, T_REF_C
from ._compensator import FROM_FIELD, AbstractCompensator, FromField, setting, split_targets
from ._grouping import ladder, partition
from ._physical_start import initial_values
from .reduce import K_E_NOMINAL, least_squares_slope, reduce
from .reduce import RAMP_WINDOW_S as RAMP_WINDOW_S

PARAMETERS = (
    ("k_e0", "", 1e-4),
    ("k_e_tc", "1/°C", 1e-6),
    ("bias0", "rad/s", 0.01 * DEG_PER_H),
    ("bias1", "rad/s/°C", 1e-4 * DEG_PER_H),
    ("bias2", "rad/s/°C²", 1e-6 * DEG_PER_H),
    ("delta_inv_tau0", "1/s", 0.01 * DEG_PER_H),
    ("delta_inv_tau_lam", "1/°C", 1e-3),
    ("theta_tau0", "rad", 1e-2),
    ("theta_tau1", "rad/°C", 1e-4),
    ("gain_mismatch0", "", 1e-5),
    ("gain_mismatch1", "1/°C", 1e-7),
    ("cross_talk", "", 1e-5),
)
"""Fitted parameters: (name, unit, typical uncertainty used to scale the LM problem)."""
NAMES = tuple(p[0] for p in PARAMETERS)
_SCALE = np.array([p[2] for p in PARAMETERS])


MODEL_OMEGA = 2 * math.pi * 5000.0
"""Mean natural angular frequency of the model gyro [rad/s] (not fitted: with ideal loops the
averaged pattern rate does not depend on it)."""
MODEL_TAU = 640.0
"""Mean decay time of the model gyro [s] (not fitted: the ideal amplitude loop holds the
amplitude whatever τ is; the damping *anisotropy* Δ(1/τ) is fitted)."""


PLANT_RESONATOR = ("omega", "tau", "delta_omega", "theta_omega", "chi")
"""What a plant (`PhysicalCompensator(plant=…)`) gives the grey box of its resonator, held
fixed in the fit: mean frequency ω [rad/s], decay time τ [s], frequency split Δω [rad/s]
and its axis θ_ω [rad, electrical], nonlinearity χ [rad²/s²] — each a number or a
[`TemperatureLaw`][hrgjax.TemperatureLaw]. Of its loops it takes the whole `Control`."""

_LAW_FIELDS = ("p0", "p1", "p2", "lam", "t_ref")


def _as_law(x) -> TemperatureLaw:
    if isinstance(x, TemperatureLaw):
        return TemperatureLaw(*(getattr(x, f) for f in _LAW_FIELDS))
    return TemperatureLaw(x)


def known_plant(plant: Gyro | None) -> Gyro | None:
    """The part of a gyro the grey box takes as known (`PLANT_RESONATOR` and the loops), in
    one fixed layout (every such parameter a [`TemperatureLaw`][hrgjax.TemperatureLaw]) so a
    fitted compensator saves and loads; `None` stays `None` (ideal loops).

    **Raises:** `TypeError` for anything but a [`hrgjax.Gyro`][]; `ValueError` for a plant
    whose loops are ideal or open (nothing for the grey box to model: give `plant=None`)."""
    if plant is None:
        return None
    if not isinstance(plant, Gyro):
        raise TypeError(f"plant must be a hrgjax.Gyro (its loops and resonator constants) or "
                        f"None; got {type(plant).__name__}")  # fmt: skip
    ctl = plant.control
    if ctl.ideal or not ctl.enabled:
        raise ValueError("plant.control: ideal or open loops have no lag to model; give "
                         "plant=None for the ideal-loop grey box")  # fmt: skip
    res = Resonator(**{f: _as_law(getattr(plant.resonator, f)) for f in PLANT_RESONATOR})
    control = Control(
        amplitude=ctl.amplitude,
        drive=ctl.drive,
        excitation_phase=_as_law(ctl.excitation_phase),
        pll_bandwidth=ctl.pll_bandwidth,
        agc_bandwidth=ctl.agc_bandwidth,
        quadrature_bandwidth=ctl.quadrature_bandwidth,
        forcer_gain_mismatch=_as_law(ctl.forcer_gain_mismatch),
    )
    return Gyro(resonator=res, control=control, readout=Readout(), noise=None)


def plant_to_json(plant: Gyro | None) -> dict | None:
    """A `known_plant` as JSON numbers (laws as [p0, p1, p2, λ, T_ref])."""
    if plant is None:
        return None
    law = lambda x: [float(getattr(x, f)) for f in _LAW_FIELDS]
    ctl = plant.control
    return {
        "resonator": {f: law(getattr(plant.resonator, f)) for f in PLANT_RESONATOR},
        "control": {
            "amplitude": float(ctl.amplitude),
            "drive": ctl.drive,
            "excitation_phase": law(ctl.excitation_phase),
            "pll_bandwidth": float(ctl.pll_bandwidth),
            "agc_bandwidth": float(ctl.agc_bandwidth),
            "quadrature_bandwidth": float(ctl.quadrature_bandwidth),
            "forcer_gain_mismatch": law(ctl.forcer_gain_mismatch),
        },
    }


def plant_from_json(d: dict | None) -> Gyro | None:
    """Inverse of `plant_to_json`."""
    if d is None:
        return None
    law = lambda x: TemperatureLaw(*x)
    c = dict(d["control"])
    c["excitation_phase"] = law(c["excitation_phase"])
    c["forcer_gain_mismatch"] = law(c["forcer_gain_mismatch"])
    res = Resonator(**{f: law(d["resonator"][f]) for f in PLANT_RESONATOR})
    return known_plant(Gyro(resonator=res, control=Control(**c), readout=Readout(), noise=None))


def model_gyro(
    values, omega: float = MODEL_OMEGA, tau: float = MODEL_TAU, plant: Gyro | None = None
) -> Gyro:
    """The model gyro of the parameter vector `values` (order of `PARAMETERS`): with ideal
    loops, mean frequency `omega` [rad/s] and decay time `tau` [s]; or, given a `plant`
    (`known_plant`), with the plant's resonator constants (`PLANT_RESONATOR`) and its PI
    loops."""
    v = {name: values[i] for i, name in enumerate(NAMES)}
    law = lambda p0, p1=0.0, p2=0.0, lam=0.0: TemperatureLaw(p0, p1, p2, lam, T_REF_C)
    known = {"omega": omega, "tau": tau}
    if plant is not None:
        known = {f: getattr(plant.resonator, f) for f in PLANT_RESONATOR}
    res = Resonator(
        **known,
        k_e=law(v["k_e0"], v["k_e0"] * v["k_e_tc"]),
        delta_inv_tau=law(v["delta_inv_tau0"], lam=v["delta_inv_tau_lam"]),
        theta_tau=law(v["theta_tau0"], v["theta_tau1"]),
    )
    readout = Readout(
        gain_mismatch=law(v["gain_mismatch0"], v["gain_mismatch1"]), cross_talk=v["cross_talk"]
    )
    return Gyro(
        resonator=res,
        control=Control(ideal=True) if plant is None else plant.control,
        readout=readout,
        rate_bias=law(v["bias0"], v["bias1"], v["bias2"]),
    )


def readout_angle(gyro_t: Gyro, theta):
    """The readout map at one temperature: the measured pattern angle θ̂ [rad] of the true
    pattern angle `theta` [rad] under ideal loops (the amplitude at the AGC set point, no
    quadrature), `gyro_t` a gyro at that temperature (`gyro.at(T)`)."""
    a0 = gyro_t.control.amplitude
    return measured_estimates(gyro_t, a0, 0.0 * a0, theta, 0.0 * a0).theta


def true_angle(gyro_t: Gyro, theta_meas, iterations: int = 4):
    """Invert the readout map at one temperature: θ with θ̂(θ) = `theta_meas` [rad]."""
    theta = theta_meas
    for _ in range(iterations):
        theta = theta - (readout_angle(gyro_t, theta) - theta_meas)
    return theta


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
      elsewhere or from the design): the fit then models the PI loops' lag (`_loop_pull`)
      and its parameters are the physical ones; the compensator's drift and scale factor
      hold the loops ([`hrgjax.resonator.slow`][]).
    - `sf_rate`: with a plant, the table rate [rad/s] at which the scale factor takes the
      loops' lag — `fit` sets it to the calibration's mean rotation rate. The lag's 2θ
      ripple turns its phase with the rate (by 2·atan(2k_eΩ/β): 5.5° at 5 °/s with 2 rad/s
      loops), so one SF(θ, T) holds it exactly at one rate; 0: the slow-rate limit.
    - `initial`: optional starting values of `fit` (order of
      [`PARAMETERS`][hrgjax.calibration.physical.PARAMETERS], SI); `None` (default): from
      harmonic fits of the reduced drift and scale factor at each temperature. A fitted
      compensator has `None` here.
    """

    k_e: float = eqx.field(static=True, default=K_E_NOMINAL)
    window_s: float = eqx.field(static=True, default=PHYSICAL_WINDOW_S)
    max_steps: int = eqx.field(static=True, default=64)
    values: jax.Array | None = None
    covariance: jax.Array | None = None
    stats: tuple = eqx.field(static=True, default=())
    plant: Gyro | None = eqx.field(default=None, converter=known_plant)
    sf_rate: float = eqx.field(static=True, default=0.0)
    initial: jax.Array | None = None

    @property
    def fit_stats(self) -> dict:
        """χ²/dof, residual RMS of at-rest (static and ramp) and moving windows [°/h], LM
        steps, window count."""
        return dict(self.stats)

    @property
    def name(self) -> str:
        """Short label used in tables."""
        return "physical"

    def gyro(self) -> Gyro:
        """The fitted model gyro: fitted laws, with ideal loops (no `plant`) or the plant's
        loops and resonator constants."""
        if self.values is None:
            raise ValueError("this PhysicalCompensator is not fitted; use comp = comp.fit(data)")
        return model_gyro(self.values, plant=self.plant)

    def parameters(self) -> dict[str, tuple[float, float]]:
        """{name: (value, standard error)} in SI units."""
        err = np.sqrt(np.diag(np.asarray(self.covariance)))
        return {
            n: (float(v), float(e))
            for n, v, e in zip(NAMES, np.asarray(self.values), err, strict=True)
        }

    def _derivatives(self, theta_meas, temperature_c):
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
        if self.sf_rate == 0.0:
            theta_dot, d_rate = jax.jvp(rate, (w0,), (jnp.ones_like(w0),))
            return slope, theta_dot, -d_rate
        theta_dot = rate(w0)
        return slope, theta_dot, -(rate(w0 + self.sf_rate) - theta_dot) / self.sf_rate

    def readout_temperature_sensitivity(self, theta, temperature_c):
        gyro = self.gyro()
        true = true_angle(gyro.at(temperature_c), theta)
        meas = lambda temp: readout_angle(gyro.at(temp), true)
        return jax.jvp(meas, (temperature_c,), (jnp.ones_like(temperature_c),))[1]

    def drift(self, theta, temperature_c):
        slope, theta_dot, _ = self._derivatives(theta, temperature_c)
        return -slope * theta_dot / self.k_e

    def scale_factor(self, theta, temperature_c):
        slope, _, k_e = self._derivatives(theta, temperature_c)
        return slope * k_e / self.k_e

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
        - `raw`: the raw samples, when `data` are windows.
        - `key`: the common interface's; not used (the fit is deterministic).
        - `initial`: *deprecated*, give `PhysicalCompensator(initial=…)`: starting values
          (order of `PARAMETERS`); default: the `initial` field.

        **Returns:** a new fitted `PhysicalCompensator` (values, covariance, stats).

        **Raises:** `RuntimeError` without float64; `TypeError` without the raw samples;
        `ValueError` without static or rotation runs.
        """
        require_x64("PhysicalCompensator.fit")
        if raw is not None:
            data = raw
        if not isinstance(data, MeasuredData):
            raise TypeError(
                "PhysicalCompensator.fit needs MeasuredData (the raw samples): pass them as "
                "data or as raw="
            )
        initial = setting(self, "initial", initial)
        windows = reduce(data, self.k_e, window_s=self.window_s)
        split_targets(windows)
        groups = _groups(data, self.window_s, self.k_e)
        x0 = np.asarray(initial if initial is not None else initial_values(windows, self.k_e))
        plant = self.plant  # normalised by the field's converter (known_plant)
        if plant is None:
            values, steps, res, sigma, jac = _fit(groups, device(x0), self.k_e, self.max_steps)
        else:
            measured, values = groups, x0
            for _ in range(LOOP_PASSES):
                pull = _loop_pull(measured, device(values), self.k_e, plant)
                groups = _less_pull(measured, pull)
                values, steps, res, sigma, jac = _fit(groups, device(values), self.k_e,
                                                      self.max_steps)  # fmt: skip
        values, steps, jac = np.asarray(values), int(steps), np.asarray(jac) * _SCALE
        weights = _weights(groups)
        res = {k: np.asarray(v)[weights[k] > 0] for k, v in res.items()}  # real windows only
        sigma = {k: float(v) for k, v in sigma.items()}
        r = np.concatenate([res[k] / sigma[k] for k in (True, False)])
        dof = max(r.size - len(NAMES), 1)
        chi2 = float(r @ r) / dof
        cov = np.linalg.inv(jac.T @ jac) * chi2 * np.outer(_SCALE, _SCALE)
        rest = res[True] / weights[True][weights[True] > 0]  # the windows' rates, unweighted
        stats = {
            "chi2_per_dof": chi2,
            "static_rms_dph": float(np.sqrt(np.mean(rest**2))) / DEG * 3600,
            "moving_rms_dph": sigma[False] / DEG * 3600,
            "lm_steps": int(steps),
            "n_windows": int(r.size),
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
        )


def _mean_rotation_rate(data: MeasuredData) -> float:
    """Mean table rate of the moving runs [rad/s] (0 without any)."""
    rates = [float(np.mean(st.rate[i])) for st in data.stacked() for i in range(len(st))
             if not st.static[i]]  # fmt: skip
    return float(np.mean(rates)) if rates else 0.0


WEIGHT_WINDOW_S = 60.0
"""Window length [s] the at-rest residual scatter is referred to: an at-rest window of
length L is weighted by √(L / 60 s) / σ (white rate noise: variance ∝ 1/L)."""


SHARED_LENGTH_RUNS = 4
"""A run length shared by at least this many runs (of one sample interval) gets a compiled
group of its own; rarer lengths are padded up to the next power of two of samples and
share one — a plan of 44 different segment lengths compiles 5 groups, not 44. The padded
tail is simulated and masked out of every window: it costs run time (≤ 2×, on a simulator
that runs in seconds) and saves compiling (about 3–4 s per group for the simulator, more
for the fit's Jacobian program: a 12-h designed plan's first calibration 109–119 → 58–65 s;
`benchmarks/README.md`). Neighbouring lengths are then run as one group where that is
cheaper than compiling another (`_merged`: 7 groups → 3, first fit 49.0 → 21.4 s)."""


FIT_COMPILE_S = 6.0
"""Seconds one group adds to compiling the fit's residual-and-Jacobian program (2-core CPU,
`benchmarks/fit_group_layouts.py`: a 12-h designed plan's 7, 3 and 2 groups 46.8, 22.4 and
16.1 s) — what running two groups of run lengths as one saves (`_merged`)."""

FIT_EVALUATIONS = 40.0
"""Residual-and-Jacobian evaluations per compile, as `_merged` weighs them against compiling:
a fit makes ≈ 12 (its Levenberg–Marquardt steps, the weights, the covariance); this counts
three fits per session."""

FIT_MERGED_STEPS_MAX = 2**13
"""Estimated solver steps beyond which `_merged` merges no further."""

FIT_STEP_S = (1e-6, 1.5e-6)
"""Seconds per solver step of one evaluation of a group's residuals and Jacobian, fixed + per
run (2-core CPU, fitted to a 12-h designed plan's layouts of 7 and 2 groups; measured by
`benchmarks/fit_group_layouts.py`: 80, 131 and 410 ms per evaluation for 7, 3 and 2)."""


def steps_estimate(seconds: float, rate_rad_s: float) -> float:
    """Accepted steps of the averaged model over `seconds` at a table rate [rad/s]
    (`hrgjax._cost.steps_per_s` at the nominal angular gain)."""
    from .._cost import steps_per_s

    return seconds * steps_per_s(abs(rate_rad_s) * K_E_NOMINAL)


def _extend(x: np.ndarray, length: int, linear: bool) -> np.ndarray:
    """(R, N, …) → (R, length, …): continued linearly from the last two samples (`linear`)
    or held at the last."""
    n = x.shape[1]
    if n == length:
        return x
    k = np.arange(1, length - n + 1, dtype=float).reshape((1, -1) + (1,) * (x.ndim - 2))
    step = x[:, -1:] - x[:, -2:-1] if linear else 0.0 * x[:, -1:]
    return np.concatenate([x, x[:, -1:] + k * step], axis=1)


def _knots(n: int, length: int, step: int, count: int) -> np.ndarray:
    """`count` knot indices of a run of `n` samples padded to `length`: every `step` samples
    and its last sample (so the profile on the run itself is the unpadded one), then as many
    more as `count` asks, in the padded tail first, else in the widest gaps."""
    knots = set(np.arange(0, n, step).tolist()) | {n - 1}
    if length > n:
        knots.add(length - 1)
    while len(knots) < count:
        k = np.array(sorted(knots))
        gaps = np.diff(k)
        tail = k[1:] > n - 1
        pick = np.where(tail & (gaps > 1), gaps, 0)
        if not pick.any():
            pick = np.where(gaps > 1, gaps, 0)
        i = int(np.argmax(pick))
        knots.add(int(k[i] + gaps[i] // 2))
    return np.array(sorted(knots))


class _Group(eqx.Module):
    """Runs of one padded length and sample interval, stacked for one vmap of the
    simulator. Static runs are reduced as one window, moving runs as windows of `window_s`
    (`n_move` samples), ramps (at rest, the temperature moving) as windows of
    `RAMP_WINDOW_S` (`n_ramp` samples; the last may be partial); windows past a run's own
    end carry zero weight."""

    t: jax.Array  # (R, L) sample times [s], padded
    theta0: jax.Array  # (R,) measured initial angle [rad]
    t_knots: jax.Array  # (R, K) profile knots [s]
    rate: jax.Array  # (R, K) [rad/s]
    temperature: jax.Array  # (R, K) [°C]
    accel: jax.Array  # (R, K, 3) [g]
    measured_static: jax.Array  # (Rs,) window rates [rad/s]
    static_mask: jax.Array  # (Rs, L) 1 on the run's own samples
    static_weight: jax.Array  # (Rs,) √(window length / WEIGHT_WINDOW_S)
    measured_moving: jax.Array  # (Rm, Wm)
    moving_valid: jax.Array  # (Rm, Wm) 1 for whole windows inside the run
    measured_ramp: jax.Array  # (Rr, Wr)
    ramp_mask: jax.Array  # (Rr, L)
    ramp_weight: jax.Array  # (Rr, Wr) √(window length / 60 s), 0 for windows < 4 samples
    static_idx: tuple = eqx.field(static=True)
    moving_idx: tuple = eqx.field(static=True)
    ramp_idx: tuple = eqx.field(static=True)
    n_move: int = eqx.field(static=True)
    n_ramp: int = eqx.field(static=True)


def _windows(xp, a, n: int, partial: bool):
    """(R, L) → (R, W, n): consecutive windows of `n` samples; the samples past the last
    whole window dropped, or (`partial`) kept in one more window padded with zeros."""
    r, length = a.shape
    w = -(-length // n) if partial else length // n
    if w * n > length:
        a = xp.concatenate([a, xp.zeros((r, w * n - length), dtype=a.dtype)], axis=1)
    return a[:, : w * n].reshape(r, w, n)


def _masked_slopes(xp, t, y, mask, n, partial=False):
    """Least-squares slopes of `y` over consecutive windows of `n` samples of (R, L) arrays
    (`_windows`), each over its samples with `mask` 1 (`reduce`'s slope); (R, W). Windows
    without 2 such samples give 0."""
    t, y, m = (_windows(xp, a, n, partial) for a in (t, y, mask))
    return least_squares_slope(xp, t, y, m)[0]


def _groups(data: MeasuredData, window_s: float, k_e: float) -> list[_Group]:
    stacks = data.stacked()
    for stack in stacks:
        if stack.n_samples < 4:
            raise ValueError(
                f"run {int(stack.run[0])} has {stack.n_samples} samples; reduction needs at "
                "least 4 per window"
            )
    buckets: dict[tuple[int, float], list] = {}
    short: set[tuple[int, float]] = set()
    for stack in stacks:
        n = stack.n_samples
        # runs shorter than a moving window keep their length (reduced as one window)
        is_short = n < max(int(round(window_s / stack.dt)), 4)
        length = n if is_short or len(stack) >= SHARED_LENGTH_RUNS else ladder(n)
        key = (length, round(stack.dt, 9))
        buckets.setdefault(key, []).append(stack)
        if is_short:
            short.add(key)
    return [_group(stacks, length, window_s, k_e) for length, stacks in _merged(buckets, short)]


def _merged(buckets, short) -> list[tuple[int, list]]:
    """Buckets of one sample interval, sorted by length, run as one group (padded to the
    longest) where compiling another group's simulator and Jacobian (`FIT_COMPILE_S`) costs
    more than the steps the shorter runs are simulated on for over a fit's evaluations
    (`FIT_EVALUATIONS`, each with its tangents); runs shorter than a window stay apart."""
    out = []
    for dt in sorted({dt for _, dt in buckets}):
        keys = sorted(k for k in buckets if k[1] == dt)

        def cost(i, j, keys=keys, dt=dt):
            if any(k in short for k in keys[i:j]) and j - i > 1:
                return math.inf
            stacks = [st for k in keys[i:j] for st in buckets[k]]
            rows = sum(len(st) for st in stacks)
            rate = max(float(np.max(np.abs(st.rate))) for st in stacks)
            steps = steps_estimate((keys[j - 1][0] - 1) * dt, rate)
            if j - i > 1 and steps > FIT_MERGED_STEPS_MAX:
                return math.inf
            run = steps * (FIT_STEP_S[0] + rows * FIT_STEP_S[1])
            return FIT_COMPILE_S + FIT_EVALUATIONS * run

        for i, j in partition(len(keys), cost):
            out.append((keys[j - 1][0], [st for k in keys[i:j] for st in buckets[k]]))
    return out


def _group(stacks, length: int, window_s: float, k_e: float) -> _Group:
    """One `_Group` of `stacks` (same sample interval) padded to `length` samples."""
    dt = stacks[0].dt
    n_move = min(max(int(round(window_s / dt)), 4), length)
    n_ramp = min(max(int(round(RAMP_WINDOW_S / dt)), 4), length)
    rows = []  # per run: (n, t, theta, rate, temperature, accel, kind)
    for st in stacks:
        ramp = st.static & (np.ptp(st.temperature, axis=1) > 0.0)
        kind = np.where(~st.static, "moving", np.where(ramp, "ramp", "static"))
        ext = (
            _extend(st.t, length, True),
            _extend(st.wave_angle, length, False),
            _extend(st.rate, length, False),
            _extend(st.temperature, length, True),
            _extend(st.accel, length, False),
        )
        rows += [(st.n_samples, *(a[i] for a in ext), kind[i]) for i in range(len(st))]
    # knots: every window's start (the shortest window any run here is cut into) and the end
    kinds = {r[-1] for r in rows}
    step = min([length - 1] + [n_move] * ("moving" in kinds) + [n_ramp] * ("ramp" in kinds))
    count = max(_knots(r[0], length, step, 0).size for r in rows)
    knots = np.stack([_knots(r[0], length, step, count) for r in rows])
    t = np.stack([r[1] for r in rows])
    theta = np.stack([r[2] for r in rows])
    n_of = np.array([r[0] for r in rows])
    own = (np.arange(length)[None, :] < n_of[:, None]).astype(float)  # (R, L)
    pick = lambda a: np.stack([r[a][k] for r, k in zip(rows, knots, strict=True)])
    idx = {k: np.array([i for i, r in enumerate(rows) if r[-1] == k], int) for k in kinds}
    idx = {k: idx.get(k, np.zeros(0, int)) for k in ("static", "moving", "ramp")}
    s, m, r = idx["static"], idx["moving"], idx["ramp"]
    # moving: whole windows inside the run (as `reduce`); ramps: windows tiling the run,
    # the last partial one kept when it has ≥ 4 samples
    n_whole = n_of[m] // n_move
    moving_valid = (np.arange(length // n_move)[None, :] < n_whole[:, None]).astype(float)
    in_win = _windows(np, own[r], n_ramp, True).sum(axis=-1)
    ramp_weight = np.where(in_win >= 4, np.sqrt(np.maximum(in_win - 1, 0) * dt / WEIGHT_WINDOW_S),
                           0.0)  # fmt: skip
    slopes = lambda sel, mask, n, p=False: -_masked_slopes(np, t[sel], theta[sel], mask, n, p) / k_e
    return _Group(
        t=device(t),
        theta0=device(theta[:, 0]),
        t_knots=device(np.take_along_axis(t, knots, axis=1)),
        rate=device(pick(3)),
        temperature=device(pick(4)),
        accel=device(pick(5)),
        measured_static=device(slopes(s, own[s], length)[:, 0]),
        static_mask=device(own[s]),
        static_weight=device(np.sqrt((n_of[s] - 1) * dt / WEIGHT_WINDOW_S)),
        measured_moving=device(slopes(m, own[m], n_move) * moving_valid),
        moving_valid=device(moving_valid),
        measured_ramp=device(slopes(r, own[r], n_ramp, True) * (ramp_weight > 0)),
        ramp_mask=device(own[r]),
        ramp_weight=device(ramp_weight),
        static_idx=tuple(s.tolist()),
        moving_idx=tuple(m.tolist()),
        ramp_idx=tuple(r.tolist()),
        n_move=n_move,
        n_ramp=n_ramp,
    )


def _weights(groups) -> dict:
    """Host arrays in `_residuals`' order: {True: each at-rest residual's √(length / 60 s)
    (0: no window), False: 1 for a moving window inside its run, else 0}."""
    rest, moving = [], []
    for g in groups:
        rest += [np.asarray(g.static_weight), np.asarray(g.ramp_weight).ravel()]
        moving += [np.asarray(g.moving_valid).ravel()]
    return {True: np.concatenate(rest), False: np.concatenate(moving)}


def _simulated_rates(group: _Group, values, k_e: float, plant=None):
    """Simulated window rates (static (Rs,), moving (Rm, Wm), ramp (Rr, Wr)) [rad/s] of one
    group, reduced as the measured ones; ideal loops, or the `plant`'s PI loops."""
    gyro = model_gyro(values, plant=plant)

    def one(t, theta0, t_knots, rate, temp, acc):
        theta_start = true_angle(gyro.at(temp[0]), theta0)
        prof = Profile(t=t_knots, rate=rate, temperature=temp, accel=acc,
                       wave_angle0=theta_start)  # fmt: skip
        rec = simulate(gyro, prof, ts=t, adjoint=diffrax.ForwardMode(), rtol=1e-9, atol=1e-12)
        return rec.wave_angle

    theta = jax.vmap(one)(group.t, group.theta0, group.t_knots, group.rate, group.temperature,
                          group.accel)  # fmt: skip
    length = group.t.shape[1]

    def slopes(idx, mask, n, partial=False):
        idx = np.asarray(idx, int)
        return -_masked_slopes(jnp, group.t[idx], theta[idx], mask, n, partial) / k_e

    static = slopes(group.static_idx, group.static_mask, length)[:, 0]
    moving_mask = jnp.ones((len(group.moving_idx), length))
    moving = slopes(group.moving_idx, moving_mask, group.n_move) * group.moving_valid
    ramp = slopes(group.ramp_idx, group.ramp_mask, group.n_ramp, True)
    return static, moving, ramp


def _residuals(groups, values, k_e):
    """{True: at-rest residuals (static and ramp windows, each × √(length / 60 s)),
    False: moving residuals} [rad/s], measured − simulated; 0 where there is no window."""
    sims = [_simulated_rates(g, values, k_e) for g in groups]
    rest, moving = [], []
    for g, (s, mv, r) in zip(groups, sims, strict=True):
        rest += [(g.measured_static - s) * g.static_weight]
        rest += [((g.measured_ramp - r) * g.ramp_weight).ravel()]
        moving += [(g.measured_moving - mv).ravel()]
    return {True: jnp.concatenate(rest), False: jnp.concatenate(moving)}


LOOP_PASSES = 2
"""Times a fit with a plant computes the loops' pull (`_loop_pull`) and fits: at the starting
values, then at the first fit's values (the pull is ≈ 3e-5 of the rate and changes with the
fitted values at that order: a second pass leaves nothing the data can see)."""


@program(check=Check("PhysicalCompensator.fit (the PI loops' pull)"))
def _loop_pull(groups, values, k_e, plant):
    """What the plant's PI loops add to every window rate (static, moving, ramp) [rad/s]
    beyond the ideal-loop model at `values`: the same runs simulated both ways. Subtracted
    from the measured rates, it lets the fit run the ideal-loop model (cheap: the PI loops
    take ≈ 20× the ideal loops' time per run, `benchmarks/physical_plant.py`) and still fit the
    physical parameters."""
    out = []
    for g in groups:
        pi = _simulated_rates(g, values, k_e, plant)
        ideal = _simulated_rates(g, values, k_e)
        out.append(tuple(a - b for a, b in zip(pi, ideal, strict=True)))
    return out


def _less_pull(groups, pull):
    """The groups with the loops' pull taken off their measured window rates."""
    out = []
    for g, (s, mv, r) in zip(groups, pull, strict=True):
        out.append(eqx.tree_at(
            lambda x: (x.measured_static, x.measured_moving, x.measured_ramp), g,
            (g.measured_static - s, g.measured_moving - mv * g.moving_valid,
             g.measured_ramp - jnp.where(g.ramp_weight > 0, r, 0.0)),
        ))  # fmt: skip
    return out


@program(check=Check("PhysicalCompensator.fit (residuals and Jacobian)"))
def _residuals_jacobian(groups, values, k_e):
    """Residuals {True: static, False: moving} [rad/s] at `values` and their Jacobians with
    respect to the scaled parameters x (values + x·scale). The fit's one simulator program:
    it serves the weights, every Levenberg–Marquardt step and the covariance."""
    fn = lambda x: _residuals(groups, values + x * _SCALE, k_e)
    return fn(jnp.zeros(len(NAMES))), jax.jacfwd(fn)(jnp.zeros(len(NAMES)))


def _scatter(residuals, weights) -> dict:
    """Robust scatter (1.4826 × median absolute deviation) of each kind of residual, over
    the real windows (`_weights` > 0)."""
    out = {}
    for kind, r in residuals.items():
        r = np.asarray(r)[weights[kind] > 0]
        out[kind] = float(1.4826 * np.median(np.abs(r - np.median(r))))
    return out


def scatter_per_dof(residuals, jac, weights, iterations: int = 4) -> dict:
    """Residual scatter of each kind of window (at rest, moving) at the solution, each kind
    with its own degrees of freedom: σ_k² = Σ r_k² / (n_k − p_k), where p_k is the sum of
    the leverages (the hat matrix's diagonal of the σ-weighted Jacobian) over kind k's rows
    (Σ_k p_k = the number of parameters). A plain RMS would take σ of a kind whose few
    windows carry most of the parameters (the at-rest windows of a small plan) too small,
    and every error bar with it. The leverages depend on the σ's: a few fixed-point
    iterations from the RMS."""
    kinds = (True, False)
    real = {k: weights[k] > 0 for k in kinds}
    r = {k: np.asarray(residuals[k])[real[k]] for k in kinds}
    j = {k: np.asarray(jac[k])[real[k]] for k in kinds}
    n = {k: r[k].size for k in kinds}
    sigma = {k: np.sqrt(np.mean(r[k] ** 2)) for k in kinds}
    if not all(np.isfinite(s) and s > 0 for s in sigma.values()):
        return sigma  # noise-free (or degenerate) data: nothing to correct
    for _ in range(iterations):
        q, _ = np.linalg.qr(np.concatenate([j[k] / sigma[k] for k in kinds]))
        leverage = np.sum(q**2, axis=1)
        p = {True: leverage[: n[True]].sum(), False: leverage[n[True] :].sum()}
        sigma = {k: np.sqrt(np.sum(r[k] ** 2) / max(n[k] - p[k], 1.0)) for k in kinds}
    return sigma


def _fit(groups, x0, k_e, max_steps):
    """Weights, Levenberg–Marquardt (one compiled step at a time, with a progress bar),
    final residuals and Jacobian.

    Weights: the residual scatter of each kind of window (at rest, moving) at the starting
    values (robust: median absolute deviation; the harmonic start is close), re-estimated
    after the fit for the covariance. The solver is optimistix's Levenberg–Marquardt, fed
    the residuals and Jacobian of `_residuals_jacobian` at each point it evaluates
    (`least_squares_with_jacobian`), so the simulator is compiled once per fit, not twice."""
    weights = _weights(groups)
    x0 = np.asarray(x0)
    at = {}  # host copies of the last evaluation: {True/False: residuals}, Jacobians

    def weighted(x):
        # Host arithmetic between the compiled programs (eager jnp would compile each op).
        r, jac = _residuals_jacobian(groups, device(x0 + np.asarray(x) * _SCALE), k_e)
        at["r"], at["jac"] = {k: np.asarray(v) for k, v in r.items()}, jac
        if "sigma" not in at:  # the first call: at the starting values
            at["sigma"] = _scatter(at["r"], weights)
        sigma = at["sigma"]
        kinds = (True, False)
        r_w = np.concatenate([at["r"][k] / sigma[k] for k in kinds])
        jac_w = np.concatenate([np.asarray(jac[k]) / sigma[k] for k in kinds])
        return device(r_w), device(jac_w)

    # The problem is scaled so that one unit of x is about one standard error: stopping at
    # 1e-4 of that is far below anything the data can tell. Absolute only: a tolerance
    # relative to x stops a fit that started far (|x| in the hundreds) a fraction of a
    # standard error short of the optimum.
    x, steps, result, _ = least_squares_with_jacobian(
        weighted,
        optx.LevenbergMarquardt(rtol=0.0, atol=1e-4),
        device(np.zeros(len(NAMES))),
        max_steps=max_steps,
        desc="physical fit (Levenberg–Marquardt)",
    )
    message = first_failure(result, optx.RESULTS)
    if message is not None:
        raise RuntimeError(f"PhysicalCompensator.fit: Levenberg–Marquardt failed: {message}")
    values = x0 + np.asarray(x) * _SCALE
    # `least_squares_with_jacobian` evaluated last at the solution: `at` holds it, unweighted.
    r1, jac1 = at["r"], at["jac"]
    sigma1 = scatter_per_dof(r1, {k: np.asarray(v) for k, v in jac1.items()}, weights)
    jac = np.concatenate(
        [np.asarray(jac1[True]) / sigma1[True], np.asarray(jac1[False]) / sigma1[False]]
    )
    return values, steps, r1, sigma1, jac / np.asarray(_SCALE)[None, :]
