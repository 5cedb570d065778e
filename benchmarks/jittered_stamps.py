"""Jittered time stamps and the physical fit: compiled groups, fit time, fitted values.

A bench session of 36 runs of 60 s at 0.5 s (3 temperatures × 6 angles, static and 5 °/s,
`tvg3_like`, one switch-on) is fitted with its own stamps, then with every stamp moved by
Gaussian jitter of 1 µs, 0.1 ms and 1 ms rms (the wave angles left as simulated: the jitter
is an error of the logger's clock, as in logged data). Printed per case: `stacked()`'s
stacks, the fit's compiled groups, the fit's wall time, and each parameter's shift from the
clean-stamp fit in units of the clean fit's σ and of its own, and its σ against the clean
fit's.

Runs whose intervals differ only by their jitter share one stack and one compiled group
(`MeasuredData.stacked`); before, each jittered run was its own (34–36 groups, a fit that
had not finished after 15 min).

Usage: `.venv/bin/python benchmarks/jittered_stamps.py`.
"""

import sys
import time

import jax
import numpy as np
from _common import machine, report

import hrgjax as hg
from hrgjax import calibration as cal
from hrgjax.calibration import physical
from hrgjax.data import MeasuredData, concat


def session() -> MeasuredData:
    gyro = hg.presets.tvg3_like()
    temps, angles = (-40.0, 20.0, 60.0), tuple(range(-90, 90, 30))
    static = cal.static_plan(temps, angles, duration_s=60.0, dt_out=0.5)
    rotation = cal.rotation_plan(temps, angles, duration_s=60.0, dt_out=0.5)
    key = jax.random.key(1000)
    bias = jax.random.fold_in(key, 7)
    a = cal.run_plan(gyro, static, key=key, bias_key=bias)
    b = cal.run_plan(gyro, rotation, key=jax.random.fold_in(key, 1), bias_key=bias,
                     first_run=static.size)  # fmt: skip
    return concat([a, b])


def main() -> int:
    print(f"jittered_stamps.py on {machine()}")
    data = session()
    comp = cal.PhysicalCompensator()
    t0 = time.perf_counter()
    clean = comp.fit(data)
    print(f"clean stamps: first fit (compile + fit) {time.perf_counter() - t0:.1f} s")
    sigma = np.sqrt(np.diag(np.asarray(clean.covariance)))
    rng = np.random.default_rng(0)
    for jitter in (1e-6, 1e-4, 1e-3):
        cols = {k: np.array(v) for k, v in data.columns.items()}
        cols["time_s"] = cols["time_s"] + rng.normal(0.0, jitter, cols["time_s"].size)
        jittered = MeasuredData(cols)
        groups = len(physical.fit_groups(jittered, comp.window_s, comp.k_e))
        t0 = time.perf_counter()
        fit = comp.fit(jittered)
        took = time.perf_counter() - t0
        own = np.sqrt(np.diag(np.asarray(fit.covariance)))
        shift = np.asarray(fit.values) - np.asarray(clean.values)
        z, z_own, ratio = shift / sigma, shift / own, own / sigma
        print(f"jitter {jitter * 1e3:g} ms rms: {len(jittered.stacked())} stacks, {groups} "
              f"compiled groups, fit {took:.2f} s; max |shift| {np.max(np.abs(z)):.3f} σ "
              f"({physical.NAMES[int(np.argmax(np.abs(z)))]}), {np.max(np.abs(z_own)):.2f} of "
              "the jittered fit's own σ, σ / clean σ "
              f"{ratio.min():.2f}–{ratio.max():.2f}, rotation-window RMS "
              f"{fit.fit_stats['moving_rms_dph']:.4f} °/h "
              f"(clean {clean.fit_stats['moving_rms_dph']:.4f})")  # fmt: skip
        report(f"physical fit, stamps jittered {jitter * 1e3:g} ms rms", groups, "groups",
               "max |shift| / clean σ", ratio=np.max(np.abs(z)))  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
