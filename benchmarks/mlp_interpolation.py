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

`--quick`: the prior on the demo's quick plan (`run_study(quick=True)`'s calibration,
−40/+20/+60 °C, so t_scale 50 °C against 20 °C above; seed 0 is the demo's switch-on and
network key), tested at its levels and between them (−10, +40 °C), 15° steps, 120-s runs;
each cell the static drift error [°/h] / the angle error at the end of the 5 °/s runs (the
demo's figure) / the largest during them [°], RMS over the test angles. Columns: the MLP
without the prior, with the defaults, with the defaults × (T_REF/t_scale)⁴ (T_REF 20 °C:
the weights in physical units, °C, measured and not adopted: docs/calibration.md), and the
default end-to-end MLP (≈ 1.5 min a seed).

Usage: `nice .venv/bin/python benchmarks/mlp_interpolation.py [--beyond | --quick] [SEED ...]`
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
    seed_plan,
    static_plan,
)
from hrgjax.calibration.study import bench_session

LEVELS = (0.0, 20.0, 40.0)
TEST_T = (0.0, 10.0, 20.0, 30.0, 40.0)
BEYOND_T = (-40.0, -20.0, 0.0, 20.0, 40.0, 60.0)
BETWEEN = (10.0, 30.0)
MLP_KEY = 3
QUICK_T = (-40.0, -10.0, 20.0, 40.0, 60.0)
QUICK_LEVELS = (-40.0, 20.0, 60.0)
T_REF = 20.0  # [°C] the physical-units variant: weights × (T_REF / t_scale)⁴


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


def quick(seeds):
    """The quick plan's calibration (as `run_study(quick=True, key=key(seed))`), tested at
    `QUICK_T`: at-level against between-level errors, with and without the prior."""
    print(f"machine: {machine()}")
    gyro, angles = hg.presets.tvg3_like(), tuple(range(-90, 91, 15))
    for seed in seeds:
        k_cal, k_test, k_bias, k_net = jax.random.split(jax.random.key(seed), 4)
        cal = bench_session(gyro, seed_plan(True), key=k_cal, bias_key=k_bias)
        plans = [static_plan(QUICK_T, angles, 120.0, 0.5),
                 rotation_plan(QUICK_T, angles, 5.0, 120.0, 0.5)]  # fmt: skip
        test = bench_session(gyro, plans, key=k_test, bias_key=k_bias,
                             first_run=len(np.unique(cal.run)))  # fmt: skip
        windows = reduce(cal)
        t_scale = 0.5 * (max(QUICK_LEVELS) - min(QUICK_LEVELS))
        f = (T_REF / t_scale) ** 4
        makers = {
            "MLP no prior": MLPCompensator(drift_t_curvature=0.0, sf_t_curvature=0.0),
            "MLP prior": MLPCompensator(),
            f"MLP prior × {f:.4g}": MLPCompensator(
                drift_t_curvature=1e-3 * f, sf_t_curvature=0.1 * f
            ),  # fmt: skip
            "MLP end-to-end": MLPCompensator(e2e_steps=100, mode="end_to_end"),
        }
        comps = {"Fourier+T²": FourierCompensator(temperature_degree=2).fit(windows)}
        for label, comp in makers.items():
            comps[label] = comp.fit(windows, key=k_net, raw=cal)
        table = accuracy_table(comps, test, QUICK_T)
        print(f"\nseed {seed}: static drift [°/h] / end angle / largest angle error at 5 °/s [°]")
        print("| T [°C] | " + " | ".join(comps) + " |")
        print("|---|" + "---|" * len(comps))
        for temp in QUICK_T:
            cells = [f"{table[k]['static_drift_dph'][temp]:.3f} / "
                     f"{table[k]['angle_error_deg'][temp]:.4f} / "
                     f"{table[k]['max_angle_error_deg'][temp]:.4f}" for k in comps]  # fmt: skip
            between = "" if temp in QUICK_LEVELS else " (between)"
            print(f"| {temp:+.0f}{between} | " + " | ".join(cells) + " |")
        for label in comps:
            end = table[label]["angle_error_deg"]
            at = max(end[t] for t in QUICK_LEVELS)
            mid = max(end[t] for t in QUICK_T if t not in QUICK_LEVELS)
            print(f"seed {seed} {label}: end angle error, largest at the levels {at:.4f}°, "
                  f"between {mid:.4f}° ({mid / at:.3g}×)")  # fmt: skip


if __name__ == "__main__":
    args = sys.argv[1:]
    seeds = [int(s) for s in args if not s.startswith("--")]
    if "--quick" in args:
        quick(seeds or [0, 1])
    else:
        main(seeds or [0, 1], BEYOND_T if "--beyond" in args else TEST_T)
