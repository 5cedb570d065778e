"""Virtual-precession sweeps as `PrecessionCompensator.fit` reads them: grouped by
temperature, each run's samples after the settling, and the checks that the sweeps at each
temperature determine the drift (samples left, both directions, the angle covered)."""

from __future__ import annotations

import numpy as np

from ..data import MeasuredData
from ..units import DEG, DEG_PER_S, EARTH_RATE, STILL_RATE_DPS

EARTH_RATE_DPS = EARTH_RATE / DEG_PER_S
"""Largest constant case rate mode reversal and the sweeps take [°/s] (0.00418: Earth's
rate, the most of it a bench's sensitive axis sees; `hrgjax.units.STILL_RATE_DPS`, 1e-3 °/s,
is below its vertical share Ω_E sin φ above 14° latitude)."""
CONSTANT_RATE_DPS = 1e-6 * EARTH_RATE_DPS
"""The most a rate beyond `STILL_RATE_DPS` may vary over a run (mode reversal, a sweep) and
count as constant [°/s]: half a change between mode reversal's holds would go into the
anisotropy whole."""


def at_rest(rate_dps) -> bool:
    """Whether a run's case rates `rate_dps` [°/s] (a profile's knots or a run's samples) are
    rest: within `STILL_RATE_DPS` (a rate table's readback jitter), or constant to
    `CONSTANT_RATE_DPS` and no larger than Earth's (`EARTH_RATE_DPS`: a bench on the Earth,
    whose rate then enters the drift's constant term, as in a static run on that bench)."""
    rate_dps = np.asarray(rate_dps, dtype=float)
    peak, spread = float(np.max(np.abs(rate_dps))), float(np.ptp(rate_dps))
    return peak <= STILL_RATE_DPS or (peak <= EARTH_RATE_DPS and spread <= CONSTANT_RATE_DPS)


MIN_SWEEP_SAMPLES = 20
"""Fewest samples a sweep must keep after `settle_s`."""

MIN_COVERAGE_DEG = 120.0
"""Least arc of wave angle (electrical, mod 180°) the sweeps turning each way must cover at
a temperature after `settle_s` [°]: the 2nθ harmonics are determined only over most of a
period — the 2θ and 4θ basis has condition number 1 over 180°, 1.3 over 165° (a plan's
sweeps read with a longer settle_s), 5 over 120°, 20 over 90° and 2900 over 30° (a 30° arc
put the drift 100× off)."""


def sweeps_by_temperature(data: MeasuredData, bin_c: float, settle_s: float):
    """[(temperature [°C], [(t, θ, ρ, used) per run])] sorted by temperature, each with runs
    turning both ways. **Raises:** `ValueError` for a turning table (not `at_rest`: beyond
    [`STILL_RATE_DPS`][hrgjax.units.STILL_RATE_DPS], readback jitter, unless constant and no
    larger than Earth's rate), a
    sweep that pauses, no sweeps, a sweep left with fewer than `MIN_SWEEP_SAMPLES` after
    `settle_s` [s] (checked before the directions: a settling longer than the sweeps leaves
    none), sweeps in one direction only, or covering less than `MIN_COVERAGE_DEG`."""
    by_temp: dict[float, list] = {}
    for idx in data.run_indices():
        t = data["time_s"][idx]
        rho = data["precession_dps"][idx] * DEG_PER_S
        if np.all(rho == 0):
            continue  # a static run: nothing to sweep
        run = int(data["run"][idx[0]])
        table = data["table_rate_dps"][idx]
        if not at_rest(table):  # jitter within STILL_RATE_DPS, or Earth's constant rate: rest
            raise ValueError(f"run {run}: the table turns (|table_rate_dps| up to "
                             f"{float(np.max(np.abs(table))):.3g} °/s, varying by "
                             f"{float(np.ptp(table)):.3g}); virtual-precession sweeps are taken "
                             f"with the case at rest (|table_rate_dps| ≤ STILL_RATE_DPS = "
                             f"{STILL_RATE_DPS:g} °/s, or constant and no larger than Earth's "
                             f"{EARTH_RATE_DPS:.4g} °/s)")  # fmt: skip
        temp = float(np.round(np.mean(data["temperature_c"][idx]) / bin_c) * bin_c)
        used = t - t[0] >= settle_s
        if np.any(rho[used] == 0):
            first = float(t[used][rho[used] == 0][0])
            raise ValueError(f"run {run}: the sweep pauses (precession_dps 0) at t = {first:g} s "
                             "after settling; give each sweep its own run")  # fmt: skip
        by_temp.setdefault(temp, []).append((t, data["wave_angle_deg"][idx] * DEG, rho, used))
    if not by_temp:
        raise ValueError("no virtual-precession sweeps in the data (every precession_dps is 0)")
    out = []
    for temp in sorted(by_temp):
        runs = by_temp[temp]
        short = min(runs, key=lambda r: int(r[3].sum()))
        if (kept := int(short[3].sum())) < MIN_SWEEP_SAMPLES:
            raise ValueError(
                f"at {temp:g} °C a sweep of {short[0][-1] - short[0][0]:g} s keeps {kept} samples "
                f"after settle_s = {settle_s:g} s, fewer than {MIN_SWEEP_SAMPLES}: give a "
                "settle_s shorter than the sweeps (or longer sweeps)"
            )
        signs = {float(np.sign(np.median(r[2][r[3]]))) for r in runs}
        if signs != {1.0, -1.0}:
            raise ValueError(
                f"at {temp:g} °C the sweeps turn one way only; the drift and the forcers' gain "
                "separate only with sweeps in both directions (precession_plan runs ±ρ)"
            )
        for sign, way in ((1.0, "+ρ"), (-1.0, "−ρ")):
            arcs = [r[1][r[3]] / DEG for r in runs if np.median(r[2][r[3]]) * sign > 0]
            covered = coverage_deg(arcs)
            if covered < MIN_COVERAGE_DEG:
                raise ValueError(
                    f"at {temp:g} °C the sweeps turning {way} cover {covered:.0f}° of the 180° "
                    f"(electrical) of wave angle the 2nθ harmonics need (≥ {MIN_COVERAGE_DEG:g}° "
                    "after settle_s): sweep over a half turn (180° electrical) in each direction "
                    "(precession_plan does)"
                )
        out.append((temp, runs))
    return out


def coverage_deg(arcs) -> float:
    """Degrees of the 180° (electrical) period visited by the wave angles [°] of `arcs` (each
    a run's samples, the path between them counted), in 1° bins."""
    seen = np.zeros(180, bool)
    for a in arcs:
        lo, hi = float(np.min(a)), float(np.max(a))
        if hi - lo >= 180.0:
            return 180.0
        start = int(np.floor(lo))
        bins = np.arange(start, start + int(np.ceil(hi - start)))
        seen[bins % 180] = True
    return float(seen.sum())
