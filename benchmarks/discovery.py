"""Discovery on dwell-grid data: recovery, false positives and gap shrink (issue 4 targets).

Datasets from `hrgjax.discovery.generate` (default gyro reduced to the nominal physics, with
its noise: white angle noise, ARW, Gauss–Markov bias instability, switch-on bias — coloured),
5 temperatures × 9 wave angles × 60 s, static and 5 °/s. The acceptance thresholds are the
library defaults, fixed before this run; seeds here (1000+) were not used to choose them.

Prints per effect: recovery of the right name, gap before / after / noise floor, and for the
null datasets the false-positive rate; wall time per dataset. Wilson 95 % intervals.

Usage: `.venv/bin/python benchmarks/discovery.py [--quick]`.
"""

import math
import sys
import time

import jax
import numpy as np
from _common import machine

from hrgjax.discovery import discover
from hrgjax.discovery.generate import GENERATED, hidden_effect_dataset

SIZES = {
    "damping_anisotropy_temperature": -0.04,
    "bias_temperature": 0.02,
    "angular_gain_temperature": 1e-5,
    "readout_gain_mismatch": 2e-3,
}


def wilson(k, n, z=1.96):
    if n == 0:
        return (float("nan"), float("nan"))
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return c - h, c + h


def main(quick: bool):
    n_each, n_null = (4, 8) if quick else (15, 50)
    print(f"machine: {machine()}; {n_each} datasets per effect, {n_null} nulls")
    times = []
    print(
        f"{'hidden effect':>32} {'right name':>12} {'95 % CI':>15} {'gap before':>11} "
        f"{'after':>7} {'floor':>7} {'after/floor':>11}"
    )
    for effect in GENERATED:
        hits, before, after, floor = 0, [], [], []
        for i in range(n_each):
            key = jax.random.key(1000 + 97 * i + len(effect))
            data = hidden_effect_dataset(effect, SIZES[effect], key=key)
            t0 = time.perf_counter()
            rep = discover(data)
            times.append(time.perf_counter() - t0)
            hits += rep["missing_effect"] == effect
            before.append(rep["gap_before"])
            after.append(rep["gap_after"])
            floor.append(rep["noise_floor"])
        lo, hi = wilson(hits, n_each)
        print(
            f"{effect:>32} {hits:>5}/{n_each:<6} [{lo:.2f}, {hi:.2f}] "
            f"{np.median(before):11.3f} {np.median(after):7.3f} {np.median(floor):7.3f} "
            f"{np.median(np.asarray(after) / np.asarray(floor)):11.2f}"
        )
    fp = 0
    for i in range(n_null):
        data = hidden_effect_dataset(None, 0.0, key=jax.random.key(5000 + i))
        t0 = time.perf_counter()
        rep = discover(data)
        times.append(time.perf_counter() - t0)
        fp += rep["missing_effect"] is not None
    lo, hi = wilson(fp, n_null)
    print(f"{'null (nothing hidden)':>32} false positives {fp}/{n_null} [{lo:.2f}, {hi:.2f}]")
    print(
        f"discover wall time per dataset (after the first): median "
        f"{np.median(times[1:]):.2f} s, max {np.max(times[1:]):.2f} s"
    )
    print("targets: recovery ≥ 95 %, false positives ≤ 5 %, gap after ≤ 1.3× floor")


if __name__ == "__main__":
    main("--quick" in sys.argv)
