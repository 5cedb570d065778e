"""Do mtotdev's bias correction and ±1σ interval hold, at every octave τ from τ₀ to T/3?

Monte Carlo with exact truth: records of N rate samples at 1 Hz (N + 1 phase points) of one
discrete power-law noise, `hg.allan.deviation(y, 1.0, "mtotdev", "octave")` on each, its
deviation² against the true modified Allan variance Mod σ²(τ), computed from the noise's
autocovariance (Σ over lags of the rate's autocovariance times the filter's own):

- `wpm` white angle noise (α = 2), `fpm` flicker angle noise (α = 1: the rate ARFIMA(0, −½,
  0), exact by circulant embedding), `wfm` white rate noise (0), `ffm` flicker rate noise
  (−1: the rate's increments ARFIMA(0, −½, 0)), `rwfm` rate random walk (−2);
- `mix`: a gyro's quantisation (white angle), ARW (white rate) and RRW, the first two
  crossing at m = 16 and the last two at m = N/16.

Per τ: E[dev²]/Mod σ² (1 when the bias correction is right), the share of records whose
±1σ interval holds the truth (68 %), the median EDF and the noise types read.
Run against an older hrgjax with PYTHONPATH=... for its figures.

`--exact N`: the raw estimator's exact E[Mod Totvar]/Mod σ² and exact EDF (tr AΣ)²/tr (AΣ)²
of its quadratic form A over N phase points (dense, independent of `hrgjax.allan.total`),
against `mtotvar_bias` and `edf_mtotdev`, at octave m; N ≤ 2 049 (O(N³)).

`--bias-table M`: `mtotvar_bias`'s stored table (`_BIAS_TABLE` in `hrgjax.allan.total`,
α = 2 … −2, m = 1 … 128) printed as source from `_bias` (O(m² log m) by FFT), its largest
difference from the stored one, and every entry at m ≤ M against the dense form here
(`run_form`, `covariance`: O(m³); M = 128 ≈ 1 min).

`--rho N`: `hrgjax.allan.mixture`'s ρᵢⱼ tables (`MTOTDEV_RHO_M`, `MTOTDEV_RHO`: the cross
terms of Var Mod Totvar between white angle, white rate, flicker rate and random-walk rate
noise) printed as source from the dense forms over N phase points, and the stored ones'
largest difference (N = 385 ≈ 15 s).

Usage: `.venv/bin/python benchmarks/coverage_mtotdev.py [--n 200] [--samples 1024]
[--noises wpm,fpm,wfm,ffm,rwfm,mix] [--seed 1] [--rule hrgjax|stable32] [--kind mtotdev]`
(200 records of 1 024 samples per noise ≈ 20 s on 2 shared cores; `--exact 1025` ≈ 10 s).
"""

from __future__ import annotations

import argparse
import math
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import hrgjax as hg  # noqa: E402

ALPHA = {"wpm": 2, "fpm": 1, "wfm": 0, "ffm": -1, "rwfm": -2}
ORDER = {"wpm": 0, "fpm": 1, "wfm": 1, "ffm": 2, "rwfm": 2}  # running sums to the phase


def gamma(noise, lags):
    """Autocovariance of the driving sequence u (white, or ARFIMA(0, −½, 0)) at 0 … lags−1."""
    g = np.zeros(lags)
    if noise in ("fpm", "ffm"):
        g[0] = 4.0 / math.pi
        for k in range(1, lags):
            g[k] = g[k - 1] * (k - 1.5) / (k + 0.5)
    else:
        g[0] = 1.0
    return g


def draw(rng, noise, n):
    """n rate samples (n + 1 phase points) of one noise; x = u summed ORDER times."""
    p = ORDER[noise]
    size = n + 1 if p == 0 else n
    if noise in ("fpm", "ffm"):  # circulant embedding of the ARFIMA autocovariance
        g = gamma(noise, size + 1)
        lam = np.sqrt(np.clip(np.fft.rfft(np.r_[g, g[-2:0:-1]]).real, 0, None) / (2 * size))
        w = rng.normal(size=lam.size) + 1j * rng.normal(size=lam.size)
        w[[0, -1]] = rng.normal(size=2) * math.sqrt(2)
        u = (np.fft.irfft(w * lam, n=2 * size) * size * math.sqrt(2))[:size]
    else:
        u = rng.normal(size=size)
    if p == 2:
        u = np.cumsum(u)  # the rate
    return np.diff(u) if p == 0 else u


def mod_sigma2(noise, m, scale=1.0):
    """Exact Mod σ² at factor m: the modified second difference's weights carried to u."""
    c = np.zeros(3 * m)
    for j in range(m):
        c[j] += 1.0
        c[j + m] -= 2.0
        c[j + 2 * m] += 1.0
    c /= m
    for _ in range(ORDER[noise]):
        c = np.cumsum(c[::-1])[::-1][1:]
    r = np.correlate(c, c, "full")[c.size - 1 :]
    g = gamma(noise, r.size)
    return scale**2 * (g[0] * r[0] + 2 * np.dot(g[1:], r[1:])) / (2.0 * m * m)


