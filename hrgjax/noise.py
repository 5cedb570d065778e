r"""Gyro noise with explicit PRNG keys.

All rate noises are in **equivalent input rate** (what a rate table would have to turn to
cause them); the simulator maps them to the wave angle through $\dot\theta = -k_e\Omega$.
They are superposed on the deterministic solution (first order in the noise: the drift
laws change by ~1e-5 rad/s per rad of wave angle, so noise-sized angle offsets do not alter
them measurably).

The same noise on the measured pattern (electrical) angle — the rate parts × k_e, its
second moments and its estimation from data — is
[`NoiseModel`][hrgjax.pattern_noise.NoiseModel] (`NoiseModel.from_gyro(noise, k_e)`),
which the bench design and the discovery share.
"""

from __future__ import annotations

import inspect
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import plausible
from ._checks import (
    FINITE_NONNEGATIVE,
    FINITE_POSITIVE,
    check_1d,
    check_key,
    check_nonnegative,
    check_numbers,
    check_positive,
    check_values,
    concrete_value,
    int_as_float,
)
from ._compiled import device, fused
from .resonator.params import as_parameter, concrete_fields, refuse_unconverted


class Noise(eqx.Module):
    r"""Noise model of a whole-angle gyro.

    **Arguments:**

    - `angle_white`: σ of white readout noise on the measured wave angle, per output sample
      [rad, electrical].
    - `angle_random_walk`: N, white rate noise density [rad/√s] (ARW; IEEE 952 N).
    - `bias_instability`: σ of a first-order Gauss–Markov rate [rad/s].
    - `correlation_time`: its correlation time $T_c$ [s] (> 0).
    - `run_bias`: σ of a constant rate bias drawn once per switch-on [rad/s].
    - `amplitude_white`: σ of white readout noise on amplitude and quadrature, per sample,
      relative to the amplitude set point.

    Each standard deviation must lie in its range of `hrgjax.plausible.RANGES` (`PLAUSIBLE`),
    sized for a gyro, an HRG's to a MEMS gyro's: an ARW up to 10⁻³ rad/√s (3.4 °/√h), a bias
    instability up to 10⁻³ rad/s (206 °/h), a switch-on bias up to 0.05 rad/s (2.9 °/s), the
    bounds excluded; beyond, a datasheet's °/√h or °/h typed as SI is refused naming the
    factor (`0.002 * hrgjax.units.DEG_PER_SQRT_H`; `hrgjax.plausible.relaxed(noise_arw=…)`
    widens it). `simulate` holds values put in with `eqx.tree_at` or traced to them too.
    """

    angle_white: jax.Array = eqx.field(converter=as_parameter, default=0.0)
    angle_random_walk: jax.Array = eqx.field(converter=as_parameter, default=0.0)
    bias_instability: jax.Array = eqx.field(converter=as_parameter, default=0.0)
    correlation_time: jax.Array = eqx.field(converter=as_parameter, default=100.0)
    run_bias: jax.Array = eqx.field(converter=as_parameter, default=0.0)
    amplitude_white: jax.Array = eqx.field(converter=as_parameter, default=0.0)

    def __check_init__(self):
        refuse_unconverted(self)
        for name, value in concrete_fields(self, NONNEGATIVE):
            check_nonnegative(f"Noise.{name}", value, f"[{UNITS[name]}] (a standard deviation)")
            plausible.check(f"Noise.{name}", value, PLAUSIBLE[name])
        for name, value in concrete_fields(self, ("correlation_time",)):
            check_positive(f"Noise.{name}", value, "[s]")


NONNEGATIVE = (
    "angle_white",
    "angle_random_walk",
    "bias_instability",
    "run_bias",
    "amplitude_white",
)
"""`Noise` fields that are standard deviations or densities (≥ 0)."""
UNITS = {
    "angle_white": "rad",
    "angle_random_walk": "rad/√s",
    "bias_instability": "rad/s",
    "correlation_time": "s",
    "run_bias": "rad/s",
    "amplitude_white": "relative",
}
"""Units of the `Noise` fields."""
PLAUSIBLE = {
    "angle_white": "noise_angle_white",
    "angle_random_walk": "noise_arw",
    "bias_instability": "noise_bias_instability",
    "run_bias": "noise_run_bias",
    "amplitude_white": "noise_amplitude_white",
}
"""Each `Noise` standard deviation's range in [`hrgjax.plausible.RANGES`][hrgjax.plausible.RANGES]
(a value in a datasheet's unit typed as SI is refused, the unit named)."""


