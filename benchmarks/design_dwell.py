"""Experiment design (issue 22): what limits a third of the seed's bench time — the dwell on
each point, or the points?

The seed's grid (11 temperatures × 19 wave angles, static and 5 °/s rotation runs) simulated
with its 3-min dwells and again with 1-min dwells, `--seeds` times each on the default gyro
(all its noise, independent keys as in `design_mc.py`), calibrated with the physical grey
box and the MLP, and compared on the seed's test grid with the noise-free static drift. If a
compensator's error grows as √3 when the dwells shrink threefold, its error on this grid is
the noise averaged over the dwells, and a plan of a third of the time cannot match it on the
same points; it could only by needing fewer points — which an empirical model cannot afford
(`design_mc.py --model empirical`). Also printed: the bench time of the grid's transitions
alone (1-s dwells), against the 12 h that are a third of the seed plan's.

Usage: `.venv/bin/python benchmarks/design_dwell.py [--seeds 6]` (≈ 4 min on 2 cores).
"""

import argparse
import time

import numpy as np
from _common import machine, report
from design_mc import monte_carlo, rms_ratio, truth_on_test_grid

import hrgjax as hg
from hrgjax.calibration import design as d


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=6)
    a = ap.parse_args()
    gyro = hg.presets.tvg3_like()
    print(f"machine: {machine()}")
    seed = d.seed_bench_plan()
    third = float(d.bench_time_h(seed)) / 3
    bare = float(d.bench_time_h(d.seed_bench_plan(duration_s=1.0)))
    print(f"seed grid: {float(d.bench_time_h(seed)):.2f} h with 3-min dwells; "
          f"{bare:.2f} h of it transitions (1-s dwells); a third of the seed's: {third:.2f} h")  # fmt: skip
    report("bench time of the seed grid's transitions alone", bare, "h",
           "/ a third of the seed plan's time", bare / third)  # fmt: skip
    truth = truth_on_test_grid(gyro)
    runs = {}
    for dwell in (180.0, 60.0):
        plan = d.seed_bench_plan(duration_s=dwell)
        t0 = time.perf_counter()
        runs[dwell] = monte_carlo(gyro, plan, a.seeds, truth, mlp=True, ins=False)
        print(f"{dwell:.0f}-s dwells: {float(d.bench_time_h(plan)):.2f} h, "
              f"{time.perf_counter() - t0:.0f} s", flush=True)  # fmt: skip
    print(f"\n{a.seeds} seeds each; static drift error on the seed's test grid [°/h], RMS")
    print("compensator   3-min dwells   1-min dwells   ratio ± s.e.   √3 (noise-limited)")
    for comp in ("physical", "MLP"):
        long, short = runs[180.0][comp]["drift"], runs[60.0][comp]["drift"]
        ratio, se = rms_ratio(short, long)
        rms = lambda x: float(np.sqrt(np.mean(x**2)))  # noqa: E731
        print(f"{comp:12s}  {rms(long):12.4g}  {rms(short):13.4g}  {ratio:6.2f} ± {se:4.2f}  "
              f"{np.sqrt(3):10.2f}")  # fmt: skip
        report(f"static drift error with 1-min vs 3-min dwells on the seed grid, {comp}",
               rms(short), "°/h", f"/ 3-min dwells' (s.e. ± {se:.2f})", ratio, "√3 ≈ 1.73 "
               "if the noise on the dwells limits it")  # fmt: skip


if __name__ == "__main__":
    main()
