"""The adaptive solver's longest step, bounded by the loops' time constant
(`hrgjax.resonator.control.max_step`, `LOOP_STEPS` / the fastest loop bandwidth): what it
costs and what it buys, with the bound and without it, side by side in one run (each arm in
its own process, so that each compiles its own programs).

Prints, per arm: the accepted steps and the warm wall time of hour-long averaged-model runs
(`tvg3_like`, noise off, no temperature laws, unless named: at rest, at 10 °/s, in
force-to-rebalance mode, the default preset with its noise and laws, and the same gyro with
every defect 0, which sits exactly on its loops' equilibrium), then the gradient of a 20-s
amplitude-and-quadrature loss at that equilibrium against central differences.

Usage: `.venv/bin/python benchmarks/max_step.py`.
"""

import json
import subprocess
import sys
import time

import equinox as eqx
import jax
import jax.numpy as jnp
from _common import child_or_main, machine

import hrgjax as hg
from hrgjax.simulate import simulate_with_stats

HOUR = 3600.0


def _zero(gyro):
    return eqx.tree_at(
        lambda g: (g.resonator.delta_omega, g.resonator.delta_inv_tau, g.resonator.chi,
                   g.control.excitation_phase, g.readout.gain_mismatch, g.readout.cross_talk,
                   g.readout.misalignment, g.rate_bias),
        gyro, (0.0,) * 8,
    )  # fmt: skip


def _cases():
    plain = hg.presets.tvg3_like(noise=False, temperature_laws=False)
    rest = hg.Profile.static(HOUR, 20.0, 30.0)
    return {
        "at rest": (plain, rest, {}),
        "10 °/s": (plain, hg.Profile.constant_rate(10.0, HOUR, 20.0), {}),
        "force-to-rebalance, at rest": (plain.in_mode("ftr"), rest, {}),
        "default preset (noise, laws), at rest": (
            hg.presets.tvg3_like(), rest, {"key": jax.random.key(0)}),
        "every defect 0, at rest": (_zero(plain), rest, {}),
    }  # fmt: skip


def child(out):
    if sys.argv[sys.argv.index("--arm") + 1] == "none":
        import hrgjax.resonator.control as control

        control.LOOP_STEPS = float("inf")  # before anything compiles: no bound
    rows = {}
    for name, (gyro, profile, kw) in _cases().items():
        run = lambda g=gyro, p=profile, k=kw: simulate_with_stats(g, p, dt_out=1.0, **k)
        steps = int(run()[1])
        t0 = time.perf_counter()
        jax.block_until_ready(run()[0].wave_angle)
        rows[name] = (steps, time.perf_counter() - t0)
    zero = _zero(hg.presets.tvg3_like(noise=False, temperature_laws=False))
    prof = hg.Profile.static(20.0, 20.0, 30.0)

    def loss(x):
        g = eqx.tree_at(lambda g: g.readout.gain_mismatch, zero, x)
        rec = hg.simulate(g, prof, dt_out=1.0)
        return jnp.mean(rec.amplitude) + 1e3 * jnp.mean(rec.quadrature)

    grad = float(jax.grad(loss)(jnp.asarray(0.0)))
    fd = float((loss(1e-7) - loss(-1e-7)) / 2e-7)
    with open(out, "w") as f:
        json.dump({"rows": rows, "grad": grad, "fd": fd}, f)


def main():
    print(f"machine: {machine()}")
    arms = {}
    for arm in ("bound", "none"):
        out = f"/tmp/hrgjax_max_step_{arm}.json"
        cmd = [sys.executable, __file__, "--child", out, "--arm", arm]
        subprocess.run(cmd, check=True)
        with open(out) as f:
            arms[arm] = json.load(f)
    b, n = arms["bound"]["rows"], arms["none"]["rows"]
    print(f"\n{'1-h run (averaged model)':>40} {'steps':>14} {'ratio':>6} {'warm wall [s]':>16}")
    print(f"{'':>40} {'bound / none':>14} {'':>6} {'bound / none':>16}")
    for name in b:
        print(f"{name:>40} {b[name][0]:>6} / {n[name][0]:<6} {b[name][0] / n[name][0]:6.2f} "
              f"{b[name][1]:7.3f} / {n[name][1]:<7.3f}")  # fmt: skip
    print("\nd(mean amplitude + 1e3 mean quadrature)/d gain_mismatch, 20 s at rest, defects 0:")
    for arm in ("bound", "none"):
        a = arms[arm]
        print(f"  {arm:>5}: reverse mode {a['grad']:+.6e}, central difference {a['fd']:+.6e}")


if __name__ == "__main__":
    child_or_main(child, main)
