"""The figures behind this stop's trust fixes, side by side, each against what the code did
before (the old figures are quoted, measured at 35fb7d0):

- **Design criteria at weak priors** (`calibration.design.PRECISION_FLOOR`): the `d`, `a`
  and `drift` criteria of the seed's quick plan and of its first 10, 20, 40 segments (which
  leave directions unseen) at `prior_scale` 1e2 … 1e8. Before: NaN at 1e8 on every partial
  plan; at the default prior the values are bit-identical to before.
- **Force-to-rebalance noise** (`simulate`'s readout noise on the rebalance output): the
  noise terms `allan.identify_noise` names in the rate a whole-angle gyro's angle gives and
  in an FTR gyro's rebalance output, for angle random walk, white readout noise and a
  Gauss–Markov rate. Before: the FTR output carried no readout noise (a Gauss–Markov σ of
  1.8e-13 rad/s where whole-angle read quantization 1.79e-4 rad).
- **The check on traced parameters** (`simulate` under `jit`/`vmap`/`sweep` names a NaN
  parameter or profile): a sweep's time with it and without it (as before), one process.

Usage: `.venv/bin/python benchmarks/trust_checks.py` (≈ 30 s on 2 cores).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from _common import machine

import hrgjax as hg

design = hg.calibration.design


def criteria_rows():
    plan = design.seed_bench_plan(quick=True)
    fields = (plan.temperature_c, plan.temperature_end_c, plan.wave_angle_deg, plan.rate_dps,
              plan.duration_s)  # fmt: skip
    print("design criteria (d, a, drift [°/h]) by segments kept and prior_scale:")
    for n in (10, 20, 40, plan.kind.shape[0] if hasattr(plan.kind, "shape") else len(plan.kind)):
        part = design.BenchPlan(plan.kind[:n], *(x[:n] for x in fields))
        for scale in (1e2, 1e4, 1e6, 1e8):
            d, a, drift = (float(design.criterion(part, k, prior_scale=scale))
                           for k in ("d", "a", "drift"))  # fmt: skip
            print(f"  {n:4d} segments, prior ×{scale:7.0e}: d {d:12.6f}  a {a:12.6g}  "
                  f"drift {drift:10.6g}")  # fmt: skip


def ftr_rows():
    base = hg.presets.tvg3_like(temperature_laws=False, noise=False)
    prof = hg.Profile.static(4000.0, wave_angle0_deg=30.0)
    print("noise terms named in the rate read out, whole-angle (wa) and force-to-rebalance "
          "(ftr), 4000 s at 2 Hz:")  # fmt: skip
    for label, noise in (("ARW 1e-5 rad/√s", hg.Noise(angle_random_walk=1e-5)),
                         ("white readout 1e-4 rad", hg.Noise(angle_white=1e-4)),
                         ("Gauss–Markov 2e-5 rad/s, 50 s",
                          hg.Noise(bias_instability=2e-5, correlation_time=50.0))):  # fmt: skip
        gyro = eqx.tree_at(lambda g: g.noise, base, noise, is_leaf=lambda x: x is None)
        for mode in ("wa", "ftr"):
            rec = hg.simulate(gyro.in_mode(mode), prof, key=jax.random.key(3), dt_out=0.5)
            if mode == "wa":
                rate = -np.diff(np.asarray(rec.wave_angle)) / np.asarray(rec.k_e)[1:] / 0.5
            else:
                rate = np.asarray(rec.rebalance_rate)[1:]
            rate = rate[20:] - np.mean(rate[20:])
            model = hg.allan.identify_noise(rate, 2.0, unit="rad/s", gauss_markov=1)
            terms = {k: v.get("value", {kk: vv["value"] for kk, vv in v.items()
                                        if isinstance(vv, dict)})
                     for k, v in model.terms.items()}  # fmt: skip
            print(f"  {label:30s} {mode:3s}: {terms}")


def check_cost_rows(repeat: int = 5):
    """The cost of `simulate`'s check on traced parameters (`_checks.traceable`, added in
    the eleventh session) in a sweep: the same 32-member temperature × rate sweep with the
    check and with it replaced by the identity (as before), each compiled first, best of
    `repeat`, interleaved."""
    import sys
    import time

    sim_module = sys.modules["hrgjax.simulate"]  # (the package's `simulate` is the function)

    gyro = hg.presets.tvg3_like(noise=False)

    def make():
        def f(temperature_c, rate_dps):  # a fresh function: its own compiled batch
            prof = hg.Profile.constant_rate(rate_dps, 60.0, temperature_c)
            return hg.simulate(gyro, prof, dt_out=1.0).wave_angle[-1]

        return f

    grids = {"temperature_c": jnp.linspace(-40.0, 60.0, 4), "rate_dps": jnp.geomspace(1, 100, 8)}
    checked, real = make(), sim_module.traceable
    plain = make()
    sim_module.traceable = lambda name, tree, limits=None: tree
    try:
        np.asarray(hg.sweep(plain, cost=None, **grids))
    finally:
        sim_module.traceable = real
    np.asarray(hg.sweep(checked, cost=None, **grids))
    best = {"with the check": np.inf, "without (before)": np.inf}
    for _ in range(repeat):
        for label, fn in (("with the check", checked), ("without (before)", plain)):
            t0 = time.perf_counter()
            np.asarray(hg.sweep(fn, cost=None, **grids))
            best[label] = min(best[label], time.perf_counter() - t0)
    ratio = best["with the check"] / best["without (before)"]
    print("sweep of 32 × 60-s runs (averaged model), best of", repeat, "after compiling:")
    for label, t in best.items():
        print(f"  {label:17s} {1e3 * t:8.1f} ms")
    print(f"  ratio with / without: {ratio:.3f}")


if __name__ == "__main__":
    print(machine())
    jnp.zeros(1).block_until_ready()
    criteria_rows()
    ftr_rows()
    check_cost_rows()
