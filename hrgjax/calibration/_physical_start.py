"""Starting values of the physical fit from per-temperature harmonic fits (no simulation)."""

from __future__ import annotations

import math

import numpy as np

from ..units import DEG, T_REF_C
from ._compensator import split_targets
from .reduce import K_E_NOMINAL


def _levels(temperature_c) -> np.ndarray:
    """Temperatures (rounded to 1e-6 °C) held for at least 3 windows: a harmonic fit
    (offset, cos 2θ, sin 2θ) needs 3. A ramp's windows each have a temperature of their own
    and are left out (a minimum-norm fit of one point is no start)."""
    temps, counts = np.unique(np.round(temperature_c, 6), return_counts=True)
    held = temps[counts >= 3]
    return held if held.size else temps


def initial_values(windows, k_e: float = K_E_NOMINAL) -> np.ndarray:
    """Starting values from per-temperature harmonic fits of reduced drift and SF (at the
    temperatures held for at least 3 windows of each kind)."""
    static, moving = split_targets(windows)
    temps = _levels(static.temperature_c)
    amp, phase, offset = [], [], []
    for temp in temps:
        m = np.abs(static.temperature_c - temp) < 1e-6
        th = static.wave_angle_deg[m] * DEG
        d = (static.rate_dps[m] - static.table_rate_dps[m]) * DEG
        basis = np.stack([np.ones_like(th), np.cos(2 * th), np.sin(2 * th)], axis=1)
        c0, c, s = np.linalg.lstsq(basis, d, rcond=None)[0]
        amp.append(2 * k_e * math.hypot(c, s))
        phase.append(0.5 * math.atan2(c, -s))
        offset.append(c0)
    dt = temps - T_REF_C
    phase = 0.5 * np.unwrap(2 * np.asarray(phase))
    deg = min(len(temps) - 1, 2)
    bias = np.polyfit(dt, offset, deg)[::-1] if len(temps) > 1 else np.array([offset[0]])
    bias = np.concatenate([bias, np.zeros(3 - bias.size)])
    if len(temps) > 1:
        lam, log_d0 = np.polyfit(dt, np.log(np.maximum(amp, 1e-30)), 1)
        th1, th0 = np.polyfit(dt, phase, 1)
    else:
        lam, log_d0, th1, th0 = 0.0, math.log(max(amp[0], 1e-30)), 0.0, phase[0]
    mt = _levels(moving.temperature_c)
    s0, gains, cross = [], [], []
    for temp in mt:
        m = np.abs(moving.temperature_c - temp) < 1e-6
        th = moving.wave_angle_deg[m] * DEG
        sf = moving.rate_dps[m] / moving.table_rate_dps[m]
        basis = np.stack([np.ones_like(th), np.cos(2 * th), np.sin(2 * th)], axis=1)
        a0, ac, asn = np.linalg.lstsq(basis, sf, rcond=None)[0]
        s0.append(a0)
        gains.append(-ac / (2 * a0))
        cross.append(-asn / (2 * a0))
    dtm = mt - T_REF_C
    if len(mt) > 1:
        kt, k0 = np.polyfit(dtm, np.asarray(s0) * k_e, 1)
        g1, g0 = np.polyfit(dtm, gains, 1)
    else:
        kt, k0, g1, g0 = 0.0, s0[0] * k_e, 0.0, gains[0]
    return np.array(
        [
            k0,
            kt / k0,
            *(bias / k0 * k_e),
            math.exp(log_d0),
            lam,
            th0,
            th1,
            g0,
            g1,
            float(np.mean(cross)),
        ]
    )
