"""The physical fit's groups of run lengths: compile time against time per evaluation.

A designed plan's runs have many lengths; the fit pads rare ones to powers of two of
samples and then runs neighbouring lengths as one group where compiling another costs more
than the extra steps (`_physical_groups.merge_buckets`). This script times the fit's one
program (the residuals and their Jacobian, `_physical_fit.residuals_jacobian`) on one plan's
simulated data in three layouts — every padded length apart, the default merge, and one group
per sample interval — and prints each layout's compile (with its first call) and best-of-5 evaluation,
the figures `physical.FIT_COMPILE_S` and `FIT_STEP_S` were fitted to. Each layout is a
different program; all run in this one process, so compiled pieces they share (none of the
groups' simulators) would favour the later ones.

Usage: `.venv/bin/python benchmarks/fit_group_layouts.py [--plan-file plan.json]` (default:
`design(12.0)`, ≈ 2 min more).
"""

import argparse
import time

import jax
from _common import machine, report

import hrgjax as hg
from hrgjax.calibration import _physical_fit, _physical_groups, physical
from hrgjax.calibration import design as d


def apart(buckets, short):
    return [(key[0], stacks) for key, stacks in buckets.items()]


def one_per_interval(buckets, short):
    by_dt = {}
    for (length, dt), stacks in buckets.items():
        by_dt.setdefault(dt, []).append((length, stacks))
    return [(max(n for n, _ in v), [st for _, s in v for st in s]) for v in by_dt.values()]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plan-file")
    a = ap.parse_args()
    plan = d.load_plan(a.plan_file)[0] if a.plan_file else d.design(12.0).plan
    data = d.simulate_plan(hg.presets.tvg3_like(), plan, key=jax.random.key(0))
    values, k_e = d.nominal_values(), physical.K_E_NOMINAL
    program = jax.jit(_physical_fit.residuals_jacobian)
    print(f"machine: {machine()}")
    print(f"plan: {plan.size} segments")
    rows = {}
    default = _physical_groups.merge_buckets
    for name, layout in (("apart", apart), ("default", default),
                         ("one per interval", one_per_interval)):  # fmt: skip
        _physical_groups.merge_buckets = layout
        try:
            groups = _physical_groups.fit_groups(data, 10.0, k_e)
        finally:
            _physical_groups.merge_buckets = default
        t0 = time.perf_counter()
        jax.block_until_ready(program(groups, values, k_e))
        compile_s = time.perf_counter() - t0
        best = min(_timed(program, groups, values, k_e) for _ in range(5))
        shapes = ", ".join(f"{g.t.shape[0]}×{g.t.shape[1]}" for g in groups)
        print(f"{name:17s} {len(groups)} groups (runs × samples: {shapes}): compile + first "
              f"{compile_s:.1f} s, evaluation {best * 1e3:.1f} ms", flush=True)  # fmt: skip
        rows[name] = (compile_s, best)
    for name in ("default", "one per interval"):
        report(f"fit program, {name} layout: compile + first call", rows[name][0], "s",
               "/ every length apart", rows[name][0] / rows["apart"][0])  # fmt: skip
        report(f"fit program, {name} layout: one evaluation", rows[name][1] * 1e3, "ms",
               "/ every length apart", rows[name][1] / rows["apart"][1])  # fmt: skip


def _timed(program, groups, values, k_e):
    t0 = time.perf_counter()
    jax.block_until_ready(program(groups, values, k_e))
    return time.perf_counter() - t0


if __name__ == "__main__":
    main()
