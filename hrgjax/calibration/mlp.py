r"""`MLPCompensator`: the seed's neural compensator (one hidden layer, Rprop).

Two `eqx.nn.MLP`s with one tanh hidden layer, 30 neurons for the drift and 20 for the scale
factor (MISSION.md §1), map (wave angle, temperature) to D and SF. Inputs and outputs are
normalised; the angle enters either as the seed did (`encoding="angle"`: θ folded to
[−90°, 90°) and scaled to [−1, 1)) or, by default, periodically (`encoding="periodic"`:
cos 2θ, sin 2θ), which makes the 180° period exact and removes the seam at ±90°.

With `st_width > 0` a third network models the readout's temperature sensitivity
s_T(θ, T) = ∂θ̂/∂T, the apparent rate −s_T Ṫ/k_e that a changing temperature adds (the
term of [`corrected_rate`][hrgjax.calibration.AbstractCompensator.corrected_rate] that the
seed's networks, and any bench at constant temperatures, cannot see). It is learnt jointly
with the drift from the at-rest windows of **ramps** (the table at rest, the temperature
moving: `reduce(…, ramp_window_s=RAMP_WINDOW_S)`), whose measured rate is
D(θ, T) − s_T(θ, T) Ṫ/k_e; fitting it needs such data (`fit` says so when there is none).

Training is full-batch resilient backpropagation (`optax.rprop`), run as equal blocks of one
compiled `lax.scan` with a progress bar between blocks:

- `mode="reduced"`: on the reduced targets (drift on static windows; then SF on rotation
  windows with that drift removed), as in the seed — but a rotation window's rate is the
  average of the rate over the arc the wave turns in it, so the networks' model of it is
  their output averaged over that arc (`ARC_NODES` quadrature nodes of the least-squares
  slope's weight, `hrgjax.calibration._window_arc`), the drift removed likewise. Read as
  point values (the seed), the 2θ scale-factor ripple came out 0.97 of the truth at 20 °/s,
  0.80 at 50 °/s; now 0.9995 and 0.988 (0.9987 after 1000 steps). Static windows turn by
  the drift alone (1 °/h: 0.05° in 300 s): their value at the mean angle;
- `mode="end_to_end"`: from the reduced fit, both networks are trained on the **angle
  error** of every run at every window edge, the compensated rate integrated over every
  sample interval's arc as `correct` does ([`end_to_end_loss`][hrgjax.calibration.mlp.end_to_end_loss]).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_key, concrete_value
from .._compiled import device, program
from .._x64 import require_x64
from ..data import MeasuredData
from ..nn.train import check_fit_data, rprop_with_progress
from ..units import DEG
from ._compensator import (
    FROM_FIELD,
    AbstractCompensator,
    FromField,
    as_levels,
    as_range,
    check_number,
    check_whole,
    domain_of,
    fit_windows,
    require_temperatures,
    setting,
    setting_field,
)
from ._correction import NODES, arc_rule, integrate_arcs
from ._raw import check_raw
from ._window_arc import arc_mean, arc_rows, bin_windows, window_arc, window_average
from .reduce import K_E_NOMINAL, RAMP_WINDOW_S, WINDOW_S, RateWindows, check_k_e, check_window

ENCODINGS = ("periodic", "angle")
MODES = ("reduced", "end_to_end")
ST_RATE_REF = 1.0 / 60.0
"""Temperature rate [°C/s] (1 °C/min) at which the s_T network's unit output moves the
measured rate by one drift scale: s_T = drift_scale · k_e / ST_RATE_REF · st_net(x)."""
MIN_RAMP_RATE = 1e-3
"""Smallest |Ṫ| [°C/s] (0.06 °C/min) of a window that counts as a ramp's."""
CURVATURE_POINTS = 64
"""Points (θ, T) of the smoothness prior in T (`curvature_points`). Fitted on 0/20/40 °C,
with 32 or 48 the +20 °C rotation error rose up to 1.7× or 1.4× (docs/calibration.md)."""
MIN_TEMPERATURES = 2
"""Distinct temperatures (levels within 0.5 °C counted once) `MLPCompensator.fit` needs
among the static and among the rotation runs. At one level the normalised temperature input
is the same for every training point, so the first layer's temperature weights keep their
random initial values: fitted at +20 °C only, the rotation error 1 °C away was 60× the one
at +20 °C, 10 °C away 110× (docs/calibration.md). Two levels are the least that make the
networks see T move; between levels the smoothness prior (`drift_t_curvature`,
`sf_t_curvature`) keeps them near their at-level error, beyond them is another matter
(docs/calibration.md: `correct` counts samples outside the calibrated range)."""