def mix(n):
    """(noise, scale) terms of the gyro mixture over n rate samples."""
    q, arw, rrw = math.sqrt(16.0 / 3.0), 1.0, math.sqrt(3.0) * 16.0 / n
    return (("wpm", q), ("wfm", arw), ("rwfm", rrw))


def covariance(noise, size):
    """A generalised covariance of `size` phase points (good for forms that drop a line)."""
    p = ORDER[noise]
    nu = size if p == 0 else size - 1
    g = gamma(noise, nu)
    cov = g[np.abs(np.subtract.outer(np.arange(nu), np.arange(nu)))]
    if p == 0:
        return cov
    step = np.tril(np.ones((size, nu)), -1)
    if p == 2:
        step = step @ np.tril(np.ones((nu, nu)))
    return step @ cov @ step.T


def run_form(m):
    """One run's 6m reflected second differences as rows over its 3m points, built from SP
    1065 eq. 27's steps (detrend by the halves' means, reflect, average, difference)."""
    size, half = 3 * m, 3 * m // 2
    dist = (size - 1) / 2 + 1 if size % 2 else size / 2
    rows = []
    for j in range(6 * m):
        w = np.zeros(size)
        for k, sgn in ((j, 1.0), (j + m, -2.0), (j + 2 * m, 1.0)):
            for e in range(k, k + m):  # extended index e → run index
                w[size - 1 - e if e < size else e - size if e < 2 * size else 3 * size - 1 - e] += (
                    sgn / m
                )
        # detrending: x_l − l·s, s = (mean of last half − mean of first half)/dist
        moment = np.sum(w * np.arange(size)) / dist
        w[:half] += moment / half
        w[size - half :] -= moment / half
        rows.append(w)
    return np.asarray(rows)


def exact(n):
    from hrgjax.allan.total import edf_mtotdev, mtotvar_bias

    ms = [2**k for k in range(20) if 3 * 2**k <= n]
    covs = {noise: covariance(noise, n) for noise in ALPHA}
    print(f"N = {n} phase points: m, N/m, exact E[Mod Totvar]/Mod σ² (mtotvar_bias), "
          "exact EDF (edf_mtotdev; Table 8 under stable32)")  # fmt: skip
    for m in ms:
        rows, form = dense_form(m, n)
        line = []
        for noise, alpha in ALPHA.items():
            run = covariance(noise, 3 * m)
            var = np.sum((rows @ run) * rows, axis=1)
            fs = form @ covs[noise]
            edf = np.trace(fs) ** 2 / np.sum(fs * fs.T)
            line.append(f"{noise} {np.mean(var) / var[3 * m]:.4f} ({mtotvar_bias(alpha, m):.4f}) "
                        f"{edf:7.2f} ({edf_mtotdev(alpha, m, n):7.2f}; "
                        f"{edf_mtotdev(alpha, m, n, 'stable32'):7.2f})")  # fmt: skip
        print(f"  {m:5d} {n / m:7.2f}  " + " | ".join(line), flush=True)


def bias_table(upto):
    from hrgjax.allan.total import _BIAS_TABLE, BIAS_EXACT_TO, _bias

    t0 = time.time()
    table = {a: [_bias(a, m) for m in range(1, BIAS_EXACT_TO + 1)] for a in ALPHA.values()}
    print(f"# _bias at m = 1 … {BIAS_EXACT_TO}: {time.time() - t0:.1f} s")
    print("# fmt: off\n_BIAS_TABLE = {")
    for a, row in table.items():
        print(f"    {a}: (")
        for i in range(0, len(row), 7):
            print("        " + " ".join(f"{v:.9f}," for v in row[i : i + 7]))
        print("    ),")
    print("}\n# fmt: on")
    stored = max(abs(v - w) for a in table for v, w in zip(table[a], _BIAS_TABLE[a], strict=True))
    print(f"# largest |_bias − stored|: {stored:.1e} (9 decimals: ≤ 5e-10)")
    worst = 0.0
    t0 = time.time()
    for m in range(1, upto + 1):
        rows = run_form(m)
        for noise, alpha in ALPHA.items():
            var = np.sum((rows @ covariance(noise, 3 * m)) * rows, axis=1)
            worst = max(worst, abs(table[alpha][m - 1] / (np.mean(var) / var[3 * m]) - 1.0))
    print(f"# largest relative difference from the dense form, m ≤ {upto}: {worst:.1e} "
          f"({time.time() - t0:.0f} s)")  # fmt: skip


RHO_TYPES = ("wpm", "wfm", "ffm", "rwfm")  # the IEEE 952 terms' types (α = 2, 0, −1, −2)


def dense_form(m, n):
    """`(rows, A)`: one 3m-point run's form (`run_form`) and the raw Mod Totvar's dense
    quadratic form over n phase points, the run's summed at every start."""
    rows = run_form(m)
    a = rows.T @ rows
    form = np.zeros((n, n))
    for i in range(n - 3 * m + 1):
        form[i : i + 3 * m, i : i + 3 * m] += a
    return rows, form


