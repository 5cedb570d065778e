"""Do the Allan-family intervals hold where a gyro's noises cross (a noise *mixture*)?

Monte Carlo with exact truth: records of N rate samples (τ₀ = 1) of a sum of independent
noises, each drawn exactly — white angle noise (`wpm`, σ of the phase per point), white rate
noise (`wfm`, σ per sample), a Gauss–Markov rate taken as interval means (`gm`, σ and T in
samples, by the Toeplitz Cholesky factor), flicker rate noise (`ffm`: the rate's increments
ARFIMA(0, −½, 0) by circulant embedding) and a rate random walk (`rwfm`). The truth at each
octave m is the exact Allan or modified Allan variance of the sum, from the components'
autocovariances carried through the estimator's filter (independent of hrgjax). Then
`hg.allan.deviation(y, 1.0, kind, "octave")` on each record: per τ the share of ±1σ
intervals (and of 95 % intervals, from (dev, edf) by χ²) that hold the truth, E[dev²]/σ²,
the median EDF, the share of records whose bias (mtotdev, ttotdev) or EDF (oadev) came
from the fitted mixture (`AllanResult.mixture`; "-" on an hrgjax without it) and the types
read.

Mixtures (`MIXES`): `tvg3_10s` (`hg.presets.tvg3_like`'s noise at 0.1 Hz: readout 1″/k_e
white angle, ARW 0.002 °/√h, a Gauss–Markov 0.003 °/h with T_c = 600 s; white angle crosses
ARW at m ≈ 68), `tvg3_1s` (the same at 1 Hz, m ≈ 680), `fog_100hz` (a navigation FOG:
quantisation 0.01″, ARW 0.002 °/√h, bias instability 0.003 °/h as flicker rate; crossing at
m ≈ 2), `four_band` (white angle | ARW at m = 4, ARW | flicker at 64, flicker | RRW at 512).

Usage: `.venv/bin/python benchmarks/coverage_mixture.py [--mix fog_100hz,four_band,tvg3_10s,tvg3_1s]
[--kinds oadev,mtotdev] [--n 300] [--samples 1024] [--seed 1]` (≈ 20 s per mixture and kind
at 300 records of 1 024 samples, 2 shared cores); against an older hrgjax with
PYTHONPATH=... for its figures (the same seed draws the same records).
"""

from __future__ import annotations

import argparse
import math
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402
from scipy.linalg import cholesky, toeplitz  # noqa: E402

import hrgjax as hg  # noqa: E402

ORDER = {"wpm": 0, "wfm": 1, "gm": 1, "ffm": 2, "rwfm": 2}  # sums from u to the phase
ONE_SIGMA = 0.6826894921370859


def gamma_frac(lags):
    """Autocovariance of ARFIMA(0, −½, 0) at 0 … lags − 1."""
    g = np.empty(lags)
    g[0] = 4.0 / math.pi
    for k in range(1, lags):
        g[k] = g[k - 1] * (k - 1.5) / (k + 0.5)
    return g


def gamma_gm(lags, sigma, tc):
    """Autocovariance of interval means of a Gauss–Markov rate (σ, T in samples)."""
    a = 1.0 / tc
    k = np.arange(1, lags)
    g = np.empty(lags)
    g[0] = 2 * sigma**2 * tc**2 * (a - 1 + math.exp(-a))
    g[1:] = sigma**2 * tc**2 * np.exp(-(k - 1) * a) * (1 - math.exp(-a)) ** 2
    return g


def gamma_u(comp, lags):
    """Autocovariance of the component's driving series u (phase, rate or rate increments)."""
    kind, s = comp[0], comp[1]
    if kind == "gm":
        return gamma_gm(lags, s, comp[2])
    if kind == "ffm":
        return s**2 * gamma_frac(lags)
    g = np.zeros(lags)
    g[0] = s**2
    return g


def _ffm_scale(avar_floor, m=64):
    return math.sqrt(avar_floor / truth([("ffm", 1.0)], "avar", m))


def filt(var, m):
    """The estimator's filter on the phase and its normalisation (σ² = E(c·x)²/norm)."""
    if var == "avar":
        c = np.zeros(2 * m + 1)
        c[[0, m, 2 * m]] = 1.0, -2.0, 1.0
        return c, 2.0 * m * m
    c = np.zeros(3 * m)
    for j in range(m):
        c[j] += 1.0
        c[j + m] -= 2.0
        c[j + 2 * m] += 1.0
    return c / m, 2.0 * m * m


def truth(comps, var, m):
    """Exact Allan ("avar") or modified Allan ("mvar") variance of the sum at factor m."""
    c, norm = filt(var, m)
    out = 0.0
    for comp in comps:
        cu = np.asarray(c, float)
        for _ in range(ORDER[comp[0]]):  # coefficients carried to the increments
            cu = np.cumsum(cu[::-1])[::-1][1:]
        r = np.correlate(cu, cu, mode="full")[cu.size - 1 :]
        g = gamma_u(comp, r.size)
        out += g[0] * r[0] + 2 * np.dot(g[1:], r[1:])
    return out / norm