_WHO = "MLPCompensator"


class MLPCompensator(AbstractCompensator):
    """Neural drift and scale-factor model (module docstring).

    **Arguments:**

    - `drift_width`, `sf_width`: hidden neurons (30 and 20 in the seed).
    - `encoding`: `"periodic"` (cos 2θ, sin 2θ, T) or `"angle"` (folded θ, T; the seed's).
    - `steps`: Rprop iterations for the reduced fit; `e2e_steps` for end-to-end training.
    - `learning_rate`: Rprop's initial step size.
    - `bin_deg`: the scale-factor targets are averaged in cells of one temperature level
      (window temperatures within 0.5 °C are one level, as the fits count them) and
      `bin_deg` of wave angle (the seed's grid: one target per point); the cell's inputs
      are the circular mean of its windows' angles and their mean temperature.
    - `k_e`: nominal angular gain.
    - `st_width`: hidden neurons of the readout temperature-sensitivity network s_T(θ, T)
      (0, the default: none, the seed's MLP; see the module docstring).
    - `drift_t_curvature`, `sf_t_curvature`: weights of the smoothness prior in temperature (0:
      none, the seed's training): the drift (and s_T) and the scale-factor losses get weight ·
      mean (∂²y/∂τ²)² added, y the network's normalised output, τ = (T − t_centre)/t_scale, over
      `CURVATURE_POINTS` points (θ, T) spread over the calibrated range (no data needed there).
      Without it the networks wiggle between sparse levels: fitted on 0/20/40 °C, the rotation
      error at +10 and +30 °C was 9.5–19× the largest at the levels; with the defaults (10⁻³,
      0.1) 0.84–1.12×. The drift's weight is the smaller: its laws curve in T (an exponential
      amplitude), and 10⁻² raised its at-level static error up to 2.2×. In τ a law's own
      curvature grows with t_scale²: on −40/+20/+60 °C the at-level rotation error rose 1.6–12×
      (between levels it fell 6–24×; weights in °C, × (20 °C/t_scale)⁴, were worse overall:
      docs/calibration.md). `mode="end_to_end"` refines without it.
    - `drift_net`, `sf_net`, `st_net`, and the normalisation (`t_centre`, `t_scale` [°C];
      `drift_offset`, `drift_scale` [rad/s]; `sf_offset`, `sf_scale`): set by `fit`.
    - `mode`: how `fit` trains, `"reduced"` or `"end_to_end"` (module docstring).
    - `window_s`: rotation-run window [s] of the reduction when `fit` is given
      `MeasuredData`, and of the end-to-end loss.
    - `temperature_range` ((T_min, T_max) [°C]) and `n_temperature_levels`: the
      calibration windows' temperature span and level count, set by `fit` (`None`: unknown;
      [`correct`][hrgjax.calibration.AbstractCompensator.correct] applies the network
      beyond it and counts those samples — there its error went either way: fitted on
      0…40 °C, at +60 °C its static drift 5× below raw, its rotation error 3.2× above;
      `extrapolate=False` passes them through).

    **Raises:** `ValueError`, one line naming the field, when built with an unknown
    `encoding` or `mode`, `drift_width`, `sf_width` or `steps` not a whole number ≥ 1,
    `st_width` or `e2e_steps` not a whole number ≥ 0 (`e2e_steps` ≥ 1 with
    `mode="end_to_end"`), `learning_rate` or `bin_deg` not finite and > 0,
    `drift_t_curvature` or `sf_t_curvature` not finite and ≥ 0, `window_s` neither `None`
    nor finite and > 0, or `k_e` outside (0, 1].
    """

    drift_width: int = setting_field(_WHO, "drift_width", 30)
    sf_width: int = setting_field(_WHO, "sf_width", 20)
    encoding: str = eqx.field(static=True, default="periodic")
    steps: int = setting_field(_WHO, "steps", 3000)
    learning_rate: float = setting_field(_WHO, "learning_rate", 1e-3)
    bin_deg: float = setting_field(_WHO, "bin_deg", 5.0)
    e2e_steps: int = setting_field(_WHO, "e2e_steps", 200)
    k_e: float = setting_field(_WHO, "k_e", K_E_NOMINAL)
    st_width: int = setting_field(_WHO, "st_width", 0)
    drift_t_curvature: float = setting_field(_WHO, "drift_t_curvature", 1e-3)
    sf_t_curvature: float = setting_field(_WHO, "sf_t_curvature", 0.1)
    drift_net: eqx.nn.MLP | None = None
    sf_net: eqx.nn.MLP | None = None
    st_net: eqx.nn.MLP | None = None
    t_centre: jax.Array = eqx.field(converter=jnp.asarray, default=20.0)
    t_scale: jax.Array = eqx.field(converter=jnp.asarray, default=50.0)
    drift_offset: jax.Array = eqx.field(converter=jnp.asarray, default=0.0)
    drift_scale: jax.Array = eqx.field(converter=jnp.asarray, default=1.0)
    sf_offset: jax.Array = eqx.field(converter=jnp.asarray, default=1.0)
    sf_scale: jax.Array = eqx.field(converter=jnp.asarray, default=1.0)
    mode: str = eqx.field(static=True, default="reduced")
    window_s: float | None = setting_field(_WHO, "window_s", WINDOW_S)
    temperature_range: tuple[float, float] | None = eqx.field(
        static=True, default=None, converter=as_range
    )
    n_temperature_levels: int | None = eqx.field(static=True, default=None, converter=as_levels)
    TRAINING_FIELDS = ("steps", "learning_rate", "bin_deg", "e2e_steps", "drift_t_curvature",
                       "sf_t_curvature", "mode", "window_s")  # fmt: skip

    def __check_init__(self):
        check_k_e(self.k_e)
        who = "MLPCompensator"
        if self.encoding not in ENCODINGS:
            raise ValueError(f"{who}: encoding must be one of {ENCODINGS}; got {self.encoding!r}")
        if self.mode not in MODES:
            raise ValueError(f"{who}: mode must be one of {MODES}; got {self.mode!r}")
        check_whole(who, "drift_width", self.drift_width, 1, " (hidden neurons)")
        check_whole(who, "sf_width", self.sf_width, 1, " (hidden neurons)")
        check_whole(who, "st_width", self.st_width, 0, " (0: no s_T network)")
        check_whole(who, "steps", self.steps, 1, " (Rprop iterations)")
        e2e = self.mode == "end_to_end"
        check_whole(who, "e2e_steps", self.e2e_steps, 1 if e2e else 0,
                    " with mode='end_to_end'" if e2e else " (Rprop iterations)")  # fmt: skip
        check_number(who, "learning_rate", self.learning_rate, " (Rprop's initial step)",
                     minimum=0.0, strict=True)  # fmt: skip
        for name in ("drift_t_curvature", "sf_t_curvature"):
            check_number(who, name, getattr(self, name), " (0: no smoothness prior in T)",
                         minimum=0.0)  # fmt: skip
        check_number(who, "bin_deg", self.bin_deg, " [° of wave angle]", minimum=0.0, strict=True)
        check_window(who, self.window_s)

    @property
    def name(self) -> str:
        """Short label used in tables."""
        return "MLP+Ṫ" if self.st_width else "MLP"

    @property
    def in_size(self) -> int:
        """Number of network inputs (3 periodic, 2 seed-style)."""
        return 3 if self.encoding == "periodic" else 2

    def features(self, theta, temperature_c, xp=jnp):
        """Normalised network input for one point: θ [rad, electrical], T [°C] (or, with
        `xp=np`, for NumPy arrays of points: shape (..., `in_size`))."""
        centre, scale = self.t_centre, self.t_scale
        if xp is np:  # NumPy throughout (a jax scalar would turn the arithmetic eager-jax)
            centre, scale = float(centre), float(scale)
        tn = (temperature_c - centre) / scale
        if self.encoding == "periodic":
            return xp.stack([xp.cos(2 * theta), xp.sin(2 * theta), tn], axis=-1)
        folded = (theta + xp.pi / 2) % xp.pi - xp.pi / 2
        return xp.stack([folded / (xp.pi / 2), tn], axis=-1)

    def drift(self, theta, temperature_c):
        if self.drift_net is None:
            raise ValueError("this MLPCompensator is not fitted; use comp = comp.fit(data, key=…)")
        x = self.features(theta, temperature_c)
        return self.drift_offset + self.drift_scale * self.drift_net(x)

    def scale_factor(self, theta, temperature_c):
        if self.sf_net is None:
            raise ValueError("this MLPCompensator is not fitted; use comp = comp.fit(data, key=…)")
        x = self.features(theta, temperature_c)
        return self.sf_offset + self.sf_scale * self.sf_net(x)

    def readout_temperature_sensitivity(self, theta, temperature_c):
        """s_T(θ, T) [rad/°C] from the s_T network; zero without one (`st_width = 0`)."""
        if self.st_net is None:
            return jnp.zeros_like(theta)
        x = self.features(theta, temperature_c)
        return self.drift_scale * self.k_e / ST_RATE_REF * self.st_net(x)

    def init(self, key: jax.Array) -> MLPCompensator:
        """Fresh untrained networks (weights from `key`; the s_T network's output layer
        starts at zero, so s_T = 0 until ramps teach it otherwise)."""
        check_key("MLPCompensator.init: key", key)
        kd, ks, kt = jax.random.split(key, 3)
        make = lambda w, k: eqx.nn.MLP(self.in_size, "scalar", w, 1, jnp.tanh, key=k)
        comp = eqx.tree_at(
            lambda c: (c.drift_net, c.sf_net),
            self,
            (make(self.drift_width, kd), make(self.sf_width, ks)),
            is_leaf=lambda x: x is None,
        )
        if not self.st_width:
            return comp
        st = make(self.st_width, kt)
        last = st.layers[-1]
        st = eqx.tree_at(lambda m: (m.layers[-1].weight, m.layers[-1].bias), st,
                         (jnp.zeros_like(last.weight), jnp.zeros_like(last.bias)))  # fmt: skip
        return eqx.tree_at(lambda c: c.st_net, comp, st, is_leaf=lambda x: x is None)

    def fit(
        self,
        data,
        *,
        key: jax.Array | None = None,
        raw: MeasuredData | None = None,
        mode: str | FromField = FROM_FIELD,
        window_s: float | None | FromField = FROM_FIELD,
    ) -> MLPCompensator:
        """Train the networks ([`AbstractCompensator.fit`][hrgjax.calibration.AbstractCompensator.fit]).

        **Arguments:**

        - `data`: [`hrgjax.MeasuredData`][] or [`RateWindows`][hrgjax.calibration.RateWindows]
          (for `mode="end_to_end"` the raw samples are needed: pass `MeasuredData`, or the
          windows plus `raw=`).
        - `key`: PRNG key of the initial weights (required).
        - `raw`: the raw samples behind windows given as `data` (used by `mode="end_to_end"`).
        - `mode`, `window_s`: *deprecated*, give `MLPCompensator(mode=…, window_s=…)`; a
          value here overrides the field of that name (and the fitted compensator keeps it).

        With `st_width > 0` the drift and s_T networks are trained together on every at-rest
        window, ramps cut into `RAMP_WINDOW_S` windows (windows given as `RateWindows` must
        come from `reduce(…, ramp_window_s=…)`); `mode="end_to_end"` then refines the drift
        and scale-factor networks with s_T held.

        **Returns:** a new fitted `MLPCompensator`.

        **Raises:** `TypeError` without one PRNG `key`; `ValueError` for an unknown mode, data
        without static or rotation runs, fewer than `MIN_TEMPERATURES` (2) distinct
        temperatures among the static or among the rotation runs (levels within 0.5 °C
        counted once: the networks learn nothing about T from one level), or, with
        `st_width > 0`, data without ramps.
        """
        require_x64("MLPCompensator.fit")
        check_key("MLPCompensator.fit: key= (the PRNG key of the initial weights)", key)
        check_raw("MLPCompensator.fit", data, raw)
        if mode is not FROM_FIELD and mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}; got {mode!r}")
        if mode is not FROM_FIELD or window_s is not FROM_FIELD:
            self = dataclasses.replace(
                self, mode=setting(self, "mode", mode), window_s=setting(self, "window_s", window_s)
            )
        mode, window_s = self.mode, self.window_s
        ramp_window_s = RAMP_WINDOW_S if self.st_width else None
        static, moving = fit_windows(data, self.k_e, window_s, ramp_window_s)
        for kind, w in (("static", static), ("rotation", moving)):
            require_temperatures(w.temperature_c, MIN_TEMPERATURES, "MLPCompensator.fit",
                                 "; the networks learn T only from the levels they see: add "
                                 "runs at other temperatures (docs/calibration.md)",
                                 where=f"the calibration data's {kind} runs")  # fmt: skip
        u = _ramp_rates(static) if self.st_width else None
        self = dataclasses.replace(self, temperature_range=None, n_temperature_levels=None)
        comp = self.init(key)
        temps = np.concatenate([static.temperature_c, moving.temperature_c])
        # Host arithmetic (NumPy) between the compiled training programs: eager jnp would
        # stage a small XLA program per operation and shape.
        t_centre = 0.5 * (temps.max() + temps.min())
        t_scale = max(0.5 * (temps.max() - temps.min()), 1.0)
        comp = eqx.tree_at(
            lambda c: (c.t_centre, c.t_scale), comp, (device(t_centre), device(t_scale))
        )
        x_c = device(comp.features(*curvature_points(t_centre, t_scale), np))
        prior = lambda weight: (x_c, device(weight)) if weight else None
        x_s = comp.features(static.wave_angle_deg * DEG, static.temperature_c, np)
        d = (static.rate_dps - static.table_rate_dps) * DEG
        d_off, d_scale = float(np.mean(d)), float(max(np.std(d), 1e-12))
        y = device((d - d_off) / d_scale)
        if u is None:
            net = train_rprop(comp.drift_net, device(x_s), y, self.steps, self.learning_rate,
                              desc="MLP drift", prior=prior(self.drift_t_curvature))  # fmt: skip
        else:  # drift and s_T together: measured = D − s_T Ṫ/k_e (module docstring)
            params, static_part = eqx.partition((comp.drift_net, comp.st_net), eqx.is_inexact_array)
            params, _ = rprop_with_progress(
                _drift_st_loss, params, (static_part, device(x_s), device(u), y,
                (x_c, device(self.drift_t_curvature))), self.steps,
                self.learning_rate, desc="MLP drift + s_T",
            )  # fmt: skip
            net, st_net = eqx.combine(params, static_part)
            comp = eqx.tree_at(lambda c: c.st_net, comp, st_net)
        comp = eqx.tree_at(
            lambda c: (c.drift_net, c.drift_offset, c.drift_scale),
            comp,
            (net, device(d_off), device(d_scale)),
        )
        # a rotation window's rate: the laws averaged over its arc (module docstring)
        th_m, arc = moving.wave_angle_deg * DEG, window_arc(moving)
        d_m = arc_mean(lambda a, t: comp._pointwise("drift", a / DEG, t), th_m,
                       moving.temperature_c, arc)  # fmt: skip
        sf = (moving.rate_dps * DEG - d_m) / (moving.table_rate_dps * DEG)
        th_b, tc_b, arc_b, sf = bin_windows(th_m, moving.temperature_c, arc, sf, self.bin_deg)
        s_off, s_scale = float(np.mean(sf)), float(max(np.std(sf), 1e-12))
        x_m, weights = arc_rows(lambda a, t: comp.features(a, t, np), th_b, tc_b, arc_b)
        net = train_rprop(comp.sf_net, device(x_m), device((sf - s_off) / s_scale), self.steps,
                          self.learning_rate, desc="MLP scale factor",
                          prior=prior(self.sf_t_curvature), weights=weights)  # fmt: skip
        comp = eqx.tree_at(
            lambda c: (c.sf_net, c.sf_offset, c.sf_scale),
            comp,
            (net, device(s_off), device(s_scale)),
        )
        if mode == "end_to_end":
            samples = raw if raw is not None else data
            if not isinstance(samples, MeasuredData):
                raise ValueError("mode='end_to_end' needs the raw samples: pass raw=MeasuredData")
            comp = train_end_to_end(comp, samples, window_s or WINDOW_S, self.e2e_steps)
        return dataclasses.replace(comp, **domain_of(temps))