def _check_key(name: str, key) -> None:
    """One JAX PRNG key, else a one-line error naming `name` (`_checks.check_key`)."""
    check_key(f"{name}: key", key)


def _check_times(name: str, key, ts):
    """`ts` as an array (a list too), checked with `key` on the host before any compiled
    program: `key` one PRNG key, `ts` 1-D finite sample times that do not run backwards (a
    repeated time is an empty interval)."""
    _check_key(name, key)
    check_numbers(f"{name}: ts", ts, "sample times [s], 1-D")
    check_1d(f"{name}: ts", ts, "sample times [s]")
    ts = device(ts, float) if isinstance(ts, list | tuple) else ts  # a list failed in jnp.diff
    v = concrete_value(ts)
    if v is not None:
        v = np.asarray(v, dtype=float)
        if not np.all(np.isfinite(v)):
            i = int(np.argmin(np.isfinite(v)))
            raise ValueError(f"{name}: ts must be finite; found {v[i]} at index {i}")
        if np.any(np.diff(v) < 0):  # an interval < 0: NaN or a wrong draw
            i = int(np.argmax(np.diff(v) < 0))
            raise ValueError(f"{name}: ts must not decrease [s]; ts[{i + 1}] = {v[i + 1]} "
                             f"follows ts[{i}] = {v[i]}")  # fmt: skip
    return ts


def _check_gauss_markov(key, ts, sigma, correlation_time) -> tuple:
    ts = _check_times("gauss_markov", key, ts)
    for name, x, ok, form in (
        ("sigma", sigma, FINITE_NONNEGATIVE, "one standard deviation >= 0"),
        ("correlation_time", correlation_time, FINITE_POSITIVE, "one time > 0 [s]"),
    ):  # fmt: skip
        check_numbers(f"gauss_markov: {name}", x, form, shape=())  # an array: JAX's broadcast error
        check_values(f"gauss_markov: {name}", x, ok, form)
    return key, ts, sigma, correlation_time


def _check_noise(name: str, noise) -> None:
    """`noise` an `hrgjax.Noise` (an int read as one failed inside the compiled program)."""
    if not isinstance(noise, Noise):
        raise TypeError(f"{name}: noise must be an hrgjax.Noise; got {type(noise).__name__}")


def _checked(check):
    """`fused(fn)` behind `check(*args)`, which refuses bad arguments on the host in one
    line before the compiled program and returns them as it takes them (`__wrapped__` is
    the plain function). Arguments by keyword are bound to `fn`'s parameters first; the
    compiled core's `lower`, `trace` and `eval_shape` stay on the wrapper (unchecked)."""

    def wrap(fn):
        signature = inspect.signature(fn)

        def prepare(*args, **kwargs):
            bound = signature.bind(*args, **kwargs)  # a TypeError names a wrong keyword
            return check(*bound.args)

        return fused(fn, prepare=prepare)

    return wrap


# one program per shape: an eager call compiled its scan every time (≈ 80 ms)
@_checked(_check_gauss_markov)
def gauss_markov(key, ts, sigma, correlation_time):
    r"""Stationary first-order Gauss–Markov samples at times `ts` (exact discretisation).

    $x_{k+1} = e^{-\Delta t/T_c}x_k + \sigma\sqrt{1-e^{-2\Delta t/T_c}}\,w_k$, $x_0\sim N(0,\sigma^2)$.

    `key` a JAX PRNG key; `ts` (N,) increasing sample times [s]; `sigma` the process's
    stationary standard deviation [any unit: rad/s for a bias-instability rate];
    `correlation_time` $T_c$ [s] (> 0). **Returns** (N,) samples in `sigma`'s unit.
    """
    dts = jnp.diff(ts)
    k0, k1 = jax.random.split(key)
    x0 = sigma * jax.random.normal(k0, ())
    phi = jnp.exp(-dts / correlation_time)
    q = 1.0 - phi**2  # 0 only for a repeated time, where √ has no finite slope
    sd = jnp.where(q > 0.0, jnp.sqrt(jnp.where(q > 0.0, q, 1.0)), 0.0)
    w = jax.random.normal(k1, dts.shape) * sigma * sd

    def step(x, inp):
        p, wk = inp
        x = p * x + wk
        return x, x

    _, xs = jax.lax.scan(step, x0, (phi, w))
    return jnp.concatenate([x0[None], xs])


