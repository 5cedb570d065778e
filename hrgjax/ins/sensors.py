r"""IMU errors on increments: biases, scale factors, misalignments, white noise, bias
instability (first-order Gauss–Markov) and random walks, per axis in the body frame, with
explicit PRNG keys.

For the interval k of length Δt, with $M = I + \mathrm{diag}(s) + A$ (scale factors `s`,
misalignment matrix `A`, small angles, its diagonal ignored):

$$\widetilde{\Delta\theta}_k = M_g\,\Delta\theta_k + \big(b_g + \bar\beta_{g,k}\big)\Delta t
+ N_g\sqrt{\Delta t}\,w_k + \int_k\varepsilon(t)\,dt,$$

and the same for $\Delta v$ (without ε). $N$ is the angle / velocity random walk density,
$\bar\beta_k$ the mean over the interval of the sum of a Gauss–Markov bias (σ, τ, started
from its stationary law) and a random walk (rate random walk density K); ε is any extra rate
error series, e.g. an hrgjax gyro's simulated output error (the HRG's drift laws driven by
the flight's temperature).

Both means are drawn exactly, for any τ/Δt. With $r = Δt/τ$ and $a = e^{-r}$ the Gauss–Markov
bias's end value and interval mean are jointly Gaussian given its start $x_k$:
$x_{k+1} = a\,x_k + e_1$, $\bar x_k = x_k(1-a)/r + e_2$, $\mathrm{Var}\,e_1 = σ^2(1-a^2)$,
$\mathrm{Cov}(e_1, e_2) = σ^2(1-a)^2/r$,
$\mathrm{Var}\,e_2 = 2σ^2\big(r - 2(1-a) + (1-a^2)/2\big)/r^2$ (written with `expm1`, and
as its series below r = 1, where the closed form cancels); the random walk's mean is its
end values' average plus its Brownian-bridge term $N(0, K^2Δt/12)$. (A trapezoid of the
samples, as before, gave τ = Δt/10 an integrated angle 4.8× too variable.)

[`PRESETS`][hrgjax.ins.sensors.PRESETS] holds representative grades (navigation, tactical,
industrial MEMS, consumer MEMS) after Groves, *Principles of GNSS, Inertial, and
Multisensor Integrated Navigation Systems*, 2nd ed., Table 4.1 and §4.4 — typical values of
each class, not any product's datasheet.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import (
    check_finite_host,
    check_key,
    check_numbers,
    concrete_value,
    is_concrete,
    vec3,
)
from .._compiled import fused, tracing_callback_free
from ..units import DEG_PER_H, DEG_PER_SQRT_H, G0

MICRO_G = 1e-6 * G0
"""One micro-g in m/s²."""
MG_PER_SQRT_HZ = 1e-3 * G0
"""Velocity random walk of 1 mg/√Hz in m/s/√s."""

_VECTOR_FIELDS = (
    "gyro_bias",
    "accel_bias",
    "gyro_scale",
    "accel_scale",
    "arw",
    "vrw",
    "gyro_bias_instability",
    "accel_bias_instability",
    "gyro_rate_random_walk",
    "accel_random_walk",
)


_UNITS = {
    "gyro_bias": "rad/s",
    "accel_bias": "m/s²",
    "gyro_scale": "-",
    "accel_scale": "-",
    "arw": "rad/√s",
    "vrw": "m/s/√s",
    "gyro_bias_instability": "rad/s",
    "accel_bias_instability": "m/s²",
    "gyro_rate_random_walk": "rad/s/√s",
    "accel_random_walk": "m/s²/√s",
}


_MISALIGNMENTS = ("gyro_misalignment", "accel_misalignment")

_TIMES = ("gyro_correlation_time", "accel_correlation_time")
"""The Gauss–Markov correlation times [s]: scalar leaves, so a sweep over them (a loop, `vmap`,
`grad`) compiles once."""


def _time(name):
    """The converter of the correlation time `name`: one real number [s], as a float array."""

    def convert(x):
        check_numbers(f"ImuModel.{name}", x, "one correlation time [s] (a real number > 0)",
                      shape=())  # fmt: skip
        return jnp.asarray(x, float)

    return convert


_DRAWN = ("gyro_bias", "accel_bias", "gyro_scale", "accel_scale", *_MISALIGNMENTS)
"""The fields [`random_unit`][hrgjax.ins.sensors.random_unit] redraws (a unit's turn-on
errors): a drawn unit's are not held to their `imu_*` ranges."""

