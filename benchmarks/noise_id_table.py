"""How often `hg.allan.noise_id` names each power-law noise, octave by octave.

Records of N rate samples (N + 1 phase points) of one power-law noise, rate PSD ∝ f^α for
α = 2 (white angle), 1 (flicker angle), 0 (white rate), −1 (flicker rate), −2 (rate random
walk), by Kasdin & Walter's (1992) filter (flicker angle noise up to f_h = 1/(2τ₀));
`noise_id(x, m)` at every octave m up to N: the share of records read right, per α and m
(`--full`: every α read). The lag-1 autocorrelation reads m ≤ N/29 (≥ 30 decimated points),
B1/R(n) beyond from 8 averages, the α carried on at 4 and 2. `--average M`: each rate
sample the mean of M of the filter's (its phase of N·M + 1 points decimated by M), as a gyro
that outputs angle increments (rate averaged over each sample interval): at m = 1 such data
carry the decimated noises' lag-1 autocorrelations. Run against an older hrgjax
(PYTHONPATH=...) for its figures.

Usage: `.venv/bin/python benchmarks/noise_id_table.py [--n 200] [--samples 4096]
[--rule hrgjax|stable32] [--dmax 2] [--average 1] [--full] [--ml]` (≈ 3 s on 2 shared
cores; ×M with `--average M`). `--ml` (short records, e.g. `--samples 16 --n 300`): the
share read right at m = 1 by `noise_id` and by the maximum-likelihood choice among the five
power laws (`ml_alpha`), what so few samples can tell.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import hrgjax as hg


def kasdin(alpha, n, rng):
    """n phase points of power-law noise with rate PSD ∝ f^α (phase exponent α − 2)."""
    h = np.ones(n)
    k = np.arange(1, n)
    h[1:] = np.cumprod((-(alpha - 2) / 2.0 + k - 1) / k)
    w = np.zeros(2 * n)
    w[:n] = rng.normal(size=n)
    return np.fft.irfft(np.fft.rfft(w) * np.fft.rfft(np.r_[h, np.zeros(n)]))[:n]


def _second_difference_cov(alpha, n):
    """Covariance of n second differences of Kasdin's phase of rate PSD ∝ f^α: fractionally
    differenced white noise (1 − B)^δ w, δ = (2 + α)/2, unit innovation (its autocovariance
    γ(0) = Γ(1 + 2δ)/Γ(1 + δ)², γ(k) = γ(k − 1)(k − 1 − δ)/(k + δ))."""
    delta = (2 + alpha) / 2.0
    g = np.empty(n)
    g[0] = math.exp(math.lgamma(1 + 2 * delta) - 2 * math.lgamma(1 + delta))
    for k in range(1, n):
        g[k] = g[k - 1] * (k - 1 - delta) / (k + delta)
    i = np.arange(n)
    return g[np.abs(i[:, None] - i[None, :])]


def ml_alpha(x):
    """The maximum-likelihood power law of phase `x` among α = 2 … −2: the Gaussian
    likelihood of its second differences under each law's exact covariance, the scale
    profiled out (a bound on what any read of so few points can do; O(n³))."""
    d = np.diff(x, 2)
    best = None
    for alpha in (2, 1, 0, -1, -2):
        chol = np.linalg.cholesky(_second_difference_cov(alpha, d.size))
        z = np.linalg.solve(chol, d)
        like = -0.5 * d.size * math.log(z @ z / d.size) - np.sum(np.log(np.diag(chol)))
        if best is None or like > best[0]:
            best = (like, alpha)
    return best[1]


def main_ml(a):
    """`--ml`: the share of records read right at m = 1 by `noise_id` and by `ml_alpha`."""
    print(f"{a.n} records of {a.samples} samples: % read right at m = 1, noise_id → "
          "maximum likelihood")  # fmt: skip
    for alpha in (2, 1, 0, -1, -2):
        rng = np.random.default_rng(700 + alpha)
        xs = [kasdin(alpha, a.samples + 1, rng) for _ in range(a.n)]
        ours = np.mean([hg.allan.noise_id(x, [1])[0] == alpha for x in xs]) * 100
        ml = np.mean([ml_alpha(x) == alpha for x in xs]) * 100
        print(f"{alpha:4d}  {ours:5.0f} → {ml:5.0f}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--samples", type=int, default=4096)
    ap.add_argument("--dmax", type=int, default=2)
    ap.add_argument("--rule", default="hrgjax")
    ap.add_argument("--average", type=int, default=1)
    ap.add_argument("--full", action="store_true")
    ap.add_argument("--ml", action="store_true")
    a = ap.parse_args()
    if a.ml:
        main_ml(a)
        return
    ms = 2 ** np.arange(int(np.log2(a.samples)))
    t0 = time.time()
    print(f"{a.n} records of {a.samples} samples (each the mean of {a.average}), rule {a.rule}, "
          f"dmax {a.dmax}: % read right")  # fmt: skip
    print("α \\ m " + " ".join(f"{m:>5d}" for m in ms))
    for alpha in (2, 1, 0, -1, -2):
        rng = np.random.default_rng(500 + alpha)
        got = np.array([hg.allan.noise_id(kasdin(alpha, a.samples * a.average + 1, rng)
                                          [:: a.average], ms, dmax=a.dmax, rule=a.rule)
                        for _ in range(a.n)])  # fmt: skip
        print(f"{alpha:4d}  " + " ".join(f"{np.mean(got[:, j] == alpha) * 100:5.0f}"
                                         for j in range(ms.size)))  # fmt: skip
        if a.full:
            for j, m in enumerate(ms):
                kinds, counts = np.unique(got[:, j], return_counts=True)
                print(f"      m = {m}: {dict(zip(kinds.tolist(), counts.tolist(), strict=True))}")
    print(f"({time.time() - t0:.0f} s)")


if __name__ == "__main__":
    main()