# u cosh u − sinh u = Σ_{k≥1} 2k u^{2k+1}/(2k+1)!: positive terms (no cancellation); for
# u < 1, eight of them leave a relative error below 5e-16.
_SERIES = tuple(2.0 * k / math.factorial(2 * k + 1) for k in range(1, 9))


def _u_minus_tanh(u):
    """u − tanh u for u ≥ 0, to a few ulp everywhere: (u cosh u − sinh u)/cosh u by its
    series below 1 (where the difference cancels), directly above. Both branches see only
    arguments where they are finite (double `where`), so gradients stay finite."""
    small = u < 1.0
    us = jnp.where(small, u, 0.5)
    ud = jnp.where(small, 1.0, u)
    u2 = us * us
    poly = 0.0
    for c in reversed(_SERIES):
        poly = poly * u2 + c
    return jnp.where(small, us**3 * poly / jnp.cosh(us), ud - jnp.tanh(ud))


def gauss_markov_bridge(dts, sigma, correlation_time):
    r"""The integral $I = \int x\,dt$ of a stationary first-order Gauss–Markov process x
    (σ, $T_c$) over intervals `dts`, given x at both ends (an Ornstein–Uhlenbeck bridge):
    $I \mid x_k, x_{k+1} \sim N\big(a\,(x_k + x_{k+1}),\ s^2\big)$ with
    $a = T_c\tanh u$, $s^2 = 4\sigma^2T_c^2\,(u - \tanh u)$, $u = \Delta t/(2T_c)$
    ($s^2 = 2\sigma^2T_c[\Delta t - 2T_c\tanh u] \approx \sigma^2\Delta t^3/(6T_c)$ for
    $\Delta t \ll T_c$, $\approx 2\sigma^2T_c\Delta t$ for $\Delta t \gg T_c$).

    With the exact samples of [`gauss_markov`][hrgjax.noise.gauss_markov] this is the exact
    joint law of the samples and their integrals at any $\Delta t/T_c$ — its second moment
    $E[I^2] = 2\sigma^2T_c[\Delta t - T_c(1 - e^{-\Delta t/T_c})]$ — where the trapezoid
    $\tfrac12(x_k + x_{k+1})\Delta t$ holds only for $\Delta t \ll T_c$.

    **Returns:** (a, s) per interval [s], [rad] (the units of σ × s).
    """
    check_values("gauss_markov_bridge: dts", dts, FINITE_NONNEGATIVE,
                 "intervals >= 0 [s]")  # fmt: skip
    dts = device(dts, float) if isinstance(dts, list | tuple) else dts  # failed in `0.5 * dts`
    check_values("gauss_markov_bridge: sigma", sigma, FINITE_NONNEGATIVE,
                 "a standard deviation >= 0")  # fmt: skip
    check_values("gauss_markov_bridge: correlation_time", correlation_time,
                 FINITE_POSITIVE, "> 0 [s]")  # fmt: skip
    return _bridge(dts, int_as_float(sigma), int_as_float(correlation_time))


@fused
def _bridge(dts, sigma, correlation_time):
    """`gauss_markov_bridge`'s arithmetic, one program per shape and type (eagerly ≈ 13
    operations, each compiled on a new input shape or type)."""
    u = 0.5 * dts / correlation_time
    g = _u_minus_tanh(u)
    pos = g > 0.0  # an empty interval (Δt = 0) has no integral and no finite √ slope
    s = 2.0 * sigma * correlation_time * jnp.where(pos, jnp.sqrt(jnp.where(pos, g, 1.0)), 0.0)
    return correlation_time * jnp.tanh(u), s