_RANGE = {name: "imu_scale" if name.endswith("_scale") else f"imu_{name}"
          for name in _VECTOR_FIELDS} | {"gyro_misalignment": "imu_misalignment",
                                         "accel_misalignment": "imu_misalignment"}  # fmt: skip
"""Each field's range in `hrgjax.plausible.RANGES` (SI; a value beyond is named with the
datasheet units it may be in: °/h or °/s, ppm or %, °/√h or °/s/√Hz, µg or mg)."""


def _vec3(name):
    return vec3("ImuModel", name, _UNITS[name])


class ImuModel(eqx.Module):
    """Errors of a strapdown IMU (module docstring). Every vector field takes a scalar (all
    axes) or 3 values (x, y, z body).

    **Fields:** `gyro_bias` [rad/s], `accel_bias` [m/s²]: fixed biases; `gyro_scale`,
    `accel_scale` [-]: scale-factor errors (1e-6 = 1 ppm); `gyro_misalignment`,
    `accel_misalignment` (3, 3) [rad]: off-diagonal small angles (row = sensed axis);
    `arw` [rad/√s], `vrw` [m/s/√s]: white-noise densities; `gyro_bias_instability` [rad/s],
    `accel_bias_instability` [m/s²] with `gyro_correlation_time`, `accel_correlation_time`
    [s]: first-order Gauss–Markov biases (σ, τ; τ one value > 0 each, a leaf like the others:
    a sweep over it compiles once); `gyro_rate_random_walk` [rad/s/√s],
    `accel_random_walk` [m/s²/√s]: bias random walks; `drawn` (static): a unit drawn by
    [`random_unit`][hrgjax.ins.sensors.random_unit].

    **Raises:** `ValueError` for a concrete field (or one under an eager `jax.grad`) that is
    not finite, a density or 1σ < 0, or a value outside its `hrgjax.plausible.RANGES` entry
    (`imu_*`, bounds excluded: e.g. |gyro_bias| < 0.75 rad/s, |gyro_scale| < 0.1,
    arw < 2.5e-3 rad/√s), named with the datasheet units it may be in and the factor from
    each (`gyro_bias=3.0`: "… — °/h → ×hrgjax.units.DEG_PER_H; °/s → ×hrgjax.units.DEG
    (hrgjax.plausible.relaxed(imu_gyro_bias=…) widens it)"; the scale factors' range is
    `imu_scale`, the misalignments' `imu_misalignment`). A field traced inside `jit`, `vmap`
    or `hg.sweep` is held to the same rules when [`apply`][hrgjax.ins.sensors.ImuModel.apply]
    runs ([`traced_checks`][hrgjax.ins.sensors.traced_checks]). A unit drawn by
    [`random_unit`][hrgjax.ins.sensors.random_unit] (`drawn`) keeps the finite check on its
    drawn fixed biases, scale factors and misalignments but not their ranges: they are
    Gaussian draws of the grade's values, which were held to the ranges, and a draw lies
    past a bound at random (σ 0.06 against |gyro_scale| < 0.1: 6 of 16 units)."""

    gyro_bias: jax.Array = eqx.field(converter=_vec3("gyro_bias"), default=0.0)
    accel_bias: jax.Array = eqx.field(converter=_vec3("accel_bias"), default=0.0)
    gyro_scale: jax.Array = eqx.field(converter=_vec3("gyro_scale"), default=0.0)
    accel_scale: jax.Array = eqx.field(converter=_vec3("accel_scale"), default=0.0)
    gyro_misalignment: jax.Array = eqx.field(converter=jnp.asarray, default=0.0)
    accel_misalignment: jax.Array = eqx.field(converter=jnp.asarray, default=0.0)
    arw: jax.Array = eqx.field(converter=_vec3("arw"), default=0.0)
    vrw: jax.Array = eqx.field(converter=_vec3("vrw"), default=0.0)
    gyro_bias_instability: jax.Array = eqx.field(
        converter=_vec3("gyro_bias_instability"), default=0.0
    )
    accel_bias_instability: jax.Array = eqx.field(
        converter=_vec3("accel_bias_instability"), default=0.0
    )
    gyro_correlation_time: jax.Array = eqx.field(
        converter=_time("gyro_correlation_time"), default=3600.0
    )
    accel_correlation_time: jax.Array = eqx.field(
        converter=_time("accel_correlation_time"), default=3600.0
    )
    gyro_rate_random_walk: jax.Array = eqx.field(
        converter=_vec3("gyro_rate_random_walk"), default=0.0
    )
    accel_random_walk: jax.Array = eqx.field(converter=_vec3("accel_random_walk"), default=0.0)
    drawn: bool = eqx.field(static=True, default=False)
    """Whether this is a unit [`random_unit`][hrgjax.ins.sensors.random_unit] drew from a
    grade (its fixed biases, scale factors and misalignments are not range-checked)."""

    def __check_init__(self):
        # concrete_value: an eager jax.grad's tracer carries its value, and is checked too
        for name in _VECTOR_FIELDS:
            v = concrete_value(getattr(self, name))
            if v is not None and not np.all(np.isfinite(v)):
                raise ValueError(f"ImuModel.{name} must be finite; got {v}")
        for name in _VECTOR_FIELDS[4:]:
            v = concrete_value(getattr(self, name))
            if v is not None and np.any(v < 0):
                raise ValueError(f"ImuModel.{name} is a density or a 1σ: it must be >= 0; got {v}")
        for name in ("gyro_misalignment", "accel_misalignment"):
            v = getattr(self, name)
            if jnp.shape(v) not in ((), (3, 3)):
                raise ValueError(
                    f"ImuModel.{name} must be 0 or a (3, 3) matrix of small angles [rad]; got "
                    f"shape {jnp.shape(v)}"
                )
            a = concrete_value(v)
            if a is not None and not np.all(np.isfinite(a)):
                at = np.unravel_index(int(np.argmax(~np.isfinite(a))), a.shape)
                where = f" at {list(map(int, at))}" if a.ndim else ""
                raise ValueError(
                    f"ImuModel.{name} must be finite (0 or a (3, 3) matrix of small angles "
                    f"[rad]); got {a[at]}{where}"
                )
        for name, quantity in _RANGE.items():  # SI, not the datasheet's °/h, ppm, °/√h, µg
            v = concrete_value(getattr(self, name))
            if v is not None and not (self.drawn and name in _DRAWN):
                v = v * (1.0 - np.eye(3)) if v.ndim == 2 else v
                unit = _UNITS.get(name, "rad")
                plausible.check(f"ImuModel.{name} [{unit}]", v, quantity)
        for name in _TIMES:
            v = concrete_value(getattr(self, name))
            if v is not None and not (np.isfinite(v) and v > 0):
                raise ValueError(f"ImuModel.{name} must be a finite time > 0 s; got {float(v)}")

    def checked(self) -> ImuModel:
        """This model with its traced fields held to
        [`traced_checks`][hrgjax.ins.sensors.traced_checks] when the program runs (one
        `eqx.branched_error_if`); itself when every field is concrete (checked where it was
        built). `apply` and the filter (`ins.ekf.loosely_coupled`) call it."""
        return _with_traced_checks(self)

    def _matrix(self, scale, mis):
        mis = jnp.broadcast_to(mis, (3, 3)) * (1.0 - jnp.eye(3))
        return jnp.eye(3) + jnp.diag(scale) + mis

    def apply(self, key, dtheta, dv, dt: float, gyro_rate_error=None, *, return_bias=False):
        """Increments as this IMU measures them (module docstring).

        **Arguments:** `key` a PRNG key; `dtheta` (N, 3) [rad] and `dv` (N, 3) [m/s] true
        increments over intervals of `dt` [s]; `gyro_rate_error`: optional extra gyro error
        [rad/s], (N, 3) as each interval's mean rate; `return_bias`: also return each
        interval's total bias — fixed, Gauss–Markov, random walk and the extra rate error, all
        but the white noise — which is what a filter's bias states estimate (`True`, `False`,
        NumPy or JAX bools and 0 / 1);
        `return_bias="gauss_markov"`: the truth of `LooselyCoupled(gauss_markov=True)`'s
        states at the interval's end, where its fix falls: the Gauss–Markov bias *at that
        instant* (the filter's Gauss–Markov states are the bias at the fix, not its mean over
        the last step), and as the total that plus the rest's interval mean (fixed bias,
        random walk, extra rate error), so that total − Gauss–Markov part is the fixed-bias
        states' truth.

        **Returns:** `(dtheta, dv)` measured, each (N, 3); with `return_bias`,
        `(dtheta, dv, gyro_bias (N, 3) [rad/s], accel_bias (N, 3) [m/s²])`, each interval's
        mean total bias; with `return_bias="gauss_markov"` `(dtheta, dv, gyro_bias,
        accel_bias, gyro_gm (N, 3) [rad/s], accel_gm (N, 3) [m/s²])`: the Gauss–Markov bias at
        each interval's end, and the total with that Gauss–Markov part (the increments are
        the same draws either way).

        **Raises:** `ValueError` for a `dt` that is not a finite interval > 0 s, increments
        not both (N, 3), a `return_bias` other than those, a `gyro_rate_error` that is not
        (N, 3) [rad/s], or a NaN or inf in a concrete `dtheta`, `dv` or `gyro_rate_error`
        (a traced one passes unchecked, as does a traced `dt`: `jit`, `vmap` or `grad` over
        the interval give the eager values); `TypeError` for any of them that is not real
        numbers (a str, a bool or complex array). Fields traced inside `jit`, `vmap` or
        `hg.sweep` are checked here, at run time
        ([`traced_checks`][hrgjax.ins.sensors.traced_checks]): the first rule broken raises
        its one line (`hg.sweep`: "sweep: at one or more grid points, ImuModel.gyro_bias
        [rad/s] is outside the plausible range -0.75 … 0.75 rad/s …")."""
        check_key("ImuModel.apply: key", key)
        gauss_markov = isinstance(return_bias, str) and return_bias == "gauss_markov"
        if not gauss_markov:
            flag = None  # a bool, NumPy or JAX bool, or 0 / 1, as the truthiness it used to be
            if not isinstance(return_bias, (str, jax.core.Tracer)):
                flag = np.asarray(return_bias)
            ok = flag is not None and flag.shape == () and flag.dtype.kind in "bui"
            if not (ok and flag.item() in (0, 1)):
                raise ValueError(
                    f'ImuModel.apply: return_bias must be False, True (or 0, 1) or "gauss_markov" '
                    f"(a Python value, not traced); got {return_bias!r}"
                )
            return_bias = bool(flag)
        for name, x, unit in (("dtheta", dtheta, "rad"), ("dv", dv, "m/s"),
                              ("gyro_rate_error", gyro_rate_error, "rad/s")):  # fmt: skip
            if x is not None or name != "gyro_rate_error":
                check_numbers(f"ImuModel.apply: {name}", x, f"real numbers (N, 3) [{unit}]")
        shape = jnp.shape(dtheta)
        if len(shape) != 2 or shape[-1] != 3 or jnp.shape(dv) != shape:
            raise ValueError(
                "ImuModel.apply: dtheta and dv must both have shape (N, 3) (one gyro [rad] and "
                f"one accelerometer [m/s] increment per interval); got {shape} and "
                f"{jnp.shape(dv)}"
            )
        if is_concrete(dt):
            d = np.asarray(dt)
            if d.shape != () or not (np.isfinite(d) and d > 0):
                raise ValueError(
                    f"ImuModel.apply: dt must be the increments' interval in seconds (> 0); got "
                    f"{dt}"
                )
        if gyro_rate_error is not None:
            es = jnp.shape(gyro_rate_error)
            try:
                ok = np.broadcast_shapes(es, shape) == shape
            except ValueError:
                ok = False
            if not ok:
                raise ValueError(
                    f"ImuModel.apply: gyro_rate_error must be ({shape[0]}, 3) [rad/s], each "
                    f"interval's mean rate error; got shape {es}"
                )
        for name, x in (("dtheta", dtheta), ("dv", dv), ("gyro_rate_error", gyro_rate_error)):
            if x is not None:  # concrete (or an eager grad's) values only: NaN gave NaN out
                check_finite_host(f"ImuModel.apply: {name}", x)
        imu = _with_traced_checks(self)
        n = shape[0]
        kg, ka = jax.random.split(key)
        g = (imu.gyro_bias_instability, imu.gyro_correlation_time, imu.gyro_rate_random_walk)
        a = (imu.accel_bias_instability, imu.accel_correlation_time, imu.accel_random_walk)
        bg, wg, gm_g = imu._bias_path(kg, n, dt, *g, imu.arw)
        ba, wa, gm_a = imu._bias_path(ka, n, dt, *a, imu.vrw)
        bg = bg + imu.gyro_bias[None]
        if gyro_rate_error is not None:
            bg = bg + jnp.asarray(gyro_rate_error, float)
        ba = ba + imu.accel_bias[None]
        mg = imu._matrix(imu.gyro_scale, imu.gyro_misalignment)
        ma = imu._matrix(imu.accel_scale, imu.accel_misalignment)
        th = dtheta @ mg.T + bg * dt + wg
        dv = dv @ ma.T + ba * dt + wa
        if gauss_markov:  # the rest at the mean, the Gauss–Markov part at the interval's end
            bg, ba = bg - gm_g[0] + gm_g[1], ba - gm_a[0] + gm_a[1]
            return th, dv, bg, ba, gm_g[1], gm_a[1]
        return (th, dv, bg, ba) if return_bias else (th, dv)

    @staticmethod
    def _bias_path(key, n, dt, sigma, tau, rrw, white):
        """(N, 3) exact interval means of the Gauss–Markov and random-walk biases (module
        docstring) [per s], (N, 3) white-noise increments, and the pair ((N, 3) the
        Gauss–Markov part of the means, (N, 3) the Gauss–Markov bias at each interval's end)."""
        k0, k1, k2, k3, k4 = jax.random.split(key, 5)
        a, b, l11, l21, l22 = _gm_interval(dt / tau)
        gm0 = sigma * jax.random.normal(k0, (3,))
        z1 = jax.random.normal(k1, (n, 3))
        z2, z3 = jax.random.normal(k4, (2, n, 3))
        e1 = z1 * (sigma * l11)[None]  # the end value's innovation
        e2 = (l21 * z1 + l22 * z2) * sigma[None]  # the mean's, correlated with it
        root = jnp.sqrt if isinstance(dt, jax.core.Tracer) else math.sqrt  # dt may be traced
        w_rw = jax.random.normal(k2, (n, 3)) * (rrw * root(dt))[None]
        bridge = z3 * (rrw * root(dt / 12.0))[None]
        mean, gm = _bias_scan(a, b, gm0, e1, e2, w_rw, bridge)
        return mean, jax.random.normal(k3, (n, 3)) * (white * root(dt))[None], gm


