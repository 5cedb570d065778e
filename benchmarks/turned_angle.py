"""The averaged model's turned angle taken out of the solved state
(`hrgjax.resonator.averaged.reference_angle`): what it costs and what it buys, with it and
without it, side by side in one run (each arm in its own process, so that each compiles its
own programs; the "accumulated" arm solves θ itself, as before the change).

Prints, per arm: accepted steps, warm wall time and the error of hour-long runs of the
docs/resonator.md example (ideal loops, Δ(1/τ) = 2e-5 1/s, θ_τ = 0.3 rad) at constant rates,
against the exact ODE dθ/dt = −k_eΩ + ½Δ(1/τ) sin2(θ − θ_τ) (scipy DOP853 at rtol 1e-13 on
the residual r = θ + k_eΩt); the same for a free resonator (`Control.free()`, 600 s, against
the same run at rtol 1e-12); and the PI-loop `tvg3_like` (noise off, no laws), which has no
turning state and must not change.

Usage: `.venv/bin/python benchmarks/turned_angle.py`.
"""

import json
import subprocess
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import child_or_main, machine
from scipy.integrate import solve_ivp

import hrgjax as hg
from hrgjax.simulate import simulate_with_stats

DEG = np.pi / 180
D, THETA_TAU, K_E = 2e-5, 0.3, 0.554
RATES_DPS = (1.0, 10.0, 100.0, 400.0)


def _resonator():
    return hg.Resonator(omega=2 * jnp.pi * 5e3, tau=640.0, k_e=K_E, delta_omega=0.0,
                        theta_omega=0.0, delta_inv_tau=D, theta_tau=THETA_TAU, chi=0.0)  # fmt: skip


def _timed(gyro, prof, **kw):
    simulate_with_stats(gyro, prof, **kw)  # compile
    t0 = time.perf_counter()
    rec, steps, _ = simulate_with_stats(gyro, prof, **kw)
    jax.block_until_ready(rec.wave_angle)
    return rec, int(steps), time.perf_counter() - t0


def _truth(t, w):
    field = lambda s, r: 0.5 * D * np.sin(2 * (r + 10 * DEG - K_E * w * s - THETA_TAU))  # noqa: E731
    r = solve_ivp(field, (t[0], t[-1]), [0.0], t_eval=t, rtol=1e-13, atol=1e-18, method="DOP853")
    return r.y[0] + 10 * DEG - K_E * w * t


def child(out):
    if sys.argv[sys.argv.index("--arm") + 1] == "accumulated":
        import hrgjax.resonator.averaged as averaged

        averaged.turning_index = lambda gyro: None  # before anything compiles: solve θ itself
    rows = {}
    ideal = hg.presets.ideal(_resonator())
    for rate in RATES_DPS:
        prof = hg.Profile.constant_rate(rate, 3600.0, 20.0, wave_angle0_deg=10.0)
        rec, steps, wall = _timed(ideal, prof, dt_out=10.0)
        err = np.abs(np.asarray(rec.wave_angle) - _truth(np.asarray(rec.t), rate * DEG)).max()
        rows[f"ideal, {rate:g} °/s, 1 h"] = (steps, wall, float(err))
    free = hg.Gyro(resonator=_resonator(), control=hg.Control.free(), readout=hg.Readout())
    for rate in (100.0, 400.0):
        prof = hg.Profile.constant_rate(rate, 600.0, 20.0, wave_angle0_deg=10.0)
        rec, steps, wall = _timed(free, prof, dt_out=10.0)
        tight = simulate_with_stats(free, prof, dt_out=10.0, rtol=1e-12, atol=1e-14)[0]
        err = np.abs(np.asarray(rec.true_wave_angle) - np.asarray(tight.true_wave_angle)).max()
        rows[f"free, {rate:g} °/s, 600 s"] = (steps, wall, float(err))
    pi = hg.presets.tvg3_like(noise=False, temperature_laws=False)
    for rate in (0.0, 10.0, 400.0):
        prof = hg.Profile.constant_rate(rate, 3600.0 if rate < 100 else 600.0, 20.0)
        rec, steps, wall = _timed(pi, prof, dt_out=1.0)
        rows[f"PI tvg3_like, {rate:g} °/s"] = (steps, wall, float(rec.wave_angle[-1]))
    with open(out, "w") as f:
        json.dump(rows, f)


def main():
    print(f"machine: {machine()}")
    arms = {}
    for arm in ("residual", "accumulated"):
        out = f"/tmp/hrgjax_turned_angle_{arm}.json"
        subprocess.run([sys.executable, __file__, "--child", out, "--arm", arm], check=True)
        with open(out) as f:
            arms[arm] = json.load(f)
    new, old = arms["residual"], arms["accumulated"]
    print(f"\n{'run':>26} {'steps':>15} {'ratio':>6} {'warm wall [s]':>17} "
          f"{'max error [rad] (PI: end angle)':>34}")  # fmt: skip
    print(
        f"{'':>26} {'residual / acc.':>15} {'':>6} {'residual / acc.':>17} {'residual / acc.':>34}"
    )
    for name in new:
        (sn, wn, en), (so, wo, eo) = new[name], old[name]
        fmt = ".12g" if name.startswith("PI") else ".2e"
        print(f"{name:>26} {sn:>7} / {so:<7} {sn / so:6.2f} {wn:7.3f} / {wo:<7.3f} "
              f"{en:>16{fmt}} / {eo:<{fmt}}")  # fmt: skip


if __name__ == "__main__":
    child_or_main(child, main)
