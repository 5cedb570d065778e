"""The MLP compensator between sparse temperature levels, with and without its smoothness
prior in temperature (`MLPCompensator.drift_t_curvature`, `sf_t_curvature`).

Per seed, one bench session on `tvg3_like()` (one switch-on): calibration at 0/20/40 °C,
6 wave angles (−90…+60° every 30°) × 120-s static and 5 °/s runs per level; test at
0/10/20/30/40 °C, every 15°, 120-s runs, same switch-on, independent noise. Each cell is
the static drift error RMS over the test angles [°/h] / the largest angle error during the
5 °/s runs, RMS over the test angles [°] (`accuracy_table`), offset kept. Columns: raw,
Fourier+T² (`FourierCompensator(temperature_degree=2)`), the MLP without the prior (weights
0: the training before the prior, the same figures) and with the defaults (MLP key 3). Then the
ratio of the rotation error between levels (+10, +30 °C) to the largest at the levels, and
the MLP fit times side by side, warm (compiled; best of 3, interleaved).

`--beyond`: the same calibration, tested at −40, −20, 0, +20, +40, +60 °C instead (the
temperature-domain table of docs/calibration.md, beyond the calibrated range; `correct`'s
default, applied there), with the physical grey box (`PhysicalCompensator`) beside, without
the fit times (≈ 5 min a seed).

Usage: `nice .venv/bin/python benchmarks/mlp_interpolation.py [--beyond] [SEED ...]`
(default 0 1; ≈ 2 min a seed on 2 shared cores, mostly simulating).
"""

import sys
import time

import jax
import numpy as np
from _common import machine, report

import hrgjax as hg
from hrgjax.calibration import (
    FourierCompensator,
    MLPCompensator,
    NoCompensation,
    PhysicalCompensator,
    accuracy_table,
    reduce,
    rotation_plan,
    static_plan,
)
from hrgjax.calibration.study import bench_session

LEVELS = (0.0, 20.0, 40.0)
TEST_T = (0.0, 10.0, 20.0, 30.0, 40.0)
BEYOND_T = (-40.0, -20.0, 0.0, 20.0, 40.0, 60.0)
BETWEEN = (10.0, 30.0)
MLP_KEY = 3


def session(seed: int, test_t=TEST_T):
    gyro = hg.presets.tvg3_like()
    k_cal, k_test, k_bias = jax.random.split(jax.random.key(seed), 3)
    angles, test_angles = tuple(range(-90, 90, 30)), tuple(range(-90, 90, 15))
    plans = lambda temps, a: [
        static_plan(temps, a, 120.0, 0.5),
        rotation_plan(temps, a, 5.0, 120.0, 0.5),
    ]  # noqa: E731
    cal = bench_session(gyro, plans(LEVELS, angles), key=k_cal, bias_key=k_bias)
    n_cal = len(np.unique(cal.run))
    test = bench_session(gyro, plans(test_t, test_angles), key=k_test, bias_key=k_bias,
                         first_run=n_cal)  # fmt: skip
    return cal, test


def main(seeds, test_t=TEST_T):
    print(f"machine: {machine()}")
    makers = {
        "MLP no prior": lambda: MLPCompensator(drift_t_curvature=0.0, sf_t_curvature=0.0),
        "MLP prior": lambda: MLPCompensator(),
    }
    warm = {k: [] for k in makers}
    for seed in seeds:
        cal, test = session(seed, test_t)
        windows = reduce(cal)
        comps = {"raw": NoCompensation(),
                 "Fourier+T²": FourierCompensator(temperature_degree=2).fit(windows)}  # fmt: skip
        for label, make in makers.items():
            comps[label] = make().fit(windows, key=jax.random.key(MLP_KEY))
        if test_t != TEST_T:
            comps["physical"] = PhysicalCompensator().fit(windows, raw=cal)
        table = accuracy_table(comps, test, test_t)
        print(f"\nseed {seed}: static drift error [°/h] / largest angle error at 5 °/s [°]")
        print("| T [°C] | " + " | ".join(comps) + " |")
        print("|---|" + "---|" * len(comps))
        for temp in test_t:
            cells = [f"{table[k]['static_drift_dph'][temp]:.3f} / "
                     f"{table[k]['max_angle_error_deg'][temp]:.4f}" for k in comps]  # fmt: skip
            print(f"| {temp:+.0f}{' (between)' if temp in BETWEEN else ''} | "
                  + " | ".join(cells) + " |")  # fmt: skip
        if test_t != TEST_T:
            continue
        for label in makers:
            rot = table[label]["max_angle_error_deg"]
            ratio = max(rot[t] for t in BETWEEN) / max(rot[t] for t in LEVELS)
            report(f"seed {seed} {label}: rotation error between / at levels", ratio, "×",
                   target="≈ 1 (near the at-level error)")  # fmt: skip
        for _ in range(3):
            for label, make in makers.items():
                t0 = time.perf_counter()
                jax.block_until_ready(make().fit(windows, key=jax.random.key(MLP_KEY)))
                warm[label].append(time.perf_counter() - t0)
    if test_t != TEST_T:
        return
    print()
    for label in makers:
        print(f"{label}: fit {min(warm[label]):.2f} s warm (best of {len(warm[label])})")
    report("MLP fit time with / without the prior, warm", min(warm["MLP prior"])
           / min(warm["MLP no prior"]), "×", target="≤ 1.3× (brief)")  # fmt: skip


if __name__ == "__main__":
    args = sys.argv[1:]
    beyond = "--beyond" in args
    main([int(s) for s in args if s != "--beyond"] or [0, 1], BEYOND_T if beyond else TEST_T)
