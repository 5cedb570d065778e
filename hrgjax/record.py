"""`Record`: what a simulation returns."""

from __future__ import annotations

import warnings

import equinox as eqx
import jax
import numpy as np

from ._checks import concrete_value, is_concrete
from ._warn import user_stacklevel
from .data import MeasuredData
from .units import DEG, DEG_PER_S


class SaturationWarning(UserWarning):
    """`simulate`: the force-to-rebalance loop sat at its force limit
    (`Record.rebalance_saturated`)."""


def warn_saturated(record: Record, limit) -> None:
    """One line (`SaturationWarning`) when an eager run's rebalance force sat at its `limit`
    (`Control.rebalance_limit`) in any sample; nothing for a traced record."""
    sat = record.rebalance_saturated
    if sat is None or (sat := concrete_value(sat)) is None or not sat.any():
        return
    shown = f" = {float(limit):g}" if isinstance(limit, jax.Array) and is_concrete(limit) else ""
    reads = np.median(np.abs(np.asarray(record.rebalance_rate))[sat > 0]) / DEG_PER_S
    warnings.warn(f"simulate: the FTR loop saturated at Control.rebalance_limit{shown} in "
                  f"{100 * sat.mean():.3g} % of the samples (Record.rebalance_saturated): the "
                  f"output there reads the limit, ≈ ±{reads:.4g} °/s, not the rate; raise the "
                  "limit (2ωa₀k_e per rad/s of rate: ≈ 608 per °/s on the default gyro)",
                  SaturationWarning, stacklevel=user_stacklevel())  # fmt: skip


class Record(eqx.Module):
    """Simulated gyro output on the output grid (SI; angles electrical).

    Batched records (from `jax.vmap`) carry leading batch axes on every field.
    """

    t: jax.Array
    """Time [s]."""
    wave_angle: jax.Array
    """Measured wave angle, unwrapped [rad, electrical]: readout errors and noise included."""
    amplitude: jax.Array
    """Estimated principal amplitude (readout units)."""
    quadrature: jax.Array
    """Estimated quadrature amplitude (readout units)."""
    table_angle: jax.Array
    """Table (case) angle ∫Ω dt [rad]."""
    table_rate: jax.Array
    """Table rate [rad/s]."""
    temperature: jax.Array
    """Resonator temperature [°C]."""
    accel: jax.Array
    """Specific force along case axes [g], shape (..., n, 3)."""
    true_wave_angle: jax.Array
    """True pattern angle, no readout error or noise [rad, electrical]: the antinode's, on
    the branch |a| ≥ |q| (`hrgjax.resonator.averaged.canonical_angle`) in both models — where
    an open-loop ellipse passes the circle (a free wave 45° off a split) it turns by π/2."""
    frequency: jax.Array
    """PLL reference frequency ω_r [rad/s]."""
    drive: jax.Array
    """AGC effort: force amplitude F (force drive) or pump depth h (parametric)."""
    quadrature_force: jax.Array
    """Quadrature-loop effort f_qc."""
    k_e: jax.Array
    """Angular gain k_e at each sample (temperature laws evaluated)."""
    run: jax.Array
    """Run id."""
    rebalance_rate: jax.Array | None = None
    """Force-to-rebalance output [rad/s]: the rate read from the rebalance force
    ([`hrgjax.resonator.control.ftr_rate`][]); `None` in whole-angle mode."""
    rebalance_on: jax.Array | None = None
    """1 where the rebalance loop held the wave, 0 where the gyro ran whole-angle (a profile's
    `rebalance` schedule); `None` without one."""
    rebalance_saturated: jax.Array | None = None
    """1 where the rebalance force sat at `Control.rebalance_limit` (the loop saturated: the
    wave runs off and the FTR output there reads the limit, not the rate), else 0; `None`
    without a limit (or in whole-angle mode). `simulate` warns when an eager run has any."""
    precession: jax.Array | None = None
    """Commanded precession rate [rad/s, electrical] (the profile's schedule); `None` when
    the profile commands none."""
    mode: str = eqx.field(static=True, default="wa")
    """Operating mode the record was taken in: `"wa"` (whole-angle) or `"ftr"`."""

    def to_data(self):
        """The record as [`hrgjax.MeasuredData`][] in the units of the data contract.

        A batched record becomes consecutive runs numbered 0, 1, … in row-major order.

        **Raises:** `TypeError` for a traced record (inside `jax.jit`, `jax.vmap` or
        `jax.grad`): `MeasuredData` holds host data; call `to_data` on the record the
        jitted function returns."""
        if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(self)):
            raise TypeError(
                "Record.to_data: MeasuredData holds host data, and this record is traced "
                "(inside jax.jit, jax.vmap or jax.grad): call to_data outside them, on the "
                "Record the jitted function returns"
            )
        t = np.asarray(self.t)
        batch = t.shape[:-1]
        n = t.shape[-1]
        flat = lambda x: np.asarray(x, dtype=float).reshape(-1)
        if batch:
            runs = np.repeat(np.arange(int(np.prod(batch))), n)
        else:
            runs = np.full(n, int(np.asarray(self.run)))
        acc = np.asarray(self.accel, dtype=float).reshape(-1, 3)
        cols = {
            "time_s": flat(t),
            "run": runs.astype(np.int64),
            "temperature_c": flat(self.temperature),
            "table_rate_dps": flat(self.table_rate) / DEG_PER_S,
            "table_angle_deg": flat(self.table_angle) / DEG,
            "wave_angle_deg": flat(self.wave_angle) / DEG,
            "amplitude": flat(self.amplitude),
            "quadrature": flat(self.quadrature),
            "accel_x_g": acc[:, 0],
            "accel_y_g": acc[:, 1],
            "accel_z_g": acc[:, 2],
        }
        if self.precession is not None:
            cols["precession_dps"] = flat(self.precession) / DEG_PER_S
        if self.rebalance_rate is not None:
            cols["rebalance_rate_dps"] = flat(self.rebalance_rate) / DEG_PER_S
        if self.rebalance_on is not None:
            cols["rebalance_on"] = flat(self.rebalance_on)
        return MeasuredData(cols)