@fused
def _bias_scan(a, b, gm0, e1, e2, w_rw, bridge):
    """`ImuModel._bias_path`'s recursion, one compiled program per length: `a`, `b` (the
    Gauss–Markov coefficients, scalars) are arguments — a scan run eagerly on a fresh
    closure holding them compiled twice on every call. The draws before it stay separate
    operations (each compiled once per shape): fused with them, XLA contracts their products
    and sums into FMAs and the values move in the last bits."""

    def step(c, w):
        gm, rw = c
        e1, e2, w_rw, bridge = w
        gm1, rw1 = a * gm + e1, rw + w_rw
        return (gm1, rw1), (b * gm + e2 + 0.5 * (rw + rw1) + bridge, (b * gm + e2, gm1))

    _, (mean, gm) = jax.lax.scan(step, (gm0, jnp.zeros(3)), (e1, e2, w_rw, bridge))
    return mean, gm


def _gm_interval(r):
    """A unit-σ first-order Gauss–Markov process over one interval of r = Δt/τ correlation
    times (module docstring): `(a, b, l11, l21, l22)` with end value = a·start + l11·z1 and
    interval mean = b·start + l21·z1 + l22·z2 (z1, z2 independent N(0, 1)), the Cholesky
    factor of the pair's joint innovation covariance. Scalars (r may be traced); accurate from
    r = 1e-8 to 1e8 (expm1, and the series of the mean's variance below r = 1); r is taken
    within [1e-80, 1e300]."""
    # τ below Δt/1e300 is white (no inf/inf); τ beyond 1e80·Δt a constant bias: the
    # innovations' 1e-40 of σ there are nothing, and below r ≈ 1e-90 the values' and the
    # derivatives' products underflow to 0/0 (XLA reassociates c12/l11 into one division)
    r = jnp.clip(jnp.asarray(r, float), 1e-80, 1e300)
    one_minus_a = -jnp.expm1(-r)
    v11 = -jnp.expm1(-2.0 * r)  # 1 - a²
    c12 = one_minus_a**2 / r
    # r - 2(1-a) + (1-a²)/2 = Σ_{k≥3} (-1)^k (2 - 2^(k-1)) r^k / k!, summed at min(r, 1)
    x = jnp.minimum(r, 1.0)
    series, term = 0.0, x * x / 2.0
    for k in range(3, 40):
        term = term * x / k
        series = series + (-1) ** k * (2.0 - 2.0 ** (k - 1)) * term
    f = jnp.where(r < 1.0, series, r - 2.0 * one_minus_a + 0.5 * v11)
    v22 = 2.0 * (f / r) / r  # r·r underflows below r = 1e-162
    l11 = jnp.sqrt(v11)
    l21 = jnp.where(l11 > 0.0, c12 / jnp.where(l11 > 0.0, l11, 1.0), 0.0)
    return jnp.exp(-r), one_minus_a / r, l11, l21, jnp.sqrt(jnp.maximum(v22 - l21 * l21, 0.0))


