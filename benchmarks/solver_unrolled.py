"""Should the averaged model's default solver be Tsit5 with its stages written out
(`UnrolledTsit5` of `gradient_trials.py`) instead of diffrax's `Tsit5`? Side by side in one
process, interleaved, on what users run:

1. one averaged run of 180 s at 10 °/s, noise on, 0.1-s outputs (`simulate` under jit);
2. seed 000's bench plan: 209 static + 209 rotating runs × 180 s, noise on (as
   `calibration_plan_speed.py`);
3. the gradient of `gradient_cost.py`'s loss (19 rotation runs × 60 s, 8 resonator
   parameters) and its forward.

Prints compile + first call and the best later call of each, their ratios
and the largest difference between the two solvers' wave angles. Not adopted: the runs
are 0.80–1.12× diffrax's, but compiling takes 1.1–3.8× as long (benchmarks/README.md).

Usage: `.venv/bin/python benchmarks/solver_unrolled.py` (≈ 2 min on 2 cores).
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from _common import best_of, first_call, machine, report
from gradient_trials import UnrolledTsit5

import hrgjax as hg

SOLVERS = {"diffrax Tsit5": diffrax.Tsit5(), "unrolled": UnrolledTsit5()}


def problems():
    gyro = hg.presets.tvg3_like()
    key = jax.random.key(0)
    out = {}

    one_prof = hg.Profile.constant_rate(10.0, 180.0, 20.0)
    out["one run, 180 s"] = lambda s: eqx.filter_jit(
        lambda: hg.simulate(gyro, one_prof, key=key, solver=s).wave_angle
    )

    static, rotation = hg.calibration.seed_plan()
    ts_s, ts_r = jnp.arange(0.0, 180.5, 1.0), jnp.arange(0.0, 180.25, 0.5)

    def plan(s):
        def one(p, k, ts):
            return hg.simulate(gyro, p, key=k, bias_key=key, ts=ts, solver=s).wave_angle

        a = jax.vmap(lambda p, k: one(p, k, ts_s))(
            static.profiles(), jax.random.split(key, static.size)
        )
        b = jax.vmap(lambda p, k: one(p, k, ts_r))(
            rotation.profiles(), jax.random.split(key, rotation.size)
        )
        return jnp.concatenate([a.ravel(), b.ravel()])

    out["seed plan, 418 runs"] = lambda s: jax.jit(lambda: plan(s))

    quiet = hg.presets.tvg3_like(noise=False, temperature_laws=False)
    rot = hg.calibration.rotation_plan((20.0,), duration_s=60.0)
    ts = jnp.arange(0.0, 60.5, 1.0)
    profiles = rot.profiles()
    target = jax.vmap(lambda p: hg.simulate(quiet, p, ts=ts).wave_angle)(profiles) + 1e-4
    params, static_part = eqx.partition(quiet.resonator, eqx.is_inexact_array)

    def loss(p, s):
        g = eqx.tree_at(lambda g: g.resonator, quiet, eqx.combine(p, static_part))
        sim = jax.vmap(lambda q: hg.simulate(g, q, ts=ts, solver=s).wave_angle)(profiles)
        return jnp.mean((sim - target) ** 2)

    out["loss, 19 runs × 60 s"] = lambda s: jax.jit(lambda: loss(params, s))
    out["gradient of the loss"] = lambda s: jax.jit(
        lambda: jnp.stack(jax.tree_util.tree_leaves(jax.grad(loss)(params, s)))
    )
    return out


def main():
    print(f"machine: {machine()}")
    rows = {}
    for name, make in problems().items():
        fns = {s: make(solver) for s, solver in SOLVERS.items()}
        first, values = {}, {}
        for s, fn in fns.items():
            first[s], values[s] = first_call(fn)
        a, b = (np.asarray(values[s]) for s in SOLVERS)
        delta = float(np.max(np.abs(a - b)) / np.max(np.abs(a)))
        best = {s: [] for s in fns}
        for _ in range(3):  # interleaved: the machine's drift hits both alike
            for s, fn in fns.items():
                best[s].append(best_of(fn, 5))
        rows[name] = (first, {s: min(v) for s, v in best.items()}, delta)
    print(f"{'':24s} {'diffrax Tsit5':>22s} {'unrolled':>22s} {'ratio':>7s} {'max rel. Δ':>11s}")
    for name, (first, wall, delta) in rows.items():
        d, u = (wall[s] for s in SOLVERS)
        fd, fu = (first[s] for s in SOLVERS)
        print(f"{name:24s} {d * 1e3:10.2f} ms ({fd:5.1f} s) {u * 1e3:10.2f} ms ({fu:5.1f} s) "
              f"{u / d:6.2f}× {delta:11.1e}")  # fmt: skip
        report(f"{name}, unrolled Tsit5", u * 1e3, "ms", "/ diffrax Tsit5", u / d)
        report(f"{name}, unrolled Tsit5: compile + first", fu, "s", "/ diffrax Tsit5", fu / fd)
    g, f = rows["gradient of the loss"][1], rows["loss, 19 runs × 60 s"][1]
    for s in SOLVERS:
        print(f"gradient / forward, {s}: {g[s] / f[s]:.2f}×")


if __name__ == "__main__":
    main()
