"""Experiment design (issue 22): plans designed by `hrgjax.calibration.design.design` within
bench-time budgets of 4 h, 12 h (a third of the seed's) and 36 h (the seed's), beside the
seed's plans, all priced by the default `BenchModel` and judged by the predictions of both
criteria: the compensated static-drift error (`drift`: ARW and readout angle noise through
the physical fit's windows, Gauss–Markov rate, ideal-loop grey box), the input-angle (tilt)
error after the 1-h warm-up flights (`warmup`), the two together (`drift+warmup`, `design`'s
default) and the position error after the flights (`ins`). The plans are designed for
`--criterion` (here default drift, as the figures of benchmarks/README.md). Prints, side by
side in one run: bench time, the predicted errors, their ratios to the seed plan's, and the
wall time of each design (target ≤ 5 min for 4 h on 2 cores).

`benchmarks/design_mc.py` checks the predictions by Monte Carlo calibrations.
Usage: `.venv/bin/python benchmarks/design.py [--criterion drift|warmup|drift+warmup|ins]
[--model physical|empirical] [BUDGET_H …]` (`--model empirical`: designed for the surrogate
of an empirical compensator, judged by the grey box's predictions all the same).
"""

import argparse
import time

import jax
from _common import machine

from hrgjax.calibration import design as d


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("budgets", type=float, nargs="*", default=[4.0, 12.0, 36.0])
    ap.add_argument("--criterion", choices=("drift", "warmup", "drift+warmup", "ins"),
                    default="drift")  # fmt: skip
    ap.add_argument("--model", choices=("physical", "empirical"), default="physical")
    a = ap.parse_args()
    jax.config.update("jax_enable_x64", True)

    kinds = ("drift", "warmup", "drift+warmup", "ins")

    def judged(plan):
        return tuple(float(d.criterion(plan, k)) for k in kinds)

    seed, quick = d.seed_bench_plan(), d.seed_bench_plan(quick=True)
    rows = [
        ("seed", float(d.bench_time_h(seed)), judged(seed), None),
        ("seed quick", float(d.bench_time_h(quick)), judged(quick), None),
    ]
    for budget in a.budgets:
        t0 = time.perf_counter()
        result = d.design(budget, criterion=a.criterion, model=a.model)
        took = time.perf_counter() - t0
        name = f"{a.criterion}{'' if a.model == 'physical' else '/emp'} {budget:g} h"
        rows.append((name, result.bench_time_h, judged(result.plan), took))
    ref = rows[0][2]
    print(f"machine: {machine()}")
    print(f"plans designed for the {a.criterion!r} criterion of the {a.model} model; "
          "the grey box's predictions of both criteria")  # fmt: skip
    units = {k: d.CRITERION_UNITS[k] for k in kinds}
    print(f"{'plan':22s} {'bench [h]':>9}" + "".join(f" {f'{k} [{units[k]}]':>18} {'/ seed':>6}"
          for k in kinds) + "   design time [s]")  # fmt: skip
    for name, hours, values, took in rows:
        t = "" if took is None else f"{took:10.1f}"
        cols = "".join(f" {v:18.4g} {v / r:6.2f}" for v, r in zip(values, ref, strict=True))
        print(f"{name:22s} {hours:9.2f}{cols}   {t}")


if __name__ == "__main__":
    main()
