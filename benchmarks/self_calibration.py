"""Calibration without a turntable (issue 47): virtual precession at rest against the seed's
turntable calibration, and mode reversal in force-to-rebalance mode.

1. One bench session on `tvg3_like()` (one switch-on, several seeds): the turntable
   calibration of the seed (`seed_plan(quick=True)`: static and 5 °/s runs at −40/+20/+60 °C,
   19 angles, fitted by the grey box `PhysicalCompensator`) and the virtual-precession
   self-calibration (`precession_plan()`: two 0.5 °/s sweeps at each of the same
   temperatures, case at rest, fitted by `PrecessionCompensator`), both tested on the seed's
   quick static test grid (−90…+90° in 15° steps, 2 min). Prints the compensated static
   drift at each temperature, the ratio self-calibration / turntable, and each plan's bench
   time under the same `BenchModel` (chamber slew and soak, 1 min per segment change).
2. Mode reversal on the default gyro over −40…+60 °C (no noise): held at θ = θ_τ(T) + 45°
   (the damping anisotropy's largest bias) and θ + 90°, the damping anisotropy's bias left
   in the mean of the two readings over its bias at one angle (each isolated by the same
   runs with Δ(1/τ) = 0).

Usage: `.venv/bin/python benchmarks/self_calibration.py [--seeds N]`.
"""

import sys
import time

import equinox as eqx
import jax
import numpy as np
from _common import machine, report

import hrgjax as hg
from hrgjax.calibration import (
    BenchModel,
    BenchPlan,
    PhysicalCompensator,
    accuracy_table,
    bench_time_h,
    run_plan,
    seed_bench_plan,
    seed_plan,
    test_plan,
)
from hrgjax.calibration import self_calibration as sc
from hrgjax.calibration.experiment import SEED_TEMPERATURES
from hrgjax.calibration.study import bench_session
from hrgjax.units import DEG, DEG_PER_H

TEMPS = (-40.0, 20.0, 60.0)


def compare(seed: int):
    gyro = hg.presets.tvg3_like()
    k_cal, k_vp, k_test, k_bias = jax.random.split(jax.random.key(seed), 4)
    cal = bench_session(gyro, seed_plan(quick=True), key=k_cal, bias_key=k_bias)
    vp = sc.run_precession_plan(gyro, sc.precession_plan(TEMPS), key=k_vp, bias_key=k_bias)
    test = run_plan(gyro, test_plan(quick=True)[0], key=k_test, bias_key=k_bias)
    t0 = time.perf_counter()
    physical = PhysicalCompensator().fit(cal)
    t_phys = time.perf_counter() - t0
    t0 = time.perf_counter()
    self_cal = sc.PrecessionCompensator().fit(vp)
    t_vp = time.perf_counter() - t0
    table = accuracy_table({"turntable": physical, "vp": self_cal}, test)
    drift = {k: table[k]["static_drift_dph"] for k in table}
    print(f"seed {seed}: fits {t_phys:.1f} s (grey box) and {t_vp:.2f} s (sweeps)")
    for t in TEMPS:
        print(f"  {t:+5.0f} °C  turntable {drift['turntable'][t]:.4f} °/h   "
              f"self-calibration {drift['vp'][t]:.4f} °/h")  # fmt: skip
    return drift


def bench_times():
    """(seed's, self-calibration's) bench time [h]: the quick plans (−40/+20/+60 °C) and the
    full ones (11 temperatures); a sweep costs a static segment of its length (no table)."""
    bench = BenchModel()
    out = []
    for quick, temps in ((True, TEMPS), (False, SEED_TEMPERATURES)):
        plan = sc.precession_plan(temps)
        segs = [
            {"kind": "static", "temperature_c": float(t), "wave_angle_deg": 0.0,
             "duration_s": plan.duration_s}
            for t in np.asarray(plan.temperature_c)
        ]  # fmt: skip
        out.append((float(bench_time_h(seed_bench_plan(quick=quick), bench)),
                    float(bench_time_h(BenchPlan.from_segments(segs), bench))))  # fmt: skip
    return out


def reversal():
    base = hg.presets.tvg3_like(noise=False)
    gyro = base.in_mode("ftr")
    flat = eqx.tree_at(lambda g: g.resonator.delta_inv_tau, gyro, 0.0)
    worst = 0.0
    for temp in np.arange(-40.0, 61.0, 10.0):
        theta = float(gyro.at(temp).resonator.theta_tau) / DEG + 45.0
        prof = hg.Profile.held_angles([theta, theta + 90.0], 120.0, 20.0, temp)
        out = {}
        for name, g in (("with", gyro), ("without", flat)):
            rec = hg.simulate(g, prof, dt_out=1.0)
            out[name] = sc.mode_reversal(rec.t, rec.rebalance_rate, prof, settle_s=30.0)
        one = float(out["with"].readings[0] - out["without"].readings[0])
        left = float(out["with"].bias - out["without"].bias)
        worst = max(worst, abs(left / one))
        print(f"  {temp:+5.0f} °C at {theta:6.1f}°: one-angle bias {one / DEG_PER_H:+.4f} °/h, "
              f"left after reversal {left / DEG_PER_H:+.2e} °/h ({100 * abs(left / one):.3f} %)")  # fmt: skip
    return worst


def main(seeds: int):
    print(f"machine: {machine()}")
    for name, (t_seed, t_vp) in zip(("quick", "full"), bench_times(), strict=True):
        print(f"bench time, {name} plans: seed's turntable {t_seed:.2f} h, virtual precession "
              f"{t_vp:.2f} h")  # fmt: skip
        report(f"self-calibration bench time / seed's ({name} plans)", t_vp / t_seed, "",
               target="≤ 0.5")  # fmt: skip
    ratios = {t: [] for t in TEMPS}
    for seed in range(seeds):
        drift = compare(seed)
        for t in TEMPS:
            ratios[t].append(drift["vp"][t] / drift["turntable"][t])
    for t in TEMPS:
        r = np.asarray(ratios[t])
        report(f"static drift, self-calibration / turntable at {t:+.0f} °C (median of {seeds})",
               float(np.median(r)), "", target="≤ 1.5")  # fmt: skip
        print(f"    per seed: {np.round(r, 3).tolist()}")
    print("\nmode reversal, default gyro (FTR, no noise):")
    worst = reversal()
    report("mode reversal: damping-anisotropy bias left / one-angle bias (worst T)", 100 * worst,
           "%", target="≤ 1 %")  # fmt: skip


if __name__ == "__main__":
    n = int(sys.argv[sys.argv.index("--seeds") + 1]) if "--seeds" in sys.argv else 3
    main(n)