def curvature_points(t_centre: float, t_scale: float):
    """The `CURVATURE_POINTS` points (θ [rad], T [°C]) of the smoothness prior: a Kronecker
    sequence (the plastic number's), uniform over θ ∈ [0, π) and T ∈ t_centre ± t_scale."""
    u = (np.arange(1, CURVATURE_POINTS + 1)[:, None] * np.array([0.7548776662, 0.5698402910])) % 1
    return np.pi * u[:, 0], t_centre + t_scale * (2.0 * u[:, 1] - 1.0)


def _ramp_rates(static: RateWindows) -> np.ndarray:
    """Ṫ / ST_RATE_REF of each at-rest window, checked: the s_T network needs ramps."""
    rate = static.temperature_rate_cps
    if rate is None:
        raise ValueError(
            "st_width > 0 needs each window's temperature rate: pass MeasuredData, or windows "
            "from reduce(data, ramp_window_s=RAMP_WINDOW_S)"
        )
    if not np.any(np.abs(rate) >= MIN_RAMP_RATE):
        raise ValueError(
            "st_width > 0 learns s_T from ramps (table at rest, temperature moving at ≥ "
            f"{MIN_RAMP_RATE * 60:g} °C/min); the calibration data have none"
        )
    return np.asarray(rate, dtype=float) / ST_RATE_REF


