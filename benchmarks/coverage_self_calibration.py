"""Do self-calibration's standard errors cover the truth? (the σ of mode reversal and sweeps)

`mode_reversal(...).bias_std`/`anisotropy_std` and `PrecessionCompensator.fit(...)
.drift_std` are read from each run's own samples (`hrgjax.calibration._sweeps`: white angle
noise and an angle random walk, by moments at two scales, carried through the reduction).
Monte Carlo with known truth: the same runs without noise (the reduction's deterministic
answer) against N seeds of the default gyro's noise with the switch-on bias off
(`tvg3_like(temperature_laws=False)`, `run_bias` 0), read as normal: ±1σ and ±2σ (nominal
68.3 %, 95.4 %) and the RMS of z = (estimate − truth)/σ (nominal 1). Each case twice: the
default noise, and with its Gauss–Markov bias (0.003 °/h pattern, T_c = 600 s, slower than
a hold or a sweep: read as bias, not in σ) off.

- mode reversal: FTR holds at 70°/160°, 150-s dwells, 20-s slew, `settle_s` 30 (120 samples
  per hold at 1 s);
- sweeps: `precession_plan((20.0,), precession_dps=1.0, settle_s=15.0)` (two 195-s sweeps,
  ±1 °/s) three times per seed (a three-temperature plan without temperature laws: the
  fewest sweeps, `MIN_POOLED_SWEEPS`, whose residuals give σ), the 5 drift coefficients of
  each pair pooled; σ from the data, and from the gyro's `NoiseModel.from_gyro` (`fit`'s
  `noise`).

Usage: `.venv/bin/python benchmarks/coverage_self_calibration.py [--n N]` (N seeds, default
100; ≈ 4 min on the 2-core machine).
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import hrgjax as hg  # noqa: E402
from hrgjax.calibration import self_calibration as sc  # noqa: E402
from hrgjax.pattern_noise import NoiseModel  # noqa: E402
from hrgjax.units import DEG_PER_H, DEG_PER_S  # noqa: E402

PAIRS = 3


def _gyro(gm: bool):
    gyro = hg.presets.tvg3_like(temperature_laws=False)
    gyro = eqx.tree_at(lambda g: g.noise.run_bias, gyro, 0.0)
    return gyro if gm else eqx.tree_at(lambda g: g.noise.bias_instability, gyro, 0.0)


def _row(label, z, sigma):
    z = np.asarray(z).ravel()
    print(f"| {label} | {z.size} | {np.mean(abs(z) < 1):.1%} | {np.mean(abs(z) < 2):.1%} "
          f"| {np.sqrt(np.mean(z**2)):.2f} | {np.median(sigma):.4f} |")  # fmt: skip


def reversal(keys, gm):
    gyro = _gyro(gm).in_mode("ftr")
    prof = hg.Profile.held_angles([70.0, 160.0], dwell_s=150.0, slew_s=20.0)
    clean = hg.simulate(gyro.without_noise(), prof, dt_out=1.0)
    truth = sc.mode_reversal(clean.t, clean.rebalance_rate, prof, settle_s=30.0)
    rec = jax.vmap(lambda k: hg.simulate(gyro, prof, key=k, dt_out=1.0))(keys)
    out = sc.mode_reversal(rec.t, rec.rebalance_rate, prof, settle_s=30.0)
    tag = "default noise" if gm else "no Gauss–Markov"
    for name in ("bias", "anisotropy"):
        err = np.asarray(getattr(out, name) - getattr(truth, name))
        std = np.asarray(getattr(out, f"{name}_std"))
        _row(f"mode reversal {name}, {tag}", err / std, std / DEG_PER_H)
        print(f"|  (MC spread {np.std(err) / DEG_PER_H:.4f} °/h) |||||")


def sweeps(keys, gm):
    gyro = _gyro(gm)
    plan = sc.precession_plan((20.0,), precession_dps=1.0, settle_s=15.0)
    profiles, settle = plan.profiles(), 15.0
    ts = jnp.arange(0.0, plan.duration_s + 0.5, plan.dt_out)
    rho = np.asarray(plan.precession_dps)[:, None] * DEG_PER_S * np.ones(ts.size)
    used = np.broadcast_to((np.asarray(ts) >= settle).astype(float), rho.shape)
    t2 = np.broadcast_to(np.asarray(ts), rho.shape)
    model = NoiseModel.from_gyro(gyro.noise, float(gyro.resonator.k_e))

    def run(key):  # PAIRS ±ρ pairs: the sweeps of PAIRS temperatures (no temperature laws)
        ks = jax.random.split(key, 2 * PAIRS).reshape(PAIRS, 2)
        sim = jax.vmap(lambda p, k: hg.simulate(gyro, p, key=k, ts=ts).wave_angle)
        return jax.vmap(lambda k: sim(profiles, k))(ks)

    def fit(theta):
        _, d = sc.fit_sweeps(*(jnp.asarray(x) for x in (t2, theta, rho, used)))
        return np.asarray(d)

    quiet = gyro.without_noise()
    truth = fit(np.asarray(jax.vmap(lambda p: hg.simulate(quiet, p, ts=ts))(profiles).wave_angle))
    err, std = [], {"from the data": [], "noise model given": []}
    for waves in np.asarray(jax.vmap(run)(keys)):
        groups = [(t2, w, rho, used) for w in waves]
        err += [fit(w) - truth for w in waves]
        for name, noise in (("from the data", None), ("noise model given", model)):
            std[name] += [d for _, d in sc.sweep_std(groups, 2, noise)]
    err = np.stack(err)
    tag = "default noise" if gm else "no Gauss–Markov"
    for name, sigma in std.items():
        sigma = np.stack(sigma)
        _row(f"sweeps, 5 drift coefficients, {tag}, σ {name}", err / sigma,
             sigma / DEG_PER_H / sc.K_E_NOMINAL)  # fmt: skip
    spread = np.std(err, axis=0) / DEG_PER_H / sc.K_E_NOMINAL
    print(f"|  (MC spread {np.round(spread, 4).tolist()} °/h) |||||")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100, help="seeds per case")
    args = ap.parse_args()
    keys = jax.random.split(jax.random.key(20261203), args.n)
    print("| case | z values | ±1σ (68.3 %) | ±2σ (95.4 %) | z-RMS | median σ [°/h] |")
    print("|---|---|---|---|---|---|")
    t0 = time.perf_counter()
    for gm in (False, True):
        reversal(keys, gm)
        sweeps(keys, gm)
    print(f"\n{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
