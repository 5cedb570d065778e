"""Experiment design (issue 22): plans designed by `hrgjax.calibration.design.design` within
bench-time budgets of 4 h, 12 h (a third of the seed's) and 36 h (the seed's), beside the
seed's plans, all priced by the default `BenchModel` and judged by the predicted
compensated static-drift error (ARW and readout angle noise through the physical fit's
windows, Gauss–Markov rate, ideal-loop grey box: the criterion `design` minimises). Prints,
side by side in one run: bench time, predicted drift error, its ratio to the seed plan's,
and the wall time of each design (target ≤ 5 min for 4 h on 2 cores).

`benchmarks/design_mc.py` checks the predictions by Monte Carlo calibrations.
Usage: `.venv/bin/python benchmarks/design.py [BUDGET_H …]`.
"""

import sys
import time

import jax
from _common import machine

from hrgjax.calibration import design as d


def main(budgets=(4.0, 12.0, 36.0)):
    jax.config.update("jax_enable_x64", True)
    seed, quick = d.seed_bench_plan(), d.seed_bench_plan(quick=True)
    ref = float(d.criterion(seed))
    rows = [
        ("seed", float(d.bench_time_h(seed)), ref, None),
        ("seed quick", float(d.bench_time_h(quick)), float(d.criterion(quick)), None),
    ]
    for budget in budgets:
        t0 = time.perf_counter()
        result = d.design(budget)
        rows.append((f"designed {budget:g} h", result.bench_time_h, result.value,
                     time.perf_counter() - t0))  # fmt: skip
    print(f"machine: {machine()}")
    print("plan                bench [h]   drift [°/h]   / seed's   design time [s]")
    for name, hours, value, took in rows:
        t = "" if took is None else f"{took:10.1f}"
        print(f"{name:18s} {hours:9.2f}   {value:11.3g}   {value / ref:8.2f}   {t}")


if __name__ == "__main__":
    main(tuple(float(x) for x in sys.argv[1:]) or (4.0, 12.0, 36.0))