def traced_checks(imu: ImuModel) -> list:
    """The run-time twins of `ImuModel`'s own checks for its traced fields (inside `jit`,
    `vmap` or `hg.sweep` a module's `__check_init__` sees no values): `[(bad, message), …]`,
    `bad` a traced boolean, `message` the eager one line without the value, in the order
    `__check_init__` checks them (finite; densities and 1σ >= 0; correlation times finite
    and > 0; each field's `imu_*` range,
    bounds excluded; a `drawn` unit's drawn fields: finite only). Concrete fields add
    nothing: they were checked where the model was built.
    [`apply`][hrgjax.ins.sensors.ImuModel.apply] raises the first that holds
    (`eqx.branched_error_if`)."""
    traced = {name: v for name in (*_VECTOR_FIELDS, *_MISALIGNMENTS)
              if concrete_value(v := getattr(imu, name)) is None}  # fmt: skip
    checks = [(~jnp.all(jnp.isfinite(v)), f"ImuModel.{name} must be finite (found NaN or inf)")
              for name, v in traced.items()]  # fmt: skip
    checks += [(jnp.any(v < 0), f"ImuModel.{name} is a density or a 1σ: it must be >= 0 "
                "(found a negative value)")
               for name, v in traced.items() if name in _VECTOR_FIELDS[4:]]  # fmt: skip
    checks += [(~(jnp.isfinite(v) & (v > 0)), f"ImuModel.{name} must be a finite time > 0 s")
               for name in _TIMES if concrete_value(v := getattr(imu, name)) is None]  # fmt: skip
    for name, quantity in _RANGE.items():  # SI, as eagerly
        if name in traced and not (imu.drawn and name in _DRAWN):
            v = traced[name]
            v = v * (1.0 - jnp.eye(3)) if v.ndim == 2 else v
            checks += plausible.traced_violations(
                f"ImuModel.{name} [{_UNITS.get(name, 'rad')}]", v, quantity
            )
    return checks


