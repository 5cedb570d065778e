"""The constant that alone changes a paired test's verdict: `constant_resolution` against
scipy's `ttest_rel` (pure numpy, ≈ 20 s on 2 cores).

Per-run residuals after each compensator's own offset, drawn here: static runs (w = 1) and
rotation runs' end-of-run angles (w = T/3600 [°] per °/h, T uniform in 60–300 s) that keep
a mean rate residual m [°/h] of the rotation runs (0.025 °/h scatter). For each case:

- `closed`: 2 t s_we / (sqrt(n) mean(w²)), the static closed form weighted by w (what
  `constant_resolution` returned before 2026-12; exact only for equal zero-mean residuals
  on equal static runs);
- `R(+)`, `R(−)`: `constant_resolution(..., difference=±1)`;
- `scipy(+)`, `scipy(−)`: the smallest c at which `ttest_rel` of the shifted pair (A + c w
  or B − c w, the smaller; 0: any c does) gives another verdict than unshifted: a scan of the verdict on a
  geometric grid, then brentq on the p-value.

Rows "self": the pair is one compensator with itself (its own test: e² against the shifted
e²); rows "pair": B another compensator (scatter 0.04 °/h, m of the other sign).

`python benchmarks/constant_resolution.py [--seed 7]`
"""

import argparse

import numpy as np
from scipy import optimize, stats

from hrgjax.calibration.paired import constant_resolution


def first_change(pair, level=0.95):
    """Smallest c > 0 at which ttest_rel(*pair(c)) gives another verdict than at c = 0."""

    def verdict(c):
        r = stats.ttest_rel(*pair(c))
        return int(np.sign(r.statistic)) if r.pvalue < 1.0 - level else 0

    grid = np.geomspace(1e-8, 10.0, 300)
    hit = np.flatnonzero([verdict(c) != verdict(0.0) for c in grid])
    if not hit.size:
        return np.inf
    if hit[0] == 0:
        return 0.0
    f = lambda c: stats.ttest_rel(*pair(c)).pvalue - (1.0 - level)
    return optimize.brentq(f, grid[hit[0] - 1], grid[hit[0]], xtol=1e-15, rtol=1e-13)


def charged(ea, eb, w, s):
    return min(first_change(lambda c: ((ea + s * c * w) ** 2, eb**2)),
               first_change(lambda c: (ea**2, (eb - s * c * w) ** 2)))  # fmt: skip


def closed(e, w):
    n = e.size
    return 2 * stats.t.ppf(0.975, n - 1) * np.std(w * e, ddof=1) / (np.sqrt(n) * np.mean(w**2))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    print(f"{'case':34s} {'closed':>8s} {'R(+)':>8s} {'scipy(+)':>8s} {'R(-)':>8s} "
          f"{'scipy(-)':>8s}  [°/h]")  # fmt: skip
    worst = 0.0
    for n in (10, 30):
        cases = []
        s = rng.normal(0, 0.025, n)
        cases.append((f"n={n} static, self", s - s.mean(), None, np.ones(n)))
        w = rng.uniform(60, 300, n) / 3600
        for m in (0.0, 0.005, 0.01):
            x = rng.normal(0, 0.025, n)
            e = w * (x - x.mean() + m)
            cases.append((f"n={n} angle m={m:g}, self", e, None, w))
            y = rng.normal(0, 0.04, n)
            cases.append((f"n={n} angle m={m:g}, pair", e, w * (y - y.mean() - m / 2), w))
        for name, ea, eb, w in cases:
            eb = ea if eb is None else eb
            got = [constant_resolution(ea, eb, w, difference=s) for s in (1.0, -1.0)]
            want = [charged(ea, eb, w, s) for s in (1.0, -1.0)]
            worst = max(
                worst,
                *(
                    abs(g - t) / max(t, 1e-300) if g != t else 0.0
                    for g, t in zip(got, want, strict=True)
                ),
            )
            print(f"{name:34s} {closed(ea, w):8.5f} {got[0]:8.5f} {want[0]:8.5f} "
                  f"{got[1]:8.5f} {want[1]:8.5f}")  # fmt: skip
    print(f"largest relative difference R vs scipy: {worst:.1e}")


if __name__ == "__main__":
    main()