def _drift_st_loss(params, data):
    """Mean squared error of D − s_T·Ṫ/k_e against the at-rest windows (normalised units)."""
    static, x, u, y, (xc, weight) = data
    drift_net, st_net = eqx.combine(params, static)
    pred = jax.vmap(drift_net)(x) - u * jax.vmap(st_net)(x)
    penalty = t_curvature(drift_net, xc) + t_curvature(st_net, xc)
    return jnp.mean((pred - y) ** 2) + weight * penalty


def t_curvature(net, x):
    """Mean of (∂²net/∂τ²)² over the points `x` (n, d), τ the last input (the normalised
    temperature): the smoothness prior in T (`MLPCompensator.drift_t_curvature`; units: the
    net's output per τ², squared). `net` maps one row (d,) to a scalar, any depth: JAX's
    forward-over-forward derivative along τ (as fast as the one-layer closed form, measured).

    **Raises:** `ValueError` (one line) when `x` is not (n, d) or `net` not scalar-valued.
    """
    out = jax.eval_shape(net, x[0]) if jnp.ndim(x) == 2 else None
    if out is None or out.shape != ():
        raise ValueError(f"t_curvature: needs points x of shape (n, d) and a net mapping a (d,) "
                         f"row to a scalar; got x {jnp.shape(x)}, net output "
                         f"{None if out is None else out.shape}")  # fmt: skip
    e = jnp.zeros(x.shape[1], x.dtype).at[-1].set(1.0)
    slope = lambda p: jax.jvp(net, (p,), (e,))[1]  # noqa: E731
    return jnp.mean(jax.vmap(lambda p: jax.jvp(slope, (p,), (e,))[1])(x) ** 2)