def draw(rng, comps, n, count):
    """`count` records of n rate samples of the sum."""
    y = np.zeros((count, n))
    for comp in comps:
        kind, s = comp[0], comp[1]
        if kind == "wpm":
            y += np.diff(rng.normal(size=(count, n + 1)) * s, axis=1)
        elif kind == "wfm":
            y += rng.normal(size=(count, n)) * s
        elif kind == "gm":
            low = cholesky(toeplitz(gamma_gm(n, s, comp[2])), lower=True)
            y += rng.normal(size=(count, n)) @ low.T
        elif kind == "ffm":  # circulant embedding of the increments' ARFIMA autocovariance
            g = gamma_frac(n + 1)
            lam = np.sqrt(np.clip(np.fft.rfft(np.r_[g, g[-2:0:-1]]).real, 0, None) / (2 * n))
            w = rng.normal(size=(count, lam.size)) + 1j * rng.normal(size=(count, lam.size))
            w[:, [0, -1]] = rng.normal(size=(count, 2)) * math.sqrt(2)
            u = (np.fft.irfft(w * lam, n=2 * n) * n * math.sqrt(2))[:, :n]
            y += np.cumsum(u, axis=1) * s
        elif kind == "rwfm":
            y += np.cumsum(rng.normal(size=(count, n)), axis=1) * s
    return y


_ARW10 = 0.002 / 60 / math.sqrt(10)  # ARW's per-sample σ at 0.1 Hz [°/s]: the rate unit
MIXES = {
    "tvg3_10s": [("wpm", (1 / 3600 / 0.554) / 10 / _ARW10), ("wfm", 1.0),
                 ("gm", (0.003 / 3600) / _ARW10, 60.0)],
    "tvg3_1s": [("wpm", (1 / 3600 / 0.554) / (0.002 / 60)), ("wfm", 1.0),
                ("gm", (0.003 / 3600) / (0.002 / 60), 600.0)],
    "fog_100hz": [("wpm", (0.01 / 3600) / 0.01 / (0.002 / 60 / 0.1)), ("wfm", 1.0),
                  ("ffm", None)],
    "four_band": [("wpm", math.sqrt(4 / 3)), ("wfm", 1.0), ("ffm", None),
                  ("rwfm", math.sqrt(3 / (64 * 512)))],
}  # fmt: skip
"""Components (kind, σ[, T]) in units of the white rate noise's σ per sample."""


def mixture(name):
    comps = list(MIXES[name])
    floor = {"fog_100hz": (0.664 * 0.003 / 3600 / (0.002 / 60 / 0.1)) ** 2, "four_band": 1 / 64}
    return [(c[0], _ffm_scale(floor[name])) if c[0] == "ffm" else c for c in comps]


def run(name, kind, n, count, seed):
    comps = mixture(name)
    y = draw(np.random.default_rng(seed), comps, n, count)
    t0 = time.time()
    rows = [hg.allan.deviation(r, 1.0, kind=kind, taus="octave") for r in y]
    spent = time.time() - t0
    m = rows[0].m
    var = "mvar" if kind in ("mdev", "tdev", "mtotdev", "ttotdev") else "avar"
    true = np.sqrt([truth(comps, var, int(k)) for k in m])
    if kind in ("tdev", "ttotdev"):
        true = true * m / math.sqrt(3)
    dev = np.array([r.dev for r in rows])
    edf = np.array([r.edf for r in rows])
    lo, hi = np.array([r.dev_low for r in rows]), np.array([r.dev_high for r in rows])
    lo95 = dev * np.sqrt(edf / stats.chi2.ppf(0.975, edf))
    hi95 = dev * np.sqrt(edf / stats.chi2.ppf(0.025, edf))
    mixed = [getattr(r, "mixture", None) for r in rows]
    alpha = np.array([r.alpha for r in rows])
    print(f"\n{kind} {name}: {count} records of {n} samples, {spent / count * 1e3:.0f} ms each")
    print(f"{'m':>6} {'±1σ %':>6} {'95 %':>6} {'E[r]':>6} {'edf':>8} {'mixed':>6}  types read")
    for i, k in enumerate(m):
        c1 = np.mean((lo[:, i] <= true[i]) & (true[i] <= hi[:, i]))
        c95 = np.mean((lo95[:, i] <= true[i]) & (true[i] <= hi95[:, i]))
        share = "-" if mixed[0] is None else f"{np.mean([x[i] for x in mixed]):.2f}"
        a, cc = np.unique(alpha[:, i], return_counts=True)
        types = " ".join(f"{int(v)}:{c}" for v, c in zip(a, cc, strict=True))
        print(f"{int(k):6d} {100 * c1:6.1f} {100 * c95:6.1f} {np.mean((dev[:, i] / true[i]) ** 2):6.3f} "
              f"{np.median(edf[:, i]):8.1f} {share:>6}  {types}")  # fmt: skip


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mix", default="fog_100hz,four_band,tvg3_10s,tvg3_1s")
    ap.add_argument("--kinds", default="oadev,mtotdev")
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--samples", type=int, default=1024)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    for j, name in enumerate(args.mix.split(",")):
        for kind in args.kinds.split(","):
            run(name, kind, args.samples, args.n, args.seed + j)


if __name__ == "__main__":
    main()
