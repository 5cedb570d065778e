"""The carrier path's stages in a loop or unrolled (issue 45: compile time; `carrier.py`'s
`LOOPED_STAGES_STEPS` rule).

With the loops closed every one of a Dormand–Prince 8 step's 13 stages demodulates the state
and runs the loop laws. Unrolled (Python), the step is 13 copies of that right-hand side;
in a loop (`lax.fori_loop` over the stages) it is one. Each case below runs in a fresh
process with the compile cache off, once with each form (the rule forced either way), and
prints the first call (trace, lower, compile and run), the compiled run (best of 3) and the
number of steps for which the compile time saved pays for the slower run:

- one closed-loop run of the default gyro (temperature laws on), 0.05 s with a rate ramp and a
  knot, rtol 1e-8 (11 intervals of 250 steps: `resonator_speed.py`'s case);
- the same under `jax.vmap` over 16 rates (one program, 16 trajectories);
- the gradient of its final wave angle with respect to the resonator (stored-state
  derivatives, `hrgjax._stepped`).

XLA's default flags, as users run (`make test`'s quick-compile flags are dropped here).
Usage: `.venv/bin/python benchmarks/carrier_stages.py` (≈ 3 min on 2 cores).
"""

import json
import os
import subprocess
import sys

CASE = r"""
import json, sys, time
from _common import best_of, first_call
import equinox as eqx
import jax, jax.numpy as jnp
import numpy as np
import hrgjax as hg
from hrgjax.resonator import carrier

carrier.LOOPED_STAGES_STEPS = {"cpu": 10**12 if sys.argv[2] == "looped" else 0}
seen = {}
jax.monitoring.register_event_duration_secs_listener(
    lambda e, d, **k: seen.__setitem__(e.rsplit("/", 1)[-1], seen.get(e.rsplit("/", 1)[-1], 0) + d))
gyro = hg.presets.tvg3_like(noise=False)
ts = np.linspace(0.005, 0.05, 10)

def prof(rate_dps=40.0):
    return hg.Profile(t=np.array([0.0, 0.012, 0.05]), rate=jnp.deg2rad(jnp.stack([0.0 * rate_dps, rate_dps, rate_dps])),
                      temperature=np.array([20.0, 20.5, 21.0]), accel=np.zeros((3, 3)),
                      wave_angle0=np.deg2rad(30.0))

case = sys.argv[1]
if case == "single":
    fn = lambda: hg.simulate(gyro, prof(), model="full", ts=ts).wave_angle
elif case == "vmap16":
    rates = jnp.linspace(10.0, 80.0, 16)
    run = jax.jit(jax.vmap(lambda r: hg.simulate(gyro, prof(r), model="full", ts=ts, fixed_step=2e-5).wave_angle))
    fn = lambda: run(rates)
else:
    def final(res):
        g = eqx.tree_at(lambda g: g.resonator, gyro, res)
        return hg.simulate(g, prof(), model="full", ts=ts, fixed_step=2e-5).wave_angle[-1]
    grad = eqx.filter_jit(eqx.filter_grad(final))
    fn = lambda: jax.tree_util.tree_leaves(grad(gyro.resonator))
first, out = first_call(fn)
run = best_of(fn, 3)
print(json.dumps({"first": first, "run": run, **seen,
                  "value": float(np.ravel(np.asarray(jax.tree_util.tree_leaves(out)[0]))[-1])}))
"""


def one(case, form):
    here = os.path.dirname(os.path.abspath(__file__))
    env = dict(os.environ, HRGJAX_NO_CACHE="1", PYTHONPATH=here)
    flags = env.get("XLA_FLAGS", "").split()
    env["XLA_FLAGS"] = " ".join(f for f in flags if "optimization_level" not in f
                                and "fusion_emitters" not in f and "expensive_passes" not in f)  # fmt: skip
    proc = subprocess.run([sys.executable, "-c", CASE, case, form], env=env, cwd=here,
                          capture_output=True, text=True, timeout=900)  # fmt: skip
    if proc.returncode:
        raise SystemExit(proc.stderr[-3000:])
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main():
    from _common import machine, report

    print(f"machine: {machine()}")
    for case, what, steps in (
        ("single", "one 0.05-s run, loops closed, laws on", 2750),
        ("vmap16", "16 such runs under vmap (2e-5 s steps)", 2750 * 16),
        ("grad", "gradient of the final angle (2e-5 s steps)", 2750),
    ):
        rows = {form: one(case, form) for form in ("looped", "unrolled")}
        a, b = rows["looped"], rows["unrolled"]
        compile_a = a["first"] - a["run"]
        compile_b = b["first"] - b["run"]
        per_step = (a["run"] - b["run"]) / steps
        pays = (compile_b - compile_a) / per_step if per_step > 0 else float("inf")
        print(f"  {what}:")
        for form, r in rows.items():
            print(f"    {form:9s} first call {r['first']:6.2f} s (trace "
                  f"{r.get('jaxpr_trace_duration', 0):.2f}, lower "
                  f"{r.get('jaxpr_to_mlir_module_duration', 0):.2f}, compile "
                  f"{r.get('backend_compile_duration', 0):.2f}), compiled run "
                  f"{r['run'] * 1e3:7.1f} ms")  # fmt: skip
        print(f"    same result within {abs(a['value'] - b['value']):.1e}; the loop's compile "
              f"saving pays for {pays:,.0f} trajectory-steps")  # fmt: skip
        report(f"carrier stages looped, {case}: first call", a["first"], "s",
               "unrolled / looped first call", b["first"] / a["first"])  # fmt: skip
        report(f"carrier stages looped, {case}: compiled run", a["run"] * 1e3, "ms",
               "looped / unrolled run", a["run"] / b["run"])  # fmt: skip


if __name__ == "__main__":
    main()
