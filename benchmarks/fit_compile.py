"""Time to the first physical fit: the simulator's tangent program compiled once vs twice.

`PhysicalCompensator.fit` runs optimistix's Levenberg–Marquardt one compiled step at a time.
*Before* (the implementation up to commit 311400f, kept here as `_fit_before`): the solver's
step program evaluated the residuals through the simulator and formed their Jacobian itself
(`jax.linearize`), while the fit's own residual-and-Jacobian program (`jax.jacfwd`, for the
weights and the covariance) held the same simulator again — two large programs to compile.
*After* (`least_squares_with_jacobian`): the step is fed the residuals and Jacobian of the
fit's one program at the point it evaluates; its own program holds no simulator.

Each figure is measured in a fresh process with no compile cache (as a user's first fit in a
session), side by side for both methods on the same data:

- `small`: 3 temperatures × 6 angles, static and 5 °/s rotation runs of 60 s (the test
  suite's coverage problem);
- `seed-quick`: the seed bench plan's quick version (`seed_bench_plan(quick=True)`), one
  session by `simulate_plan`;
- `designed`: a 4-h plan from `design(4.0)` (statics, rotations and ramps of many lengths:
  several padded groups), one session by `simulate_plan`. Designing it takes ≈ 1–2 min.

Usage: `.venv/bin/python benchmarks/fit_compile.py [--quick]` (`--quick`: `small` only).
"""

import json
import os
import subprocess
import sys
import tempfile
import time

from _common import machine, report

CASES = ("small",) if "--quick" in sys.argv else ("small", "seed-quick", "designed")


def _data(case, plan_path):
    import jax
    import jax.numpy as jnp

    import hrgjax as hg
    from hrgjax.calibration import design as d
    from hrgjax.calibration import physical, run_plan, static_plan

    key = jax.random.key(7)
    if case == "small":
        import equinox as eqx

        from hrgjax.calibration.reduce import K_E_NOMINAL
        from hrgjax.units import DEG, DEG_PER_H, DEG_PER_SQRT_H

        truth = dict.fromkeys(physical.NAMES, 0.0)
        truth.update(k_e0=K_E_NOMINAL, bias0=0.2 * DEG_PER_H, delta_inv_tau0=3e-6,
                     theta_tau0=0.45, gain_mismatch0=3e-3)  # fmt: skip
        noise = hg.Noise(angle_white=DEG / 3600, angle_random_walk=0.002 * DEG_PER_SQRT_H,
                         bias_instability=0.0, correlation_time=600.0, run_bias=0.0)  # fmt: skip
        model = physical.model_gyro(jnp.asarray([truth[n] for n in physical.NAMES]))
        gyro = eqx.tree_at(lambda g: g.noise, model, noise, is_leaf=lambda x: x is None)
        temps, angles = (-40.0, 20.0, 60.0), tuple(range(-90, 90, 30))
        static = static_plan(temps, angles, duration_s=60.0, dt_out=0.5)
        rotation = hg.calibration.rotation_plan(temps, angles, duration_s=60.0, dt_out=0.5)
        d1 = run_plan(gyro, static, key=key, bias_key=key)
        d2 = run_plan(gyro, rotation, key=jax.random.fold_in(key, 1), first_run=static.size)
        return hg.data.concat([d1, d2])
    plan = d.seed_bench_plan(quick=True) if case == "seed-quick" else d.load_plan(plan_path)[0]
    return d.simulate_plan(hg.presets.tvg3_like(), plan, key=key)


