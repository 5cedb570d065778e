"""Datasets with a hidden effect, in the data contract, built on `simulate` (DISCOVERY.md §3.1).

The base gyro is the default one reduced to the nominal model's physics:
`presets.tvg3_like(temperature_laws=False)` (every law frozen at +20 °C) with a perfect readout
and ideal loops, so its drift is bias + damping anisotropy, with the preset's noise. (With the
preset's real loops the base is not null: at 5 °/s the closed loops add a 2θ ripple of 3·10⁻⁵
to the true rate, which the search rightly flags as a scale-factor ripple.) One effect is then
put back through the gyro's own parameters, at a chosen size:

| effect | size means | how it is injected |
|---|---|---|
| `damping_anisotropy_temperature` | λ [1/°C] | Δ(1/τ)(T) = Δ₂₀ e^{λΔT} |
| `bias_temperature` | slope [°/h/°C] | rate bias + slope·ΔT |
| `angular_gain_temperature` | κ_T [1/°C] | k_e(T) = k_e(1 + κ_T ΔT) |
| `readout_gain_mismatch` | g [–] | pickoff gain mismatch g |

Effects without a mechanism in the simulator yet (thermal rate and lag, warm-up, rate scale
factor) and those needing a quadrature offset or ±g orientations are not generated yet.
"""

from __future__ import annotations

import equinox as eqx
import jax

from ..calibration.experiment import rotation_plan, run_plan, static_plan
from ..data import MeasuredData, concat
from ..gyro import Gyro
from ..presets import tvg3_like
from ..resonator.control import Control
from ..resonator.params import TemperatureLaw
from ..resonator.readout import Readout
from ..units import DEG_PER_H

GENERATED = (
    "damping_anisotropy_temperature",
    "bias_temperature",
    "angular_gain_temperature",
    "readout_gain_mismatch",
)
"""Effects the generator can hide."""

TEMPERATURES = (-40.0, -15.0, 10.0, 35.0, 60.0)
ANGLES = tuple(float(a) for a in range(-90, 90, 20))


def base_gyro(noise: bool = True) -> Gyro:
    """The default gyro with only the nominal model's physics (module docstring)."""
    g = tvg3_like(temperature_laws=False, noise=noise)
    return eqx.tree_at(lambda g: (g.readout, g.control), g, (Readout(), Control(ideal=True)))


def inject(gyro: Gyro, effect: str | None, size: float) -> Gyro:
    """`gyro` with `effect` put in at `size` (table in the module docstring); `None` = null."""
    if effect is None:
        return gyro
    res = gyro.resonator
    if effect == "damping_anisotropy_temperature":
        law = TemperatureLaw(res.delta_inv_tau, lam=size)
        return eqx.tree_at(lambda g: g.resonator.delta_inv_tau, gyro, law)
    if effect == "bias_temperature":
        law = TemperatureLaw(gyro.rate_bias, size * DEG_PER_H)
        return eqx.tree_at(lambda g: g.rate_bias, gyro, law)
    if effect == "angular_gain_temperature":
        law = TemperatureLaw(res.k_e, res.k_e * size)
        return eqx.tree_at(lambda g: g.resonator.k_e, gyro, law)
    if effect == "readout_gain_mismatch":
        return eqx.tree_at(lambda g: g.readout, gyro, Readout(gain_mismatch=size))
    raise ValueError(f"cannot generate {effect!r} yet; choose from {GENERATED} or None")


def hidden_effect_dataset(
    effect: str | None,
    size: float,
    *,
    key: jax.Array,
    duration_s: float = 60.0,
    temperatures_c=TEMPERATURES,
    angles_deg=ANGLES,
) -> MeasuredData:
    """A dwell-grid bench session (static and 5 °/s runs at every temperature × angle, one
    switch-on) of the base gyro with `effect` hidden at `size`."""
    gyro = inject(base_gyro(), effect, size)
    k_static, k_rot, k_bias = jax.random.split(key, 3)
    static = static_plan(temperatures_c, angles_deg, duration_s=duration_s, dt_out=0.5)
    rotation = rotation_plan(temperatures_c, angles_deg, duration_s=duration_s)
    a = run_plan(gyro, static, key=k_static, bias_key=k_bias)
    b = run_plan(gyro, rotation, key=k_rot, bias_key=k_bias, first_run=static.size)
    return concat([a, b])