def _check_rate_noise(key, ts, noise, start=None) -> tuple:
    ts = _check_times("rate_noise_angle", key, ts)
    _check_noise("rate_noise_angle", noise)
    if start is None:
        return key, ts, noise
    check_numbers("rate_noise_angle: start", start, "one time [s]", shape=())
    first, v = concrete_value(ts), concrete_value(start)
    if v is not None and not np.isfinite(v):
        raise ValueError(f"rate_noise_angle: start must be a finite time [s]; got {float(v)}")
    if v is not None and first is not None and np.size(first) and float(v) > first[0]:
        raise ValueError(f"rate_noise_angle: start must be <= ts[0] = {first[0]:g} s (the "
                         f"integral runs from it); got {float(v):g}")  # fmt: skip
    return key, ts, noise, int_as_float(start)


# one program per shape (it compiled gauss_markov's scan on every eager call)
@_checked(_check_rate_noise)
def rate_noise_angle(key, ts, noise: Noise, start=None):
    """Integrated equivalent-input-rate noise ∫(ARW + Gauss–Markov) dt at `ts` [rad], from
    `ts[0]` (0 there) or, given, from `start` [s] (≤ `ts[0]`: the gyro's switch-on; a window
    late in a run then carries the noise of the time before it).

    Exact at any sample interval: the Gauss–Markov rate's samples are drawn exactly
    ([`gauss_markov`][hrgjax.noise.gauss_markov]) and its integral over each interval from
    their law given both ends ([`gauss_markov_bridge`][hrgjax.noise.gauss_markov_bridge]),
    with normals from `jax.random.fold_in(key, 1)`, so every other draw is the key's as
    before. (The trapezoid of the samples acted, for Δt ≳ T_c, as white rate noise of
    density σ²Δt instead of 2σ²T_c: an Allan deviation 2.1× too large at Δt = 10 T_c.)
    The time from `start` to `ts[0]` adds one draw of its integral (normals from
    `fold_in(key, 2)`; [`noise_before`][hrgjax.noise.noise_before]): 0 where `start` is
    `ts[0]`, so the draws at `ts` are those without `start`.
    """
    k_arw, k_gm = jax.random.split(key)
    dts = jnp.diff(ts)
    arw = noise.angle_random_walk * jnp.sqrt(dts) * jax.random.normal(k_arw, dts.shape)
    gm = gauss_markov(k_gm, ts, noise.bias_instability, noise.correlation_time)
    a, s = gauss_markov_bridge(dts, noise.bias_instability, noise.correlation_time)
    bridge = jax.random.normal(jax.random.fold_in(key, 1), dts.shape)
    gm_inc = a * (gm[1:] + gm[:-1]) + s * bridge
    angle = jnp.concatenate([jnp.zeros(1), jnp.cumsum(arw + gm_inc)])
    if start is None:
        return angle
    span = jnp.maximum(ts[0] - start, 0.0)
    return angle + noise_before(jax.random.fold_in(key, 2), span, gm[0], noise)


def noise_before(key, span, rate0, noise: Noise):
    r"""One draw of the rate noise's integral [rad] over the `span` [s] (≥ 0) that ends where
    the Gauss–Markov rate is `rate0` [rad/s]: the ARW's $N\sqrt{T}\,w_1$ and, the stationary
    process being time-reversible, its rate at the span's start
    $x_s = \phi x_0 + \sigma\sqrt{1-\phi^2}\,w_2$ ($\phi = e^{-T/T_c}$) and the bridge's
    integral $a(x_s + x_0) + s\,w_3$ ([`gauss_markov_bridge`][hrgjax.noise.gauss_markov_bridge]).
    Exactly 0 at `span` = 0. (`rate_noise_angle`'s time before its first sample.)"""
    w = jax.random.normal(key, (3,))
    sigma, tc = noise.bias_instability, noise.correlation_time
    span = jnp.asarray(span, float)
    arw = noise.angle_random_walk * jnp.sqrt(span) * w[0]
    phi = jnp.exp(-span / tc)
    q = 1.0 - phi**2  # 0 at span 0, where √ has no finite slope
    sd = jnp.where(q > 0.0, jnp.sqrt(jnp.where(q > 0.0, q, 1.0)), 0.0)
    x_start = phi * rate0 + sigma * sd * w[1]
    a, s = _bridge(span, sigma, tc)
    return arw + a * (x_start + rate0) + s * w[2]


def draw_run_bias(key, noise: Noise):
    """One switch-on bias [rad/s] (equivalent input rate)."""
    _check_key("draw_run_bias", key)
    _check_noise("draw_run_bias", noise)
    return noise.run_bias * jax.random.normal(key, ())