def bin_targets(theta, temperature_c, value, bin_deg: float):
    """Average `value` in cells of one temperature level (windows' temperatures within
    `LEVEL_TOLERANCE_C`, grouped as the fits count them) and `bin_deg` of wave angle (period
    180°): `hrgjax.calibration._window_arc.bin_windows` for point values (no arc).

    **Returns:** `(theta, temperature_c, value)` per non-empty cell; θ [rad] is the circular
    mean (in 2θ) of the cell's angles, the temperature the mean of its windows'.
    """
    th, tc, _, value = bin_windows(theta, temperature_c, np.zeros(np.shape(theta)), value,
                                   bin_deg)  # fmt: skip
    return th, tc, value


def train_rprop(
    net, x, y, steps: int, learning_rate: float = 1e-3, *, desc: str = "MLP", prior=None,
    weights=None,
):  # fmt: skip
    """Full-batch Rprop on the mean squared error of `net(x) − y`, with a progress bar.

    **Arguments:** `net` (a callable Module, any depth), `x` shape (n, d), `y` shape (n,),
    `steps`, `learning_rate` (Rprop's initial step), `desc` (the progress bar's label),
    `prior`: `(x_c, weight)` adds `weight` · `t_curvature(net, x_c)` to the loss (`None`:
    no prior, and the loss never evaluates it); `weights` (J,): `x` is (n, J, d) and each
    target's model is `net` averaged over its J rows with these weights (a window's arc,
    `window_average`).

    **Returns:** the trained network. **Raises:** `ValueError` (one line) for data `net`
    cannot be fitted to ([`check_fit_data`][hrgjax.nn.train.check_fit_data]: y (n, 1) trained
    to the targets' mean) or a malformed `prior`; `RuntimeError` if training diverges.
    """
    if prior is not None and (not isinstance(prior, tuple | list) or len(prior) != 2):
        raise ValueError("train_rprop: prior must be None or a pair (x_c, weight), x_c (n, d); "
                         f"got {type(prior).__name__}")  # fmt: skip
    check_fit_data("train_rprop", net, x, y, weights)
    params, static = eqx.partition(net, eqx.is_inexact_array)
    data = (static, x, y, prior, weights)
    params, _ = rprop_with_progress(_mse_loss, params, data, steps, learning_rate, desc=desc)
    return eqx.combine(params, static)


