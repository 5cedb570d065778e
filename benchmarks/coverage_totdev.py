"""Does totdev's bias correction and interval hold at every τ up to the record's length?

Monte Carlo with exact truth: records of N rate samples at 1 Hz (N + 1 phase points, T = N s)
of one noise, `hg.allan.deviation(y, 1.0, "totdev", "octave")` on each, its deviation² against
the true Allan variance σ²(τ) at every octave τ up to T:

- `wpm`: white angle (phase) noise, phase points independent, σ_x = 1: σ² = 3/τ² (exact);
- `fpm`: flicker angle noise, the phase a sum of 20 first-order Gauss–Markov terms with
  correlation times 0.5·2^k s (equal variances; stationary, covariance R(k) known):
  σ² = (6R(0) − 8R(m) + 2R(2m))/(2τ²);
- `ffm`: flicker rate noise (bias instability), the rate such a sum: σ² from the rate's
  autocovariance, Σ (c·y)² over the Allan weights;
- `rwfm`: rate random walk, K = 0.01: σ² = E[(c·y)²] from the walk's increments;
- `wfm`: white rate noise (angle random walk), σ_y = 1: σ² = 1/τ (the commonest gyro noise);
- `wrwM` (e.g. `wrw128`): white rate noise (σ_y = 1) plus a rate random walk whose Allan
  variance crosses it at m = M (K = √3/M): σ² = 1/τ + the walk's (a gyro's angle random walk
  and rate random walk);
- `mixM` (e.g. `mix16`): white rate noise (σ_y = 1) plus white angle noise whose Allan
  variance crosses it at m = M (σ_x = √(M/3)): σ² = 1/τ + M/τ² (a quantised gyro's angle
  noise and its angle random walk).

Per τ: E[σ̂²]/σ² (mean over records), the share of records whose ±1σ interval holds σ, the
median width dev_high/dev_low, the z-RMS of z = Φ⁻¹(χ²_edf(edf·σ̂²/σ²)) (1 when the EDF is right), and the noise types read;
for every noise but `wpm`, also the records read as white angle noise (α = 2, whose exact
EDF is the largest): their count, ±1σ share and z-RMS.
Run against an older hrgjax (PYTHONPATH=...) for its figures.

Usage: `.venv/bin/python benchmarks/coverage_totdev.py [--n 400] [--samples 512]
[--noises wpm,fpm,ffm,rwfm,wfm,wrw128] [--seed 1] [--kind totdev|oadev]` (400 records of 512 samples per noise on 2
shared cores, ≈ 8 s; `--exact` prints `totvar_bias` and the EDF of white angle noise, and
flicker angle noise's exact bias when its band stops below Nyquist, no Monte Carlo).
"""

from __future__ import annotations

import argparse
import math
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import hrgjax as hg  # noqa: E402

PHI = np.exp(-1.0 / (0.5 * 2.0 ** np.arange(20)))  # Gauss–Markov terms of the flicker noises
K = 0.01


def _gm_sum(rng, n):
    """A stationary sum of the Gauss–Markov terms (unit variance each), n samples."""
    out = np.zeros(n)
    for phi in PHI:
        e = rng.normal(size=n) * math.sqrt(1 - phi * phi)
        e[0] = rng.normal()
        v = np.empty(n)
        acc = 0.0
        for i in range(n):  # lfilter without scipy
            acc = phi * acc + e[i]
            v[i] = acc
        out += v
    return out


def _cov(k):
    return np.sum(PHI[:, None] ** np.abs(np.asarray(k))[None, :], axis=0)


def draw(rng, noise, n):
    if noise == "wpm":
        return np.diff(rng.normal(size=n + 1))
    if noise == "fpm":
        return np.diff(_gm_sum(rng, n + 1))
    if noise == "ffm":
        return _gm_sum(rng, n)
    if noise.startswith("mix"):
        return rng.normal(size=n) + np.diff(
            math.sqrt(float(noise[3:]) / 3) * rng.normal(size=n + 1)
        )
    if noise == "wfm":
        return rng.normal(size=n)
    if noise.startswith("wrw"):
        return rng.normal(size=n) + math.sqrt(3.0) / float(noise[3:]) * np.cumsum(
            rng.normal(size=n)
        )
    return K * np.cumsum(rng.normal(size=n))  # rwfm


def truth(noise, m):
    if noise == "wpm":
        return 3.0 / m**2
    if noise == "fpm":
        r = _cov([0, m, 2 * m])
        return float(6 * r[0] - 8 * r[1] + 2 * r[2]) / (2.0 * m * m)
    if noise.startswith("mix"):
        return 1.0 / m + float(noise[3:]) / m**2
    if noise == "wfm":
        return 1.0 / m
    c = np.r_[-np.ones(m), np.ones(m)]
    if noise == "rwfm" or noise.startswith("wrw"):
        s = np.cumsum(c[::-1])[::-1]
        k = K if noise == "rwfm" else math.sqrt(3.0) / float(noise[3:])
        return k**2 * float(np.sum(s**2)) / (2.0 * m * m) + (noise != "rwfm") / m
    a = np.correlate(c, c, "full")
    lag = np.arange(-(c.size - 1), c.size)
    return float(np.sum(_cov(lag) * a)) / (2.0 * m * m)


