"""Time to the first calibration of a designed plan: simulate it, fit the physical model —
both compiling in a fresh process — with rare run lengths padded to a ladder of
⌈2^(k/4)⌉ samples (`before`, kept here as `_ladder_before`), to powers of two (`pow2`,
`calibration._grouping.ladder`), and to powers of two with neighbouring lengths run as one where a compile costs more than the
extra steps (`merged`, the default: `_plan_simulation.simulation_groups` for `simulate_plan`,
`_physical_groups.merge_buckets` for the fit). Fewer, longer groups: fewer programs to
compile, a little more to run.

The plan: `design(12.0)` (5 levels, 44 segments of many lengths; ≈ 2 min to design), or
`--plan-file`. Each variant runs in its own process with the compile cache off, on the same
plan and key; the data and the fitted values must agree (the padding is masked out).

Usage: `.venv/bin/python benchmarks/plan_first_calibration.py [--plan-file plan.json]`.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

from _common import machine, report


def _ladder_before(n: int) -> int:
    """Smallest ⌈2^(k/4)⌉ ≥ n (the ladder up to commit 90d30ef's successor)."""
    k = max(math.floor(4 * math.log2(n)) - 1, 0)
    while math.ceil(2 ** (k / 4)) < n:
        k += 1
    return math.ceil(2 ** (k / 4))


def child(plan_path, variant, out_path):
    import time

    import jax
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    import hrgjax as hg
    from hrgjax.calibration import PhysicalCompensator, _physical_groups, _plan_simulation
    from hrgjax.calibration import design as d

    if variant == "before":
        # each imports it by name
        _physical_groups.ladder = _plan_simulation.ladder = _ladder_before
    if variant in ("before", "pow2"):
        _plan_simulation.MERGED_STEPS_MAX = 0  # no two lengths merged
        _physical_groups.merge_buckets = lambda buckets, short: [
            (k[0], v) for k, v in buckets.items()
        ]
    plan, _ = d.load_plan(plan_path)
    gyro = hg.presets.tvg3_like()
    t0 = time.perf_counter()
    data = d.simulate_plan(gyro, plan, key=jax.random.key(0))
    t1 = time.perf_counter()
    fit = PhysicalCompensator().fit(data)
    t2 = time.perf_counter()
    data2 = d.simulate_plan(gyro, plan, key=jax.random.key(1))
    t3 = time.perf_counter()
    PhysicalCompensator().fit(data2)
    t4 = time.perf_counter()
    groups = len(_physical_groups.fit_groups(data, 10.0, _physical_groups.K_E_NOMINAL))
    with open(out_path, "w") as f:
        json.dump({"simulate": t1 - t0, "fit": t2 - t1, "simulate2": t3 - t2, "fit2": t4 - t3,
                   "groups": groups, "values": np.asarray(fit.values).tolist(),
                   "sigma": np.sqrt(np.diag(np.asarray(fit.covariance))).tolist(),
                   "wave": np.asarray(data["wave_angle_deg"]).tolist()}, f)  # fmt: skip


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plan-file")
    a = ap.parse_args()
    tmp = tempfile.mkdtemp()
    plan_path = a.plan_file
    if plan_path is None:
        import jax

        jax.config.update("jax_enable_x64", True)
        from hrgjax.calibration import design as d

        result = d.design(12.0)
        plan_path = os.path.join(tmp, "plan.json")
        d.save_plan(result.plan, plan_path, result.bench)
    env = {**os.environ, "HRGJAX_NO_CACHE": "1"}
    res = {}
    for variant in ("before", "pow2", "merged"):
        out = os.path.join(tmp, f"{variant}.json")
        code = (f"import sys; sys.path.insert(0, {os.path.dirname(__file__)!r}); "
                f"import plan_first_calibration as m; m.child({plan_path!r}, {variant!r}, {out!r})")  # fmt: skip
        subprocess.run([sys.executable, "-c", code], env=env, check=True,
                       stderr=subprocess.DEVNULL)  # fmt: skip
        with open(out) as f:
            res[variant] = json.load(f)
    import numpy as np

    b = res["before"]
    print(f"machine: {machine()}")
    print(f"plan: {plan_path}")
    for name in ("pow2", "merged"):
        f = res[name]
        diff = float(np.max(np.abs(np.subtract(b["wave"], f["wave"]))))
        vb, vf = np.asarray(b["values"]), np.asarray(f["values"])
        rel = float(np.max(np.abs(vb - vf) / np.maximum(np.abs(vb), 1e-300)))
        sig = float(np.max(np.abs(vb - vf) / np.asarray(b["sigma"])))
        print(f"{name} vs before: simulated wave angle max diff {diff:.1e}°; fitted values "
              f"max rel. diff {rel:.1e}, max {sig:.1e} of their standard errors")  # fmt: skip
    print(f"{'':8s} {'groups':>6} {'simulate [s]':>12} {'fit [s]':>8} {'first [s]':>9} "
          f"{'2nd seed: simulate, fit [s]':>28}")  # fmt: skip
    for name, r in res.items():
        print(f"{name:8s} {r['groups']:6d} {r['simulate']:12.1f} {r['fit']:8.1f} "
              f"{r['simulate'] + r['fit']:9.1f} {r['simulate2']:14.2f}, {r['fit2']:.2f}")  # fmt: skip
    first = lambda r: r["simulate"] + r["fit"]
    p, m = res["pow2"], res["merged"]
    report("first simulate_plan + physical fit of a designed 12-h plan", first(m), "s",
           "merged / before", first(m) / first(b))  # fmt: skip
    report("first simulate_plan of a designed 12-h plan", m["simulate"], "s",
           "merged / powers of two alone", m["simulate"] / p["simulate"])  # fmt: skip
    report("a later simulate_plan of the plan", m["simulate2"], "s",
           "merged / powers of two alone", m["simulate2"] / p["simulate2"])  # fmt: skip


if __name__ == "__main__":
    main()