def _mse_loss(params, data):
    static, x, y, prior, weights = data  # prior / weights None: not in the program (pytree)
    model = eqx.combine(params, static)
    loss = jnp.mean((window_average(model, x, weights) - y) ** 2)
    return loss if prior is None else loss + prior[1] * t_curvature(model, prior[0])


class AngleRuns(eqx.Module):
    """Runs of equal length stacked for end-to-end training (leading axis = run).

    `t`, `theta` [rad], `temperature_c`, `table_angle` [rad]: shape (R, N); `checkpoints`:
    sample indices (C,) bounding the windows of moving runs (the last one is N − 1);
    `static`: (R,) true for runs at rest, which count as one window, as in the reduction;
    `pieces`, `nodes`: the most pieces of arc a sample interval spans and the quadrature
    nodes a piece takes (`integrate_compensated`; `run_groups` sets them: `arc_rule`).
    """

    t: jax.Array
    theta: jax.Array
    temperature_c: jax.Array
    table_angle: jax.Array
    checkpoints: jax.Array
    static: jax.Array
    pieces: int = eqx.field(static=True, default=1)
    nodes: int = eqx.field(static=True, default=NODES)


def run_groups(data: MeasuredData, window_s: float) -> list[AngleRuns]:
    """`data`'s runs as `AngleRuns`, one per group of equal length and sampling
    (`MeasuredData.stacked`), windows of moving runs every `window_s` [s]: what the
    end-to-end training integrates over."""
    out = []
    for stack in data.stacked():
        n = stack.n_samples
        step = max(int(round(window_s / stack.dt)), 1)
        cps = np.unique(np.concatenate([np.arange(step, n, step), [n - 1]]))
        pieces, nodes = arc_rule(np.diff(stack.wave_angle, axis=-1))
        out.append(
            AngleRuns(
                t=device(stack.t),
                theta=device(stack.wave_angle),
                temperature_c=device(stack.temperature),
                table_angle=device(stack.table_angle),
                checkpoints=device(cps),
                static=device(stack.static),
                pieces=pieces,
                nodes=nodes,
            )
        )
    return out


