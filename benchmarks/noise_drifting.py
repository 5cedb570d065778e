"""The noise model of logs with no hold: a thermal chamber that ramps without stopping.

`NoiseModel.estimate` reads stretches where the table is still *and* the temperature holds;
a log of static runs whose temperature never holds has none, and discovery refused it ("pass
noise="). `NoiseModel.estimate_drifting` reads the static stretches whatever the temperature
does, with a rate-ramp column (a·b)² fitted beside the noise's (the drift rate the changing
temperature moves) and lags up to 256 s.

Side by side on the same gyro (the discovery's base gyro with a bias law of 0.02 °/h/°C and a
damping law of −0.01 /°C; the preset's noise: white angle 1″, ARW 0.002 °/√h, Gauss–Markov
0.003 °/h with T_c = 600 s, switch-on bias 0.2 °/h):

1. **estimates**: `estimate` on `continuous_dataset`'s six runs (600-s holds at each end of
   their ramps) against `estimate_drifting` on six runs that ramp from the first sample (three
   static, three turning at 2 °/s; ±60 °C in 1000 s, up and down, 3000 s at 1 Hz), and the
   drifting estimate without its ramp column;
2. **discover** on the no-hold logs: the verdict with nothing hidden (the nominal model is the
   truth: anything but `none` is a false find) and with both laws hidden (the bias law named?
   its estimate's z against the truth, beside the same on the logs with holds).

Usage: `.venv/bin/python benchmarks/noise_drifting.py [--seeds N]` (default 4; ≈ 1 min a
seed on 2 CPUs after the first compile).
"""

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import machine, report

from hrgjax.data import MeasuredData
from hrgjax.discovery import discover
from hrgjax.discovery.generate import base_gyro, continuous_dataset, inject
from hrgjax.pattern_noise import NoiseModel
from hrgjax.profiles import Profile
from hrgjax.simulate import simulate
from hrgjax.units import DEG_PER_SQRT_H, K_E_NOMINAL

LAWS = {"bias_temperature": 0.02, "damping_anisotropy_temperature": -0.01}
ROWS = ((-20, 40, 0.0, 0.0), (40, -20, 2.0, 0.0), (-20, 40, 0.0, 45.0),
        (40, -20, 2.0, 30.0), (0, 60, 0.0, -30.0), (60, 0, 2.0, 60.0))  # fmt: skip
"""(start °C, turn °C, table rate °/s, initial wave angle °) of each no-hold run."""
DURATION_S = 3000.0


@jax.jit
def _runs(gyro, profiles, keys, ts):
    return jax.vmap(lambda p, k: simulate(gyro, p, key=k, ts=ts, rtol=1e-11, atol=1e-12))(
        profiles, keys
    )


def no_hold_log(effects, key) -> MeasuredData:
    """Six runs whose temperature ramps from the first sample to the last (`ROWS`)."""
    profs = [
        Profile.piecewise(
            [0.0, 1000.0, 2000.0, DURATION_S], [rate] * 4, [a, b, a, b], wave_angle0_deg=angle
        )  # fmt: skip
        for a, b, rate, angle in ROWS
    ]
    stacked = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *profs)
    ts = jnp.arange(0.0, DURATION_S + 0.5, 1.0)
    gyro = inject(base_gyro(), effects)
    return _runs(gyro, stacked, jax.random.split(key, len(ROWS)), ts).to_data()


def without_ramp_column(data):
    """`estimate_drifting`'s stretches with `estimate`'s fit (no ramp column): every static
    stretch read as still (the temperature set constant)."""
    cols = dict(data.columns)
    cols["temperature_c"] = np.zeros(len(data))
    return NoiseModel.estimate(MeasuredData(cols), max_lag_s=256.0)


def main(n: int):
    print(f"machine: {machine()}")
    k_e = K_E_NOMINAL
    arw = lambda m: m.angle_random_walk  # noqa: E731  [rad/√s of pattern angle]
    truth = 0.002 * DEG_PER_SQRT_H * k_e
    print(f"ARW [rad/√s of pattern angle]: truth {truth:.3g} (0.002 °/√h at k_e {k_e:.3f})")
    ratios, z, z_held, named, false = [], [], [], 0, 0
    t0 = time.perf_counter()
    for seed in range(n):
        key = jax.random.key(100 + seed)
        held = continuous_dataset(LAWS, key=key, duration_s=3100)
        ramping = no_hold_log(LAWS, key)
        still, drifting = NoiseModel.estimate(held), NoiseModel.estimate_drifting(ramping)
        bare = without_ramp_column(ramping)
        ratios.append(arw(drifting) / arw(still))
        print(f"seed {seed}: holds {arw(still):.3g}  no hold {arw(drifting):.3g} "
              f"(σ_w {drifting.angle_white:.3g} vs {still.angle_white:.3g})  no hold without "
              f"the ramp column {arw(bare):.3g}, GM {bare.gm_sigma:.3g} rad/s", flush=True)  # fmt: skip
        null = discover(no_hold_log(None, key))
        false += null.verdict != "none"
        rep = discover(ramping)
        b1 = rep.parameters.get("bias_temperature", {}).get("b1")
        named += b1 is not None
        if b1 is not None:
            z.append((b1["value"] - LAWS["bias_temperature"]) / b1["sigma"])
        b1h = discover(held).parameters.get("bias_temperature", {}).get("b1")
        if b1h is not None:
            z_held.append((b1h["value"] - LAWS["bias_temperature"]) / b1h["sigma"])
        print(f"   with holds: b1 {b1h}")
        print(f"   discover: nothing hidden → {null.verdict} {null.accepted}; with the bias law → "
              f"{rep.verdict} {rep.accepted}, b1 {b1}", flush=True)  # fmt: skip
    print(f"\n{n} seeds, {time.perf_counter() - t0:.0f} s")
    print(f"ARW no hold / holds: {np.min(ratios):.2f}–{np.max(ratios):.2f}")
    print(
        f"bias law named {named}/{n}, z of b1: {np.round(z, 2).tolist()} "
        f"(RMS {np.sqrt(np.mean(np.square(z))):.2f}); on the logs with holds "
        f"{np.round(z_held, 2).tolist()} (RMS {np.sqrt(np.mean(np.square(z_held))):.2f})"
    )
    print(f"nothing hidden: false finds {false}/{n}")
    report("no-hold ARW / held ARW (median)", float(np.median(ratios)), "", target="≈ 1")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=4)
    main(ap.parse_args().seeds)
