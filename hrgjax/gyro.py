"""A whole-angle HRG: resonator + loops + readout + noise + environment sensitivities."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import plausible
from ._checks import check_finite, check_positive, is_concrete, numeric_problem
from .noise import Noise
from .resonator.control import LIMITS as CONTROL_LIMITS
from .resonator.control import Control
from .resonator.params import LIMITS as RESONATOR_LIMITS
from .resonator.params import (
    Resonator,
    TemperatureLaw,
    as_parameter,
    check_laws_at,
    checked_temperature,
    concrete_fields,
    evaluate_at,
    refuse_unconverted,
)
from .resonator.readout import LIMITS as READOUT_LIMITS
from .resonator.readout import Readout
from .units import T_REF_C


def _vector3(x):
    problem = numeric_problem(x)
    if problem is not None:
        raise TypeError(f"Gyro.g_sensitivity must be 3 real numbers [rad/s per g], shape (3,) "
                        f"(or one for every axis); got {problem}")  # fmt: skip
    host_list = isinstance(x, list | tuple) and not any(
        isinstance(v, jax.Array) for v in jax.tree.leaves(x)
    )  # a list holding a tracer is stacked by jnp
    x = jnp.asarray(np.asarray(x) if host_list else x, dtype=float)
    if x.ndim == 0:
        x = jnp.broadcast_to(x, (3,))
    if x.shape[-1:] != (3,):
        raise ValueError(f"Gyro.g_sensitivity must have shape (3,) [rad/s per g]; got {x.shape}")
    if is_concrete(x):  # a NaN ran the solver out of steps
        check_finite("Gyro.g_sensitivity", x)
    return x


class DriftTerms(eqx.Module):
    r"""Drift mechanisms beyond bias and g-sensitivity, as equivalent input rate [rad/s]
    (added to the table rate, like `Gyro.rate_bias`).

    $$\Omega_{\rm in} \mathrel{+}= c_{\dot T}\,\dot T + b_L\,(T_i - T_0)
    + b_w\,e^{-(t-t_0)/\tau_w} + \kappa_\Omega\,\Omega^3,\qquad
    \dot T_i = (T - T_i)/\tau_{th},\; T_i(t_0) = T(t_0)$$

    with $t_0$ the start of the run (switch-on) and $T_0$ = 20 °C. The lagged temperature is
    exact for the profile's piecewise-linear temperature
    ([`Profile.lagged_temperature_at`][hrgjax.Profile.lagged_temperature_at]). They are
    the physical side of the catalogue's `thermal_rate`, `thermal_lag`, `warmup_transient`
    and `rate_scale_factor` (PHYSICS.md §10: the catalogue term is −k_e times these).

    **Arguments:**

    - `temperature_rate`: $c_{\dot T}$ [rad/s per °C/s].
    - `lag`: $b_L$ [rad/s per °C]; `lag_time`: $\tau_{th}$ [s] (> 0).
    - `warmup`: $b_w$ [rad/s]; `warmup_time`: $\tau_w$ [s] (> 0).
    - `rate_cubic`: $\kappa_\Omega$ [s²] (a rate-dependent scale factor 1 + κ_Ω Ω²).

    The coefficients must lie in their `hrgjax.plausible.RANGES` (`DRIFT_PLAUSIBLE`: the
    warm-up within ±0.1 rad/s, as `Gyro.rate_bias`), or are refused naming the unit a value
    looks like (°/h typed as rad/s).
    """

    temperature_rate: jax.Array = eqx.field(converter=as_parameter, default=0.0)
    lag: jax.Array = eqx.field(converter=as_parameter, default=0.0)
    lag_time: jax.Array = eqx.field(converter=as_parameter, default=300.0)
    warmup: jax.Array = eqx.field(converter=as_parameter, default=0.0)
    warmup_time: jax.Array = eqx.field(converter=as_parameter, default=600.0)
    rate_cubic: jax.Array = eqx.field(converter=as_parameter, default=0.0)

    def __check_init__(self):
        refuse_unconverted(self)
        for name, value in concrete_fields(self, ("lag_time", "warmup_time")):
            check_positive(f"DriftTerms.{name}", value, "s")
        for name, value in concrete_fields(self, tuple(DRIFT_PLAUSIBLE)):
            check_finite(f"DriftTerms.{name}", value)
            plausible.check(f"DriftTerms.{name}", value, DRIFT_PLAUSIBLE[name])

    def input_rate(self, profile, t):
        """The added equivalent input rate [rad/s] at time t [s] of `profile`."""
        rate, _, temperature, _ = profile.sample(t)
        t_dot = profile.temperature_rate_at(t)
        lagged = profile.lagged_temperature_at(t, self.lag_time)
        return (
            self.temperature_rate * t_dot
            + self.lag * (lagged - T_REF_C)
            + self.warmup * jnp.exp(-(t - profile.t[0]) / self.warmup_time)
            + self.rate_cubic * rate**3
        )


DRIFT_PLAUSIBLE = {
    "temperature_rate": "gyro_temperature_rate",
    "lag": "gyro_thermal_lag",
    "warmup": "gyro_warmup",
    "rate_cubic": "gyro_rate_cubic",
}
"""Each `DriftTerms` coefficient's range in [`hrgjax.plausible.RANGES`][hrgjax.plausible.RANGES]
(a datasheet's °/h typed as rad/s is refused, the unit named)."""

PLAUSIBLE = {"rate_bias": "gyro_rate_bias", "g_sensitivity": "gyro_g_sensitivity"}
"""`Gyro.rate_bias`'s and `Gyro.g_sensitivity`'s ranges in `hrgjax.plausible.RANGES`; `simulate`
holds them (with `DRIFT_PLAUSIBLE`'s and `hrgjax.noise.PLAUSIBLE`'s) at run time too."""


_NO_NOISE = " (for a noise-free gyro use gyro.without_noise() or noise=None)"
_PARTS = {  # field: (class, None allowed, {type found: hint})
    "resonator": (Resonator, False, {}),
    "control": (Control, False, {type(None): " (hrgjax.Control.free() has no loops)"}),
    "readout": (Readout, False, {type(None): " (hrgjax.Readout() is a perfect one)"}),
    "noise": (
        Noise,
        True,
        {
            bool: _NO_NOISE,
            float: _NO_NOISE,
            int: _NO_NOISE,
            type: " (an instance, e.g. hrgjax.Noise(...))",
        },
    ),
    "drift_terms": (DriftTerms, True, {type: " (an instance, e.g. hrgjax.DriftTerms(...))"}),
}
"""`Gyro`'s sub-module fields: each an instance of its class (or None where allowed)."""


def _kind(x) -> str:
    """`x` for a one-line error: short reprs of numbers, bools, str and None; else its type
    (and shape for an array)."""
    if x is None:
        return "None"
    if hasattr(x, "shape") and hasattr(x, "dtype"):
        return f"{type(x).__name__} (dtype {x.dtype}, shape {tuple(x.shape)})"
    if isinstance(x, bool | int | float | str | None):
        text = repr(x)
        return f"{type(x).__name__} {text}" if len(text) <= 40 else type(x).__name__
    return type(x).__name__


class Gyro(eqx.Module):
    """A hemispherical resonator gyro in whole-angle mode.

    **Arguments:**

    - `resonator`: the [`hrgjax.Resonator`][] (may carry temperature laws).
    - `control`: the loops, [`hrgjax.Control`][].
    - `readout`: pickoff errors, [`hrgjax.Readout`][].
    - `noise`: [`hrgjax.Noise`][] or `None` for a noise-free gyro.
    - `rate_bias`: deterministic bias, equivalent input rate [rad/s] (may be a
      `TemperatureLaw`; within ±0.1 rad/s, `plausible.RANGES["gyro_rate_bias"]`: 0.3 °/h is
      `0.3 * hrgjax.units.DEG_PER_H`).
    - `g_sensitivity`: drift per specific force along case axes x, y, z, equivalent input rate
      [rad/s per g], shape (3,) (within ±4·10⁻³, `RANGES["gyro_g_sensitivity"]`).

    - `drift_terms`: further drift mechanisms ([`hrgjax.DriftTerms`][]: temperature rate,
      thermal lag, warm-up, rate-cubic scale factor), or `None`.

    A value beyond its range is refused in one line naming the datasheet units it looks like
    (`hrgjax.plausible.relaxed(gyro_rate_bias=…)` widens it); `simulate` holds values put in
    with `eqx.tree_at` or traced (`hg.sweep`) to the same ranges.
    """

    resonator: Resonator
    control: Control = Control()
    readout: Readout = Readout()
    noise: Noise | None = None
    rate_bias: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter, default=0.0)
    g_sensitivity: jax.Array = eqx.field(converter=_vector3, default=0.0)
    drift_terms: DriftTerms | None = None

    def __check_init__(self):
        for name, (cls, optional, hint) in _PARTS.items():
            value = getattr(self, name)
            if isinstance(value, cls) or (optional and value is None):
                continue
            form = f"a hrgjax.{cls.__name__}" + (" or None" if optional else "")
            got = "the class itself" if value is cls else _kind(value)
            extra = hint.get(type(value) if value is not cls else type, "")
            raise TypeError(f"Gyro.{name} must be {form}; got {got}{extra}")
        refuse_unconverted(self)
        for name, value in concrete_fields(self, tuple(PLAUSIBLE)):
            check_finite(f"Gyro.{name}", value)  # g_sensitivity: by its converter too
            plausible.check(f"Gyro.{name}", value, PLAUSIBLE[name])

    def at(self, temperature_c) -> Gyro:
        """This gyro with every temperature law evaluated at `temperature_c` [°C] (real
        numbers; concrete ones finite and inside `plausible.RANGES`, else a one-line error)."""
        out = evaluate_at(self, checked_temperature(temperature_c))
        for part, limits in (("resonator", RESONATOR_LIMITS), ("control", CONTROL_LIMITS),
                             ("readout", READOUT_LIMITS)):  # fmt: skip
            check_laws_at(f"gyro.{part}", getattr(self, part), getattr(out, part),
                          temperature_c, limits)  # fmt: skip
        check_laws_at("gyro", self, out, temperature_c, {})
        return out

    def in_mode(self, mode: str) -> Gyro:
        """The same gyro run in another operating mode: `"wa"` (whole-angle) or `"ftr"`
        (force-to-rebalance; [`hrgjax.Control`][] `mode`)."""
        return eqx.tree_at(lambda g: g.control, self, dataclasses.replace(self.control, mode=mode))

    def without_noise(self) -> Gyro:
        """The same gyro with its noise switched off."""
        return eqx.tree_at(lambda g: g.noise, self, None, is_leaf=lambda x: x is None)

    @property
    def k_e(self):
        """The resonator's angular gain k_e (a temperature law if it has one)."""
        return self.resonator.k_e


def check_one(gyro: Gyro, name: str = "gyro") -> None:
    """Refuse, in one line naming the field, a gyro that holds a batch of values (a leaf
    of another shape than one value, or 3 for `g_sensitivity`): what `jax.vmap` maps over,
    never one run's gyro (`simulate` failed deep in its solve with a shape error)."""
    for path, leaf in jax.tree_util.tree_flatten_with_path(gyro)[0]:
        where = jax.tree_util.keystr(path)
        want = (3,) if where == ".g_sensitivity" else ()
        shape = tuple(np.shape(leaf))
        if shape != want:
            form = "3 values, shape (3,)" if want else "one value, shape ()"
            raise ValueError(f"{name}{where} must be {form}; got shape {shape} (a batch of "
                             "gyros: jax.vmap over the call, or hrgjax.sweep)")  # fmt: skip