def integrate_compensated(comp: AbstractCompensator, t, theta, temperature_c, ts, pieces=None,
                          nodes=None):  # fmt: skip
    r"""Case angle [rad] from the compensated rate, integrated along the record by the rule and
    code of [`correct`][hrgjax.calibration.AbstractCompensator.correct]
    (`hrgjax.calibration._correction.integrate_arcs`; the midpoint rule used before was
    3.4e-2° off it after 60 s at 50 °/s, 1 Hz). Traceable (jit, grad, vmap over runs).

    **Arguments:** `t` [s], `theta` [rad], `temperature_c` [°C] of one run (N,); `ts` [s];
    `pieces`, `nodes`: the most pieces of arc an interval spans and the nodes a piece takes,
    Python ints (`None`: `arc_rule`'s for a concrete `theta`; traced, `pieces` is needed and
    `nodes` is `NODES`; `run_groups` sets both for training).

    **Returns:** ψ at `ts` [rad] (ψ = 0 at t[0]; between samples, linear).
    """
    value = concrete_value(theta)
    need, fit = (1, NODES) if value is None else arc_rule(np.diff(value))
    pieces = need if pieces is None and value is not None else pieces
    if isinstance(pieces, bool) or not isinstance(pieces, int | np.integer) or pieces < need:
        raise ValueError(f"integrate_compensated: pieces must be a whole number ≥ {need} (the "
                         "most pieces of arc an interval spans; given when theta is traced); "
                         f"got {pieces!r}")  # fmt: skip
    nodes = fit if nodes is None else nodes
    return jnp.interp(ts, t, integrate_arcs(comp, t, theta, temperature_c, pieces, nodes))


