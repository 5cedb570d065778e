"""Experiment design, Monte Carlo check (issue 22 scope 3): do the criterion's predictions
hold when the plans are simulated and calibrated?

For the seed's bench plan (36 h) and plans designed by `design()` within the given budgets
(default 12 h: a third of the seed's), each simulated `--seeds` times on the default gyro
(noise on: ARW, Gauss–Markov rate, switch-on bias; loops as configured, not ideal) with
independent keys, then calibrated — the physical grey box on every segment, the MLP on the
static and rotation windows (a ramp's apparent rate ∝ Ṫ is not something it models) — the
compensated static drift is compared with the noise-free truth on the seed's test grid
(11 temperatures × 37 wave angles, 5-min noise-free static runs, the session's switch-on
bias added: a compensator calibrates it away with the rest). Prints per plan: bench time,
predicted drift error (`drift_error` on the same grid), achieved RMS over seeds and grid,
their ratio (target: within 30 %), and the mean over seeds of the test grid's RMS.

The first seed of each plan compiles its simulators and the physical fit's groups (rare
segment lengths share padded ones: a designed 12-h plan of 44 lengths ≈ 9 min on 2 cores, the
seed plan ≈ 1 min); later seeds take seconds.
Usage: `.venv/bin/python benchmarks/design_mc.py [--seeds N] [--budgets 12 …] [--no-mlp]`.
"""

import argparse
import time

import jax
import numpy as np
from _common import machine, report

import hrgjax as hg
from hrgjax.calibration import MLPCompensator, PhysicalCompensator, reduce, run_plan, test_plan
from hrgjax.calibration import design as d
from hrgjax.noise import draw_run_bias
from hrgjax.units import DEG_PER_H


def truth_on_test_grid(gyro):
    """Noise-free static drift [°/h] on the seed's test grid: (angles, temperatures, drift)."""
    static, _ = test_plan()
    clean = run_plan(gyro.without_noise(), static, key=jax.random.key(0))
    w = reduce(clean)
    return w.wave_angle_deg, w.temperature_c, w.drift_dph


def monte_carlo(gyro, plan, seeds, truth, mlp=True):
    """Per seed: achieved RMS of (compensated drift − truth) on the grid, per compensator."""
    angles, temps, drift = truth
    ramps = np.flatnonzero(np.array(plan.kind) == "ramp")
    out = {"physical": [], "MLP": []} if mlp else {"physical": []}
    for s in range(seeds):
        key = jax.random.fold_in(jax.random.key(2026), s)
        t0 = time.perf_counter()
        cal = d.simulate_plan(gyro, plan, key=key)
        # simulate_plan's switch-on: the second half of its key split
        bias = float(draw_run_bias(jax.random.split(key)[1], gyro.noise)) / DEG_PER_H
        target = drift + bias
        comps = {"physical": PhysicalCompensator().fit(cal)}
        if mlp:
            w = reduce(cal)
            comps["MLP"] = MLPCompensator().fit(
                w.select(~np.isin(w.run, ramps)), key=jax.random.fold_in(key, 1)
            )
        for name, comp in comps.items():
            err = comp.drift_dph(angles, temps) - target
            out[name].append(float(np.sqrt(np.mean(err**2))))
        took = time.perf_counter() - t0
        print(f"  seed {s}: " + ", ".join(f"{k} {v[-1]:.4f}" for k, v in out.items())
              + f" °/h  ({took:.0f} s)", flush=True)  # fmt: skip
    return {k: np.asarray(v) for k, v in out.items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--budgets", type=float, nargs="*", default=[12.0])
    ap.add_argument("--no-mlp", action="store_true")
    a = ap.parse_args()
    gyro = hg.presets.tvg3_like()
    print(f"machine: {machine()}")
    truth = truth_on_test_grid(gyro)
    grid_t = tuple(float(t) for t in np.unique(truth[1]))
    grid_a = d.OPERATING_ANGLES  # the test grid's 5° steps
    plans = [("seed", d.seed_bench_plan())]
    for budget in a.budgets:
        t0 = time.perf_counter()
        result = d.design(budget)
        print(f"designed {budget:g} h in {time.perf_counter() - t0:.0f} s: {result.levels} "
              f"levels, {result.plan.size} segments", flush=True)  # fmt: skip
        plans.append((f"designed {budget:g} h", result.plan))
    rows = []
    for name, plan in plans:
        pred = float(d.drift_error(plan, temperatures_c=grid_t, angles_deg=grid_a))
        print(f"{name}: {float(d.bench_time_h(plan)):.2f} h, predicted {pred:.4f} °/h", flush=True)
        t0 = time.perf_counter()
        mc = monte_carlo(gyro, plan, a.seeds, truth, mlp=not a.no_mlp)
        rows.append((name, float(d.bench_time_h(plan)), pred, mc, time.perf_counter() - t0))
    print()
    print(f"{a.seeds} Monte Carlo seeds per plan; drift error vs the noise-free truth on the "
          "seed's test grid [°/h]")  # fmt: skip
    print(
        "plan               bench [h]  predicted  compensator  achieved (RMS)  "
        "achieved/predicted  seed spread  / seed plan's   wall [s]"
    )
    ref = {k: np.sqrt(np.mean(v**2)) for k, v in rows[0][3].items()}
    for name, hours, pred, mc, took in rows:
        for comp, v in mc.items():
            achieved = float(np.sqrt(np.mean(v**2)))
            print(f"{name:18s} {hours:9.2f}  {pred:9.4f}  {comp:11s}  {achieved:14.4f}  "
                  f"{achieved / pred:18.2f}  {np.std(v):11.4f}  {achieved / ref[comp]:13.2f}"
                  f"  {took:9.0f}")  # fmt: skip
            report(f"{name}: achieved drift error, {comp}", achieved, "°/h",
                   "achieved / predicted", achieved / pred, "within 30 %")  # fmt: skip


if __name__ == "__main__":
    main()