def _fit_before(groups, x0, k_e, max_steps):
    """The fit up to commit 311400f: optimistix stepping through the simulator itself."""
    import jax
    import numpy as np
    import optimistix as optx

    from hrgjax._compiled import device
    from hrgjax._least_squares import least_squares
    from hrgjax.calibration import _physical_fit as ph
    from hrgjax.calibration._physical_groups import window_weights

    weights = window_weights(groups)
    r0, _ = ph.residuals_jacobian(groups, x0, k_e)
    sigma = {k: device(v) for k, v in ph.robust_scatter(r0, weights).items()}
    x, steps, result = least_squares(
        _weighted_residual,
        optx.LevenbergMarquardt(rtol=0.0, atol=1e-4),
        device(np.zeros(len(ph.NAMES))),
        (groups, x0, sigma, k_e),
        max_steps=max_steps,
        desc="physical fit (before)",
        f_struct=jax.ShapeDtypeStruct((sum(r.size for r in r0.values()),), r0[True].dtype),
    )
    assert int(result._value) == 0, result
    values = np.asarray(x0) + np.asarray(x) * ph.SCALE
    r1, jac1 = ph.residuals_jacobian(groups, device(values), k_e)
    r1 = {k: np.asarray(r) for k, r in r1.items()}
    sigma1 = {k: np.sqrt(np.mean(r[weights[k] > 0] ** 2)) for k, r in r1.items()}
    jac = np.concatenate(
        [np.asarray(jac1[True]) / sigma1[True], np.asarray(jac1[False]) / sigma1[False]]
    )
    return values, steps, r1, sigma1, jac / np.asarray(ph.SCALE)[None, :]


def _weighted_residual(x, args):
    import jax.numpy as jnp

    from hrgjax.calibration import _physical_fit as ph

    groups, x0, sigma, k_e = args
    res = ph.window_residuals(groups, x0 + x * ph.SCALE, k_e)
    return jnp.concatenate([res[True] / sigma[True], res[False] / sigma[False]])


def worker(case, method, plan_path):
    """One fresh process: simulate the data, then time the first and second fit."""
    import numpy as np

    from hrgjax.calibration import PhysicalCompensator, physical

    data = _data(case, plan_path)
    if method == "before":
        physical.fit_values = _fit_before
    times, fits = [], []
    for _ in range(2):
        t0 = time.perf_counter()
        fits.append(PhysicalCompensator().fit(data))
        times.append(time.perf_counter() - t0)
    values = np.asarray(fits[-1].values)
    print(json.dumps({"first": times[0], "second": times[1], "values": values.tolist(),
                      "steps": fits[-1].fit_stats["lm_steps"]}))  # fmt: skip


def run(case, method, plan_path):
    env = dict(os.environ, HRGJAX_NO_CACHE="1", JAX_ENABLE_X64="1")
    out = subprocess.run(
        [sys.executable, __file__, "--worker", case, method, plan_path or ""],
        capture_output=True, text=True, env=env, check=False,
    )  # fmt: skip
    if out.returncode:
        sys.exit(f"{case}/{method} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    import numpy as np

    plan_path = None
    if "designed" in CASES:
        import jax

        jax.config.update("jax_enable_x64", True)
        from hrgjax.calibration import design as d

        plan_path = os.path.join(tempfile.mkdtemp(), "plan.json")
        t0 = time.perf_counter()
        res = d.design(4.0)
        d.save_plan(res.plan, plan_path, res.bench)
        print(f"designed a 4-h plan in {time.perf_counter() - t0:.0f} s "
              f"({len(res.plan.kind)} segments)")  # fmt: skip
    print(f"machine: {machine()}")
    print("first physical fit in a fresh process, no compile cache (compile + run) [s]")
    print(f"{'case':>11} {'before':>8} {'after':>8} {'ratio':>6} {'2nd before':>11} "
          f"{'2nd after':>10} {'LM steps':>9} {'max rel Δ':>10}")  # fmt: skip
    for case in CASES:
        b, a = run(case, "before", plan_path), run(case, "after", plan_path)
        # the two fits' solutions: largest relative difference over the parameters
        diff = np.abs(np.subtract(a["values"], b["values"]))
        print(f"{case:>11} {b['first']:8.1f} {a['first']:8.1f} {a['first'] / b['first']:5.2f}× "
              f"{b['second']:11.2f} {a['second']:10.2f} {b['steps']:>4}/{a['steps']:<4} "
              f"{float(np.max(diff / np.maximum(np.abs(a['values']), 1e-300))):10.1e}")  # fmt: skip
        report(f"first physical fit, {case}: after / before", a["first"], "s",
               "after / before", a["first"] / b["first"])  # fmt: skip


if __name__ == "__main__":
    if "--worker" in sys.argv:
        i = sys.argv.index("--worker")
        import jax

        jax.config.update("jax_enable_x64", True)
        worker(sys.argv[i + 1], sys.argv[i + 2], sys.argv[i + 3] or None)
    else:
        main()