def end_to_end_losses(comp: AbstractCompensator, runs: AngleRuns):
    r"""Mean squared angle errors [rad²] of the static and of the moving runs of a group.

    For each run the compensated case angle ψ(t) is integrated along the record
    ([`integrate_compensated`][hrgjax.calibration.mlp.integrate_compensated]). A moving run's
    error is taken per window, (ψ(t_{k+1}) − ψ(t_k)) − (A(t_{k+1}) − A(t_k)) with A the table
    angle: increments, not the accumulated angle, keep the noise of different windows
    independent. A static run is one window, its error the angle at its end.

    **Returns:** `(static_mse, moving_mse)` (0 for a kind the group does not have).
    """
    cps = jnp.concatenate([jnp.zeros(1, dtype=runs.checkpoints.dtype), runs.checkpoints])

    def one(t, th, tc, table, static):
        psi = integrate_compensated(comp, t, th, tc, t[cps], runs.pieces, runs.nodes)
        err = jnp.diff(psi) - jnp.diff(table[cps])
        return jnp.where(static, jnp.sum(err) ** 2, jnp.mean(err**2))

    per_run = jax.vmap(one)(runs.t, runs.theta, runs.temperature_c, runs.table_angle, runs.static)
    n_static = jnp.sum(runs.static.astype(per_run.dtype))
    n_moving = runs.static.shape[0] - n_static
    static = jnp.sum(jnp.where(runs.static, per_run, 0.0)) / jnp.maximum(n_static, 1.0)
    moving = jnp.sum(jnp.where(runs.static, 0.0, per_run)) / jnp.maximum(n_moving, 1.0)
    return static, moving


def end_to_end_loss(comp: AbstractCompensator, runs: AngleRuns):
    """Sum of the two [`end_to_end_losses`][hrgjax.calibration.mlp.end_to_end_losses] [rad²]."""
    static, moving = end_to_end_losses(comp, runs)
    return static + moving


def train_end_to_end(
    comp: MLPCompensator, data: MeasuredData, window_s: float, steps: int
) -> MLPCompensator:
    """Rprop on the end-to-end losses of all runs: the static and the moving runs' mean squared
    errors, each normalised by its value at the start, so both kinds weigh alike."""
    groups = run_groups(data, window_s)
    form = comp._program_form()  # its fit-only static fields out of the programs' keys
    params, static = eqx.partition(form, _trainable(form))
    scales = _e2e_scales(form, groups)
    params, _ = rprop_with_progress(_e2e_loss, params, (static, groups, scales), steps,
                                    comp.learning_rate, desc="MLP end-to-end")  # fmt: skip
    leaves = jax.tree_util.tree_leaves(eqx.combine(params, static))  # the same leaves as comp's
    return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(comp), leaves)


@program
def _e2e_scales(comp, groups):
    """The starting static and moving losses (each kind's normalisation)."""
    start = [end_to_end_losses(comp, g) for g in groups]
    scale_s = jnp.maximum(sum(a for a, _ in start), 1e-300)
    scale_m = jnp.maximum(sum(b for _, b in start), 1e-300)
    return scale_s, scale_m


def _e2e_loss(params, data):
    static, groups, (scale_s, scale_m) = data
    c = eqx.combine(params, static)
    parts = [end_to_end_losses(c, g) for g in groups]
    return sum(a for a, _ in parts) / scale_s + sum(b for _, b in parts) / scale_m


def _trainable(comp):
    """Filter spec: the network weights train, the normalisation stays."""
    spec = jax.tree_util.tree_map(lambda _: False, comp)
    return eqx.tree_at(
        lambda c: (c.drift_net, c.sf_net),
        spec,
        (
            jax.tree_util.tree_map(eqx.is_inexact_array, comp.drift_net),
            jax.tree_util.tree_map(eqx.is_inexact_array, comp.sf_net),
        ),
    )
