"""How the synthetic data put a catalogue effect into a gyro: the injectors of the
catalogue's entries (`Effect.inject`: `inject(gyro, size)` → the gyro with the effect at
`size`; [`generate.inject`][hrgjax.discovery.generate.inject] says what `size` means for
each effect).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax.numpy as jnp

from ..gyro import DriftTerms

LAG_TIME_S = 600.0
"""Time constant of the generated thermal lag and warm-up [s]."""


def replace_leaf(where, value):
    """An injector: `gyro` with the leaf `where(gyro)` replaced by `value(gyro, size)`."""
    return lambda gyro, size: eqx.tree_at(where, gyro, value(gyro, size))


def set_drift_terms(fields):
    """An injector: `gyro` with the [`DriftTerms`][hrgjax.gyro.DriftTerms] `fields(size)`
    set (its other drift terms kept)."""

    def inject(gyro, size):
        old = gyro.drift_terms if gyro.drift_terms is not None else DriftTerms()
        kept = {f.name: getattr(old, f.name) for f in dataclasses.fields(DriftTerms)}
        new = DriftTerms(**(kept | fields(size)))
        return eqx.tree_at(lambda g: g.drift_terms, gyro, new, is_leaf=lambda x: x is None)

    return inject


def closed_loops(gyro, size):
    """The preset's closed loops with a frequency split Δω = `size` [rad/s]."""
    from ..presets import tvg3_like

    loops = tvg3_like(temperature_laws=False, noise=False).control
    where = lambda g: (g.control, g.resonator.delta_omega)
    return eqx.tree_at(where, gyro, (loops, jnp.asarray(size)))
