"""Monte Carlo EDF of adev, oadev, mdev, hdev and ohdev at m = 1, 2 for rate noise drawn by
hrgjax's own generators, against `hg.allan.edf_discrete` (the estimator's exact EDF for
continuous rate noise's interval means) and Greenhall's (`edf_greenhall`, averaged phase).

- rate random walk: `hrgjax.ins.sensors.ImuModel(gyro_rate_random_walk=...).apply` (its
  exact interval means; the three axes are three records);
- flicker rate noise: 16 first-order Gauss–Markov rates with correlation times 2⁻⁴ … 2¹¹ s
  and equal variance (S_y ∝ 1/f from ≈ 1e-4 Hz to ≈ 2 Hz), each drawn with its exact
  interval integrals by `hrgjax.noise.rate_noise_angle`.

The Monte Carlo EDF is 2·E[σ̂²]²/Var σ̂² over the records, its ±1σ from 40 batches. The
estimators are computed here from their definitions (NumPy filters on the summed phase).

Usage: `.venv/bin/python benchmarks/edf_gyro_noise.py [--records 40000]` (≈ 1 minute at
40 000 records of 256 samples on two cores).
"""

import argparse
import math
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

import hrgjax as hg  # noqa: E402
from hrgjax.noise import Noise, rate_noise_angle  # noqa: E402

N_RATE = 256
KINDS = {"adev": (2, False, False), "oadev": (2, True, False), "mdev": (2, True, True),
         "hdev": (3, False, False), "ohdev": (3, True, False)}  # fmt: skip
GM_TIMES = 2.0 ** np.arange(-4, 12)


def estimates(x, m, d, overlapping, modified):
    """Each record's variance estimate (rows of phase x) from the filter's definition."""
    c = np.zeros(d * m + 1)
    c[::m] = [(-1) ** k * math.comb(d, k) for k in range(d + 1)]
    if modified:
        c = np.convolve(c, np.ones(m)) / m
    t = np.lib.stride_tricks.sliding_window_view(x, c.size, axis=1) @ c
    t = t[:, :: (1 if overlapping else m)]
    return np.mean(t * t, axis=1)


def draw(records):
    imu = hg.ins.sensors.ImuModel(gyro_rate_random_walk=1e-6)
    zero = jnp.zeros((N_RATE, 3))
    walk = jax.jit(jax.vmap(lambda k: imu.apply(k, zero, zero, 1.0)[0]))
    keys = jax.random.split(jax.random.key(1), -(-records // 3))
    y = np.asarray(walk(keys)).transpose(0, 2, 1).reshape(-1, N_RATE)[:records]
    x_walk = np.concatenate([np.zeros((records, 1)), np.cumsum(y, axis=1)], axis=1)
    ts = jnp.arange(N_RATE + 1, dtype=float)

    def flicker(k):
        ks = jax.random.split(k, GM_TIMES.size)
        return sum(rate_noise_angle(ks[i], ts, Noise(bias_instability=1e-6,
                                                     correlation_time=GM_TIMES[i]))
                   for i in range(GM_TIMES.size))  # fmt: skip

    x_flicker = np.asarray(jax.jit(jax.vmap(flicker))(jax.random.split(jax.random.key(2), records)))
    return {-2: x_walk, -1: x_flicker}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", type=int, default=40000)
    args = ap.parse_args(argv)
    t0 = time.time()
    phases = draw(args.records)
    n = N_RATE + 1
    print(f"edf_gyro_noise.py: {args.records} records of {N_RATE} rate samples "
          f"(drawn in {time.time() - t0:.0f} s)")  # fmt: skip
    print("noise            kind   m   Monte Carlo    edf_discrete  Greenhall  discrete/MC")
    worst = 0.0
    for alpha, name in ((-2, "rate random walk"), (-1, "flicker rate")):
        for kind, (d, ov, mod) in KINDS.items():
            for m in (1, 2):
                v = estimates(phases[alpha], m, d, ov, mod)
                mc = 2 * v.mean() ** 2 / v.var()
                b = [2 * p.mean() ** 2 / p.var() for p in np.array_split(v, 40)]
                se = np.std(b, ddof=1) / np.sqrt(len(b))
                exact = hg.allan.edf_discrete(alpha, d, m, n, ov, mod)
                greenhall = hg.allan.edf_greenhall(alpha, d, m, n, ov, mod)
                worst = max(worst, abs(exact / mc - 1))
                print(f"{name:16s} {kind:6s} {m}  {mc:7.1f} ± {se:3.1f}  {exact:9.1f}  "
                      f"{greenhall:9.1f}   {exact / mc:.3f}")  # fmt: skip
    print(f"largest |edf_discrete/MC − 1|: {worst:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