def _with_traced_checks(imu: ImuModel) -> ImuModel:
    """`imu` with `traced_checks` held by one `eqx.branched_error_if` on its traced leaves
    (what `apply` computes from); unchanged when every field is concrete, or inside one of
    hrgjax's own callback-free programs (their models were checked where they were built)."""
    if tracing_callback_free():
        return imu
    checks = traced_checks(imu)
    if not checks:
        return imu
    bad = jnp.stack([jnp.asarray(b) for b, _ in checks])
    flat, tree = jax.tree_util.tree_flatten(imu)
    traced = [i for i, x in enumerate(flat) if concrete_value(x) is None]
    checked = eqx.branched_error_if(
        [flat[i] for i in traced], jnp.any(bad), jnp.argmax(bad), [m for _, m in checks]
    )
    for i, x in zip(traced, checked, strict=True):
        flat[i] = x
    return jax.tree_util.tree_unflatten(tree, flat)


def _grade(gb_dph, arw_dpsh, bi_dph, g_ppm, g_urad, ab_ug, vrw_ug_rthz, abi_ug, a_ppm, a_urad, tau):
    mis = lambda u: np.array([[0.0, 1.0, -1.0], [-1.0, 0.0, 1.0], [1.0, -1.0, 0.0]]) * u * 1e-6
    return ImuModel(
        gyro_bias=gb_dph * DEG_PER_H,
        accel_bias=ab_ug * MICRO_G,
        gyro_scale=g_ppm * 1e-6,
        accel_scale=a_ppm * 1e-6,
        gyro_misalignment=mis(g_urad),
        accel_misalignment=mis(a_urad),
        arw=arw_dpsh * DEG_PER_SQRT_H,
        vrw=vrw_ug_rthz * MICRO_G,
        gyro_bias_instability=bi_dph * DEG_PER_H,
        accel_bias_instability=abi_ug * MICRO_G,
        gyro_correlation_time=tau,
        accel_correlation_time=tau,
    )


