"""A whole-angle HRG: resonator + loops + readout + noise + environment sensitivities."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .noise import Noise
from .resonator.control import Control
from .resonator.params import Resonator, TemperatureLaw, _param, evaluate_at
from .resonator.readout import Readout


def _vector3(x):
    x = jnp.asarray(np.asarray(x) if isinstance(x, list | tuple) else x, dtype=float)
    if x.ndim == 0:
        x = jnp.broadcast_to(x, (3,))
    if x.shape[-1:] != (3,):
        raise ValueError(f"Gyro.g_sensitivity must have shape (3,) [rad/s per g]; got {x.shape}")
    return x


class Gyro(eqx.Module):
    """A hemispherical resonator gyro in whole-angle mode.

    **Arguments:**

    - `resonator`: the [`hrgjax.Resonator`][] (may carry temperature laws).
    - `control`: the loops, [`hrgjax.Control`][].
    - `readout`: pickoff errors, [`hrgjax.Readout`][].
    - `noise`: [`hrgjax.Noise`][] or `None` for a noise-free gyro.
    - `rate_bias`: deterministic bias, equivalent input rate [rad/s] (may be a
      `TemperatureLaw`).
    - `g_sensitivity`: drift per specific force along case axes x, y, z, equivalent input rate
      [rad/s per g], shape (3,).
    """

    resonator: Resonator
    control: Control = Control()
    readout: Readout = Readout()
    noise: Noise | None = None
    rate_bias: jax.Array | TemperatureLaw = eqx.field(converter=_param, default=0.0)
    g_sensitivity: jax.Array = eqx.field(converter=_vector3, default=0.0)

    def at(self, temperature_c) -> Gyro:
        """This gyro with every temperature law evaluated at `temperature_c` [°C]."""
        return evaluate_at(self, temperature_c)

    def without_noise(self) -> Gyro:
        """The same gyro with its noise switched off."""
        return eqx.tree_at(lambda g: g.noise, self, None, is_leaf=lambda x: x is None)

    @property
    def k_e(self):
        """The resonator's angular gain k_e (a temperature law if it has one)."""
        return self.resonator.k_e
