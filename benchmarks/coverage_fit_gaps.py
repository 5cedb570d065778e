"""Do fit_noise's σ and intervals cover the truth on records with gaps? Monte Carlo with known
truth.

Records of 4 000 samples at 1 Hz: white rate noise N = 1 plus a rate random walk K
(`--k`, default 0.003: σ_K ≈ K on this length, and 0.01), oadev on the octave grid, N and K
fitted. Four cases of the same records: gap-free; one sample missing (at n/3); a 30 % block
missing (40–70 % of the record); 1 % of the samples missing at random. For N and K: the share
of records whose truth lies within the 68.27 % interval (`low`, `high`) and within value ± σ,
the z-RMS of (value − truth)/σ, the records' scatter of the value over the median σ, and
fit_noise's `method`. Run against an older hrgjax (PYTHONPATH) the figures are its own
(before: a gapped record fell back to τ independent with EDF weights).

Usage: `.venv/bin/python benchmarks/coverage_fit_gaps.py [--n 200] [--k 0.003]
[--cases free,one,block,scatter]` (200 records: ≈ 10 s per case, ≈ 4 min for `scatter`,
whose ≈ 40 runs of distinct lengths each cost a covariance, on 2 busy cores).
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import hrgjax as hg  # noqa: E402

LENGTH = 4000
TERMS = ("angle_random_walk", "rate_random_walk")
CASES = ("free", "one", "block", "scatter")


def record(seed: int, k: float, case: str) -> np.ndarray:
    """One record of `LENGTH` rate samples (N = 1, rate random walk `k`), gaps per `case`."""
    rng = np.random.default_rng(1000 + seed)
    y = rng.normal(size=LENGTH) + np.cumsum(k * rng.normal(size=LENGTH))
    if case == "one":
        y[LENGTH // 3] = np.nan
    elif case == "block":
        y[int(0.4 * LENGTH) : int(0.7 * LENGTH)] = np.nan
    elif case == "scatter":
        y[rng.random(LENGTH) < 0.01] = np.nan
    return y


def run(n: int, k: float, case: str):
    """(records, terms, 4) of value, σ, low, high; the methods; seconds per record."""
    rows, methods = [], set()
    t0 = time.perf_counter()
    for s in range(n):
        fit = hg.allan.fit_noise(hg.allan.deviation(record(s, k, case), 1.0), terms=TERMS)
        methods.add(fit.method.split(":")[0])
        rows.append([(fit.value[t], fit.sigma[t], fit.low[t], fit.high[t]) for t in TERMS])
    return np.asarray(rows), methods, (time.perf_counter() - t0) / n


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="records per case (200)")
    ap.add_argument("--k", type=float, default=0.003, help="rate random walk K (0.003)")
    ap.add_argument("--cases", default=",".join(CASES))
    args = ap.parse_args(argv)
    from _common import machine, report

    print(f"coverage_fit_gaps.py on {machine()}: {args.n} records of {LENGTH} s per case, "
          f"N = 1, K = {args.k:g}; binomial SE of a 68 % share "
          f"{np.sqrt(0.68 * 0.32 / args.n):.3f}")  # fmt: skip
    print(f"{'case':>8} {'term':>18} {'68% held':>9} {'±1σ':>6} {'z-RMS':>6} "
          f"{'scatter/σ':>10}  method, s/record")  # fmt: skip
    for case in args.cases.split(","):
        rows, methods, per = run(args.n, args.k, case)
        for i, (t, truth) in enumerate(zip(TERMS, (1.0, args.k), strict=True)):
            value, sigma, low, high = rows[:, i].T
            z = (value - truth) / np.maximum(sigma, 1e-300)
            held = float(np.mean((low <= truth) & (truth <= high)))
            print(f"{case:>8} {t:>18} {100 * held:8.1f}% {100 * np.mean(np.abs(z) < 1):5.1f}% "
                  f"{np.sqrt(np.mean(z**2)):6.2f} {np.std(value) / np.median(sigma):10.2f}  "
                  f"{sorted(methods)}, {per:.2f}")  # fmt: skip
            report(f"fit_noise {t} 68 % interval held, {case}, K {args.k:g}", 100 * held, "%",
                   target="68 ± 7 %")  # fmt: skip


if __name__ == "__main__":
    main()
