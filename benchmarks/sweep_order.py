"""`hg.sweep` ordered by cost (issue 20): a temperature × rate sweep with the rate innermost,
rates log-spaced 0.1–400 °/s, averaged model, 60-s runs.

Side by side in one process, each compiled first and then timed (best of `--repeat`):
- **unordered**: `cost=None`, one batch — every member steps until the 400 °/s ones are done;
- **auto**: the default, `cost="auto"` (estimated steps per member, sorted, chunked);
- **rate buckets**: what a careful user writes by hand — the members sorted by rate and run
  in chunks of the size `auto` chose (the issue's reference);
- **one by one**: the members run alone (no lockstep at all, no batching either).
Ratios are to the rate buckets. Then `calibration.run_plan` on the same points, in the plan's
order and sorted by |rate| (its default). Also printed: the chunk size chosen and that every result is
the unordered one to round-off.

Usage: `.venv/bin/python benchmarks/sweep_order.py [--quick] [--repeat N]`.
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import machine  # noqa: E402

import hrgjax as hg  # noqa: E402
from hrgjax import _cost  # noqa: E402
from hrgjax.sweep import member_costs  # noqa: E402

DURATION_S = 60.0


def main(quick: bool, repeat: int):
    n_t, n_w = (2, 32) if quick else (4, 64)
    temps = jnp.linspace(-40.0, 60.0, n_t)
    rates = jnp.geomspace(0.1, 400.0, n_w)
    gyro = hg.presets.tvg3_like(noise=False)

    def f(temperature_c, rate_dps):
        prof = hg.Profile.constant_rate(rate_dps, DURATION_S, temperature_c)
        return hg.simulate(gyro, prof, dt_out=DURATION_S).wave_angle[-1]

    print(f"machine: {machine()}")
    print(f"{n_t} temperatures × {n_w} rates (innermost), {DURATION_S:.0f}-s averaged runs")

    def timed(run):
        run()  # compile
        best = np.inf
        for _ in range(repeat):
            t0 = time.perf_counter()
            out = jax.block_until_ready(run())
            out = out if isinstance(out, dict) else np.asarray(out)
            best = min(best, time.perf_counter() - t0)
        return best, out

    t_un, out_un = timed(lambda: hg.sweep(f, cost=None, temperature_c=temps, rate_dps=rates))
    t_auto, out_auto = timed(lambda: hg.sweep(f, temperature_c=temps, rate_dps=rates))
    # the chunk size auto chose, from the same estimates
    tt, ww = (np.asarray(m).ravel() for m in np.meshgrid(temps, rates, indexing="ij"))
    costs = member_costs(f, "auto", {"temperature_c": jnp.asarray(tt), "rate_dps": jnp.asarray(ww)})
    devices = jax.local_devices()
    _, chunk = _cost.plan(costs, len(devices), devices[0].platform)
    # by hand: sorted by rate, chunks of the same size, each a jit(vmap) of the chunk
    batched = jax.jit(jax.vmap(f))
    order = np.argsort(ww, kind="stable")
    total = tt.size
    pad = (-total) % chunk
    idx = np.concatenate([order, np.repeat(order[-1:], pad)])

    def buckets():
        parts = [
            batched(jnp.asarray(tt[idx[i : i + chunk]]), jnp.asarray(ww[idx[i : i + chunk]]))
            for i in range(0, idx.size, chunk)
        ]
        out = np.empty(total)
        out[order] = np.concatenate([np.asarray(p) for p in parts])[:total]
        return out.reshape(n_t, n_w)

    t_b, out_b = timed(buckets)
    single = jax.jit(f)

    def one_by_one():
        return np.array([float(single(a, b)) for a, b in zip(tt, ww, strict=True)]).reshape(
            n_t, n_w
        )

    t_1, out_1 = timed(one_by_one)
    steps = costs.reshape(n_t, n_w)
    print(f"estimated steps per member: {steps.min():.0f} … {steps.max():.0f}; "
          f"auto chose chunks of {chunk} ({-(-total // chunk)} chunks)")  # fmt: skip
    print("| run | time [s] | × rate buckets |\n|---|---|---|")
    for name, t in (("unordered (cost=None, one batch)", t_un), ('auto (cost="auto")', t_auto),
                    ("rate buckets by hand", t_b), ("one by one", t_1)):  # fmt: skip
        print(f"| {name} | {t:.2f} | {t / t_b:.2f}× |")
    for name, out in (("auto", out_auto), ("buckets", out_b), ("one by one", out_1)):
        d = np.max(np.abs(out - out_un) / np.maximum(np.abs(out_un), 1e-300))
        print(f"{name}: max relative difference to unordered {d:.1e}")

    # calibration.run_plan on the same points (chunks of 32): sorted by |rate| or not
    from hrgjax.calibration import Plan, run_plan

    plan = Plan(jnp.asarray(tt), jnp.zeros(total), jnp.asarray(ww), duration_s=DURATION_S,
                dt_out=DURATION_S)  # fmt: skip
    t_plain, d_plain = timed(lambda: run_plan(gyro, plan, order_by_cost=False).columns)
    t_sorted, d_sorted = timed(lambda: run_plan(gyro, plan).columns)
    same = max(
        float(np.max(np.abs(d_sorted[k] - d_plain[k]) / np.maximum(np.abs(d_plain[k]), 1.0)))
        for k in d_plain
    )
    print(f"\nrun_plan, the same {total} points: in the plan's order {t_plain:.2f} s, sorted by "
          f"|rate| {t_sorted:.2f} s ({t_plain / t_sorted:.2f}× faster); largest difference {same:.1e} "
          f"(relative, or absolute below 1)")  # fmt: skip


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="2 × 32 members instead of 4 × 64")
    p.add_argument("--repeat", type=int, default=2, help="timed repetitions (best is kept)")
    a = p.parse_args()
    main(a.quick, a.repeat)