PRESETS = {
    "navigation": _grade(0.005, 0.002, 0.003, 5, 5, 25, 5, 10, 20, 10, 3600.0),
    "tactical": _grade(1.0, 0.1, 0.5, 100, 100, 1000, 50, 50, 300, 100, 600.0),
    "industrial": _grade(10.0, 0.3, 5.0, 1000, 1000, 5000, 100, 100, 1000, 1000, 300.0),
    "consumer": _grade(300.0, 1.0, 30.0, 5000, 5000, 20000, 300, 500, 5000, 5000, 100.0),
}
"""Representative IMU grades (module docstring): fixed gyro bias [°/h] 0.005 / 1 / 10 / 300,
ARW [°/√h] 0.002 / 0.1 / 0.3 / 1, gyro bias instability [°/h] 0.003 / 0.5 / 5 / 30,
accelerometer bias [µg] 25 / 1000 / 5000 / 20000, VRW [µg/√Hz] 5 / 50 / 100 / 300; scale
factors and misalignments from 5 ppm, 5 µrad (navigation) to 5000 ppm, 5 mrad (consumer).
The fixed errors are one unit's values (signs as given); draw a unit's own with
[`random_unit`][hrgjax.ins.sensors.random_unit]."""


def preset(name: str) -> ImuModel:
    """The [`PRESETS`][hrgjax.ins.sensors.PRESETS] entry `name`, with a clear error for an
    unknown one."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"IMU preset must be one of {sorted(PRESETS)}; got {name!r}") from None


def random_unit(imu: ImuModel, key) -> ImuModel:
    """One unit of `imu`'s grade: its fixed biases, scale factors and misalignments redrawn as
    N(0, σ²) per axis (per element), σ the given value's magnitude — a Monte Carlo run's own
    turn-on errors. The unit is `drawn`: its draws are held to be finite but not to their
    `imu_*` ranges when it is applied (a Gaussian draw lies past a bound at random: with
    σ = bound/3.3, one draw in 1 200: in 23 % of 100-unit studies at least one of the 300
    gyro scale factors); `imu`'s own values are (eagerly where it was built; its traced
    fields here, at run time: [`traced_checks`][hrgjax.ins.sensors.traced_checks])."""
    check_key("random_unit: key", key)
    imu = _with_traced_checks(imu)
    k = jax.random.split(key, 6)
    draw = lambda kk, x: jnp.abs(x) * jax.random.normal(kk, jnp.shape(x))
    off = lambda m: jnp.broadcast_to(m, (3, 3)) * (1.0 - jnp.eye(3))  # a scalar: every element
    sigma = {name: getattr(imu, name) for name in _DRAWN}
    sigma.update({name: off(sigma[name]) for name in _MISALIGNMENTS})
    draws = {name: draw(kk, x) for kk, (name, x) in zip(k, sigma.items(), strict=True)}
    return dataclasses.replace(imu, drawn=True, **draws)
