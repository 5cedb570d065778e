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

import equinox as eqx
import jax
import jax.numpy as jnp

from ._checks import check_nonnegative, check_positive, is_concrete
from .resonator.params import TemperatureLaw, as_parameter


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
    """

    angle_white: jax.Array = eqx.field(converter=as_parameter, default=0.0)
    angle_random_walk: jax.Array = eqx.field(converter=as_parameter, default=0.0)
    bias_instability: jax.Array = eqx.field(converter=as_parameter, default=0.0)
    correlation_time: jax.Array = eqx.field(converter=as_parameter, default=100.0)
    run_bias: jax.Array = eqx.field(converter=as_parameter, default=0.0)
    amplitude_white: jax.Array = eqx.field(converter=as_parameter, default=0.0)

    def __check_init__(self):
        for name in NONNEGATIVE:
            value = getattr(self, name)
            if not isinstance(value, TemperatureLaw) and is_concrete(value):
                check_nonnegative(f"Noise.{name}", value, f"[{UNITS[name]}] (a standard deviation)")
        value = self.correlation_time
        if not isinstance(value, TemperatureLaw) and is_concrete(value):
            check_positive("Noise.correlation_time", value, "[s]")


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


def gauss_markov(key, ts, sigma, correlation_time):
    r"""Stationary first-order Gauss–Markov samples at times `ts` (exact discretisation).

    $x_{k+1} = e^{-\Delta t/T_c}x_k + \sigma\sqrt{1-e^{-2\Delta t/T_c}}\,w_k$, $x_0\sim N(0,\sigma^2)$.
    """
    dts = jnp.diff(ts)
    k0, k1 = jax.random.split(key)
    x0 = sigma * jax.random.normal(k0, ())
    phi = jnp.exp(-dts / correlation_time)
    w = jax.random.normal(k1, dts.shape) * sigma * jnp.sqrt(1.0 - phi**2)

    def step(x, inp):
        p, wk = inp
        x = p * x + wk
        return x, x

    _, xs = jax.lax.scan(step, x0, (phi, w))
    return jnp.concatenate([x0[None], xs])


def rate_noise_angle(key, ts, noise: Noise):
    """Integrated equivalent-input-rate noise ∫(ARW + Gauss–Markov) dt at `ts` [rad]."""
    k_arw, k_gm = jax.random.split(key)
    dts = jnp.diff(ts)
    arw = noise.angle_random_walk * jnp.sqrt(dts) * jax.random.normal(k_arw, dts.shape)
    gm = gauss_markov(k_gm, ts, noise.bias_instability, noise.correlation_time)
    gm_inc = 0.5 * (gm[1:] + gm[:-1]) * dts
    return jnp.concatenate([jnp.zeros(1), jnp.cumsum(arw + gm_inc)])


def draw_run_bias(key, noise: Noise):
    """One switch-on bias [rad/s] (equivalent input rate)."""
    return noise.run_bias * jax.random.normal(key, ())
