"""A test session's offset against the simulator's switch-on biases (hrgjax.calibration.compare).

Calibrates a Fourier+T² compensator (and, with `--physical`, the physical grey box) on one
quick seed session, then runs the quick seed plan again in N other switch-ons. Each test
session's offset should be the change of switch-on bias, Δb = b_test − b_cal (known: the
simulator drew both), plus the error of the constant the compensator brought from its
calibration — the same for every test session. Prints, over the N sessions:

- the mean of offset − Δb (the calibration's part; the reported σ does not include it),
- their scatter about that mean against the mean reported σ (the test session's part: σ
  covers it when the ratio is ≤ 1),
- the static residual after the offset, against the same-session figure.

`python benchmarks/session_offset.py [--sessions 12] [--physical]` (≈ 1 min on 2 cores for
12 sessions without `--physical`).
"""

import argparse
import time

import jax
import numpy as np
from _common import report

import hrgjax as hg
from hrgjax import calibration as cal
from hrgjax.calibration.study import bench_session
from hrgjax.noise import draw_run_bias
from hrgjax.units import DEG_PER_H


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=12, help="test sessions (switch-ons)")
    parser.add_argument("--physical", action="store_true", help="also fit the physical model")
    args = parser.parse_args()
    gyro = hg.presets.tvg3_like()
    plans = list(cal.seed_plan(quick=True))
    bias = lambda k: float(draw_run_bias(k, gyro.noise)) / DEG_PER_H  # noqa: E731
    k_cal = jax.random.key(0)
    t0 = time.perf_counter()
    data = bench_session(gyro, plans, key=k_cal, bias_key=jax.random.fold_in(k_cal, 1))
    comps = {"Fourier+T": cal.FourierCompensator(temperature_degree=2).fit(cal.reduce(data))}
    if args.physical:
        comps["physical"] = cal.PhysicalCompensator().fit(data)
    same = cal.compare(comps, data)
    print(f"calibrated in {time.perf_counter() - t0:.1f} s; same session: offset {same.offset}")
    b_cal = bias(jax.random.fold_in(k_cal, 1))
    err, sigma, after = [], [], []
    for s in range(1, args.sessions + 1):
        key = jax.random.key(1000 + s)
        bias_key = jax.random.fold_in(key, 1)
        test = bench_session(gyro, plans, key=key, bias_key=bias_key)
        result = cal.compare(comps, test)
        delta = bias(bias_key) - b_cal
        err.append(result.offset.value_dph - delta)
        sigma.append(result.offset.sigma_dph)
        after.append(result.figure_of_merit(result.offset.source)["static_residual_dph"])
        print(f"  session {s:2d}: Δb {delta:+.4f} °/h, offset {result.offset}, "
              f"offset − Δb {err[-1]:+.4f}")  # fmt: skip
    err, sigma = np.array(err), np.array(sigma)
    spread = float(np.std(err, ddof=1))
    print(f"offset − Δb: mean {err.mean():+.4f} °/h (the calibration's constant), scatter "
          f"{spread:.4f} °/h against the mean σ {sigma.mean():.4f} °/h")  # fmt: skip
    ref = same.figure_of_merit(same.offset.source)["static_residual_dph"]
    print(f"static residual after the offset: {np.mean(after):.4f} °/h (same session {ref:.4f})")
    report("offset − Δb, mean over sessions (calibration's part)", err.mean(), "°/h")
    report("offset scatter / mean σ", spread / sigma.mean(), "", "≤ 1: σ covers", target="≤ 1")
    report("static residual after the offset", np.mean(after), "°/h", "vs same session",
           ratio=np.mean(after) / ref)  # fmt: skip


if __name__ == "__main__":
    main()