def totvar_rows(n, m):
    """SP 1065 eq. 25's n − 2 reflected second differences as dense rows over the phase."""
    e = np.eye(n)

    def ext(k):
        return e[k] if 0 <= k < n else 2 * e[0] - e[-k] if k < 0 else 2 * e[-1] - e[2 * n - 2 - k]

    return np.array([ext(i - m) - 2 * ext(i) + ext(i + m) for i in range(1, n - 1)])


def band_limited(n=513):
    """Flicker angle noise's E[Totvar]/σ² when its 1/f phase PSD stops at f_h below the
    Nyquist 1/(2τ₀) that `totvar_bias` assumes (a sensor's low-pass): exact, from the
    covariance of a circulant 1/f phase of 64n points, at τ = T/2 and T."""
    size = 64 * n
    k = np.arange(1, size // 2 + 1)
    print(f"flicker angle noise band-limited to f_h, {n} phase points: exact E[Totvar]/σ² "
          "against totvar_bias(1, m, n)")  # fmt: skip
    for fh in (1 / 2, 1 / 8, 1 / 32):
        psd = np.where(k / size <= fh, size / k, 0.0)
        lags = np.arange(2 * n + 2)
        r = (psd[None, :] * np.cos(2 * np.pi * np.outer(lags, k) / size)).sum(1) * 2 / size
        cov = r[np.abs(np.subtract.outer(np.arange(n), np.arange(n)))]
        line = []
        for m in ((n - 1) // 2, n - 1):
            rows = totvar_rows(n, m)
            exact = np.sum((rows @ cov) * rows) / (n - 2) / (6 * r[0] - 8 * r[m] + 2 * r[2 * m])
            line.append(f"m = {m}: {exact:.3f} ({hg.allan.totvar_bias(1, m, n):.3f})")
        print(f"  f_h = 1/({1 / fh:.0f}τ₀): " + ", ".join(line))


def _white(noise, alpha, hit, z):
    """The records of one τ read as white angle noise, where that is not the truth."""
    sel = alpha == 2
    if noise == "wpm" or not sel.any():
        return ""
    return f"  | {sel.sum()}, {hit[sel].mean() * 100:.1f} %, {np.sqrt(np.mean(z[sel] ** 2)):.2f}"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=400)
    ap.add_argument("--samples", type=int, default=512)
    ap.add_argument("--noises", default="wpm,fpm,ffm,rwfm")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--exact", action="store_true")
    ap.add_argument("--kind", default="totdev", help="totdev, or oadev for comparison")
    a = ap.parse_args()
    if a.exact:
        for n in (201, 2049, 8193):
            print(f"white angle noise, {n} phase points: m, τ/T, E[Totvar]/σ², exact EDF, "
                  "flicker angle noise's E[Totvar]/σ²")  # fmt: skip
            for m in sorted({1, 16, (n - 1) // 8, (n - 1) // 4, (n - 1) // 2, n - 1}):
                bias, edf = hg.allan.totvar_white_phase(m, n)
                print(f"  {m:5d} {m / (n - 1):.3f} {bias:.4f} {edf:9.2f} "
                      f"{hg.allan.totvar_bias(1, m, n):.4f}")  # fmt: skip
        band_limited()
        return
    from statistics import NormalDist

    from hrgjax.allan.uncertainty import chi2_sf

    for noise in a.noises.split(","):
        rng = np.random.default_rng(a.seed)
        t0 = time.time()
        ratio, hit, zs, alphas, edfs, wide = [], [], [], [], [], []
        for _ in range(a.n):
            r = hg.allan.deviation(draw(rng, noise, a.samples), 1.0, a.kind, "octave")
            s2 = np.asarray([truth(noise, int(k)) for k in r.m])
            ratio.append(r.dev**2 / s2)
            hit.append((r.dev_low**2 <= s2) & (s2 <= r.dev_high**2))
            wide.append(r.dev_high / r.dev_low)
            p = [1 - chi2_sf(e * d * d / t, e) for e, d, t in zip(r.edf, r.dev, s2, strict=True)]
            zs.append([NormalDist().inv_cdf(min(max(q, 1e-12), 1 - 1e-12)) for q in p])
            alphas.append(r.alpha)
            edfs.append(r.edf)
        ratio, hit, zs, alphas, edfs, wide = map(np.asarray, (ratio, hit, zs, alphas, edfs, wide))
        print(f"== {noise}, {a.n} records of {a.samples} s ({time.time() - t0:.0f} s)")
        print(
            "      m   τ/T  E[σ̂²]/σ²  ±1σ holds  hi/lo  z-RMS  median EDF  α read (count)"
            + ("" if noise == "wpm" else "  | read α = 2: records, ±1σ, z-RMS")
        )
        for j, m in enumerate(r.m):
            kinds, counts = np.unique(alphas[:, j], return_counts=True)
            read = dict(zip(kinds.astype(int).tolist(), counts.tolist(), strict=True))
            print(
                f"  {int(m):5d} {m / a.samples:5.3f}  {ratio[:, j].mean():6.3f}   "
                f"{hit[:, j].mean() * 100:6.1f} %  {np.median(wide[:, j]):5.2f}  "
                f"{np.sqrt(np.mean(zs[:, j] ** 2)):5.2f}  "
                f"{np.median(edfs[:, j]):9.1f}   {read}"
                + _white(noise, alphas[:, j], hit[:, j], zs[:, j])
            )


if __name__ == "__main__":
    main()