def rho_rows(n, ms):
    """{m: ρ of each pair of RHO_TYPES}: tr(AΣᵢAΣⱼ)/√(tr(AΣᵢ)² tr(AΣⱼ)²) of the raw estimator's
    dense form A over n phase points, pairs in the order (0, 1), (0, 2), (0, 3), (1, 2), …"""
    covs = [covariance(noise, n) for noise in RHO_TYPES]
    out = {}
    for m in ms:
        _, form = dense_form(m, n)
        fs = [form @ c for c in covs]
        v = np.array([[np.sum(p * q.T) for q in fs] for p in fs])
        rho = v / np.sqrt(np.outer(np.diag(v), np.diag(v)))
        out[m] = rho[np.triu_indices(len(RHO_TYPES), 1)]
    return out


def rho_table(n):
    """`MTOTDEV_RHO_M` (m = 1, 2, 3) and `MTOTDEV_RHO` (m ≥ 4 by r = n/m) of
    hrgjax.allan.mixture printed as source, from the dense forms over n phase points
    (n = 385: ≈ 15 s), and the stored tables' largest difference from them."""
    from hrgjax.allan import mixture

    rs = mixture.MTOTDEV_RHO_R
    ms = [1, 2, 3] + [int(round(n / r)) for r in rs]
    rho = rho_rows(n, ms)
    print(f"# pairs (α): {RHO_TYPES} = 2, 0, −1, −2; n = {n} phase points")
    print("MTOTDEV_RHO_M = {")
    for m in (1, 2, 3):
        print(f"    {m}: (" + ", ".join(f"{v:.4f}" for v in rho[m]) + "),")
    print("}\nMTOTDEV_RHO = (")
    worst = 0.0
    for r, m in zip(rs, ms[3:], strict=True):
        print("    (" + ", ".join(f"{v:.4f}" for v in rho[m]) + f"),  # r = {r} (m = {m}, "
              f"n/m = {n / m:.2f})")  # fmt: skip
    print(")")
    for m in ms:
        stored = mixture.mtotdev_rho(m, n)
        worst = max(worst, float(np.max(np.abs(stored[np.triu_indices(4, 1)] - rho[m]))))
    print(f"# largest |stored − dense| at these m: {worst:.1e}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--samples", type=int, default=1024)
    ap.add_argument("--noises", default="wpm,fpm,wfm,ffm,rwfm,mix")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--rule", default="hrgjax")
    ap.add_argument("--kind", default="mtotdev", help="mtotdev, or mdev for comparison")
    ap.add_argument("--exact", type=int, default=0, metavar="N")
    ap.add_argument("--bias-table", type=int, default=0, metavar="M")
    ap.add_argument("--rho", type=int, default=0, metavar="N")
    a = ap.parse_args()
    if a.rho:
        rho_table(a.rho)
        return
    if a.bias_table:
        bias_table(a.bias_table)
        return
    if a.exact:
        exact(a.exact)
        return
    for noise in a.noises.split(","):
        rng = np.random.default_rng(a.seed)
        t0 = time.time()
        ratio, hit, alphas, edfs = [], [], [], []
        for _ in range(a.n):
            if noise == "mix":
                y = sum(s * draw(rng, nz, a.samples) for nz, s in mix(a.samples))
            else:
                y = draw(rng, noise, a.samples)
            r = hg.allan.deviation(y, 1.0, a.kind, "octave", noise_rule=a.rule)
            terms = mix(a.samples) if noise == "mix" else ((noise, 1.0),)
            s2 = np.asarray([sum(mod_sigma2(nz, int(k), s) for nz, s in terms) for k in r.m])
            ratio.append(r.dev**2 / s2)
            hit.append((r.dev_low**2 <= s2) & (s2 <= r.dev_high**2))
            alphas.append(r.alpha)
            edfs.append(r.edf)
        ratio, hit, alphas, edfs = map(np.asarray, (ratio, hit, alphas, edfs))
        print(f"== {noise}, {a.n} records of {a.samples} s, {a.kind}, rule {a.rule} "
              f"({time.time() - t0:.0f} s)")  # fmt: skip
        print("      m   E[dev²]/σ²  ±1σ holds  median EDF  α read (count)")
        for j, m in enumerate(r.m):
            kinds, counts = np.unique(alphas[:, j], return_counts=True)
            read = dict(zip(kinds.astype(int).tolist(), counts.tolist(), strict=True))
            se = ratio[:, j].std() / math.sqrt(a.n)
            print(f"  {int(m):5d}  {ratio[:, j].mean():6.3f}±{se:.3f}  {hit[:, j].mean() * 100:6.1f} %"
                  f"  {np.median(edfs[:, j]):9.1f}   {read}")  # fmt: skip


if __name__ == "__main__":
    main()
