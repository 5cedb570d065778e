"""Do the Allan deviation's intervals cover the truth at long τ? Monte Carlo with known truth.

Records of white rate noise (angle random walk, N) plus rate random walk (K), 1 Hz, 20 000 s
(a gyro's overnight log), whose true overlapping Allan variance is N²/τ + K²τ/3. For each
record `hg.allan.deviation(y, 1 Hz, "oadev")` on its octave grid (m = 1 … 8 192); at every τ
the estimate is standardised through its own χ² law: with u = edf·σ̂²/σ² and p its χ²(edf)
probability, z = Φ⁻¹(p) is a standard normal when the EDF is right, and |z| < 1 exactly when
the ±1σ interval covers the truth. Three balances: the random walk overtaking the white rate
noise at τ = 300 s (the long τ are pure random walk) and at 2 000 s (white up to the last τ
the lag-1 autocorrelation can read, random walk beyond), and overtaking white angle
(readout) noise, σ_x per sample, at 1 000 s (true AVAR 3σ_x²/τ² + K²τ/3).

"before": the noise type of the last τ with ≥ 30 decimated points carried to every longer τ
(hrgjax until issue 46); "after": what `deviation` reports now (the B1 and R(n) ratios
beyond that reach, `hrgjax.allan.noise_id`). Same estimates, only the EDF differs.

Targets (issue 46): at the longest τ, 68 ± 8 % within ±1σ.

`--noise-rule stable32` puts Stable32's rule (B1 on the drift-removed rate down to 2
averages) in the "after" column instead.

Usage: `.venv/bin/python benchmarks/coverage_allan.py [--n 200] [--seed 0]
[--noise-rule hrgjax|stable32]` (200 records per balance: about 15 s on 2 cores).
"""

from __future__ import annotations

import argparse
import math
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import hrgjax as hg  # noqa: E402

LENGTH = 20_000  # samples at 1 Hz
WHITE = 1.0  # N: the white noise σ per 1-s sample [rate unit]
ANGLE_WHITE = 30.0  # σ_x: white angle (readout) noise per sample [rate unit × s]
BALANCES = (("rate", 300.0), ("rate", 2000.0), ("angle", 1000.0))
"""(the white noise, τ [s] where the random walk overtakes it)."""


def _carried(x, ms):
    """The noise type before issue 46: lag-1 autocorrelation where the decimated phase has
    ≥ 30 points, the last such α carried beyond."""
    out, last = [], None
    for m in ms:
        if x[:: int(m)].size >= hg.allan.ACF_POINTS:
            last = int(hg.allan.noise_id(x, [int(m)])[0])
        out.append(last)
    return np.asarray(out)


def _z(dev, truth, edf):
    from scipy import stats

    u = edf * (dev / truth) ** 2
    p = np.clip(stats.chi2.cdf(u, edf), 1e-12, 1 - 1e-12)
    return stats.norm.ppf(p)


def run(n: int, white: str, crossover: float, seed: int, noise_rule: str = "hrgjax"):
    """z (records, τ) before and after, the α identified, and the τ grid. `white`: "rate"
    (N²/τ) or "angle" (white phase noise, 3σ_x²/τ² at 1 Hz)."""
    rng = np.random.default_rng(seed)
    if white == "rate":
        k = math.sqrt(3.0) * WHITE / crossover
    else:
        k = 3.0 * ANGLE_WHITE / crossover**1.5
    before, after, alphas = [], [], []
    for _ in range(n):
        walk = k * np.cumsum(rng.normal(size=LENGTH))
        if white == "rate":
            y = WHITE * rng.normal(size=LENGTH) + walk
        else:
            y = ANGLE_WHITE * np.diff(rng.normal(size=LENGTH + 1)) + walk
        r = hg.allan.deviation(y, 1.0, kind="oadev", taus="octave", noise_rule=noise_rule)
        floor = WHITE**2 / r.taus if white == "rate" else 3 * ANGLE_WHITE**2 / r.taus**2
        truth = np.sqrt(floor + k**2 * r.taus / 3)
        x = np.concatenate([[0.0], np.cumsum(y)])
        old = _carried(x, r.m)
        edf_old = np.asarray([
            hg.allan.edf_greenhall(max(int(a), -2), 2, int(m), x.size, True, False)
            for a, m in zip(old, r.m, strict=True)
        ])  # fmt: skip
        before.append(_z(r.dev, truth, edf_old))
        after.append(_z(r.dev, truth, r.edf))
        alphas.append(r.alpha)
    return np.asarray(before), np.asarray(after), np.asarray(alphas), r.taus


def figures(z):
    return {
        "within_1sigma": float(np.mean(np.abs(z) < 1.0)),
        "within_2sigma": float(np.mean(np.abs(z) < 2.0)),
        "z_rms": float(np.sqrt(np.mean(z**2))),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="records per balance (200)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--noise-rule", default="hrgjax", choices=hg.allan.NOISE_RULES,
                    help="deviation's noise_rule for the 'after' column (hrgjax)")  # fmt: skip
    args = ap.parse_args(argv)
    from _common import machine, report

    print(f"coverage_allan.py on {machine()}: {args.n} records of {LENGTH} s per balance, "
          f"noise_rule={args.noise_rule!r}")  # fmt: skip
    t0 = time.perf_counter()
    for white, crossover in BALANCES:
        before, after, alphas, taus = run(args.n, white, crossover, args.seed, args.noise_rule)
        print(f"\nrate random walk overtakes white {white} noise at τ = {crossover:g} s")
        print(f"{'τ [s]':>7} {'±1σ before':>11} {'±1σ after':>10} {'±2σ after':>10} "
              f"{'z-RMS after':>12}  α after (share of records)")  # fmt: skip
        for i, t in enumerate(taus):
            if t < 256:
                continue
            b, a = figures(before[:, i]), figures(after[:, i])
            vals, counts = np.unique(alphas[:, i], return_counts=True)
            share = ", ".join(
                f"{v:+d}: {c / args.n:.0%}" for v, c in zip(vals, counts, strict=True)
            )
            print(f"{t:7.0f} {100 * b['within_1sigma']:10.0f}% {100 * a['within_1sigma']:9.0f}% "
                  f"{100 * a['within_2sigma']:9.0f}% {a['z_rms']:12.2f}  {share}")  # fmt: skip
        last_b, last_a = figures(before[:, -1]), figures(after[:, -1])
        report(f"Allan ±1σ coverage at τ = {taus[-1]:g} s, white {white}, crossover {crossover:g} s, before",
               100 * last_b["within_1sigma"], "%", target="68 ± 8 %")  # fmt: skip
        report(f"Allan ±1σ coverage at τ = {taus[-1]:g} s, white {white}, crossover {crossover:g} s, after ({args.noise_rule})",
               100 * last_a["within_1sigma"], "%", target="68 ± 8 %")  # fmt: skip
    print(f"\n{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
