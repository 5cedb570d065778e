"""Flicker angle noise's totdev bias: O(1) per τ against the O(n) row sum it replaced.

`hg.allan.totvar_bias(1, m, n)` sums Totvar's rows over the flicker phase's structure
function D(k) = ln(πk) + γ. Until 2026-11-30 each row was summed (NumPy, O(n) per τ), so a
`taus="all"` totdev became quadratic in the record's length; now each range of rows of
one pattern is summed in closed form (lgamma differences, `hrgjax.allan.totvar`).

1. Per τ: the O(n) row sum (below, the 2ede8ce code, as the reference) against
   `totvar_bias(1, m, n)` at the same factors (each asked once: its cache does not answer),
   both timed; their largest relative difference.
2. `hg.allan.deviation(y, 1.0, "totdev", "all")` on a flicker angle noise record of
   `--samples` rate samples (FFT 1/f phase, seed 0), wall time; run it with
   `PYTHONPATH=` an archived tree for the code before.

Usage: `.venv/bin/python benchmarks/totvar_speed.py [--sizes 1025,16385,65537]
[--factors 40] [--samples 16384] [--noise flicker-angle|white-rate]` (`--samples 0` skips
part 2; `--noise white-rate` times the rate noises' span at τ ≥ T/8: `--sizes '' --samples
4096 --noise white-rate`).
"""

from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import hrgjax as hg  # noqa: E402

EULER_GAMMA = 0.5772156649015329


def structure(k):
    """ln(πk) + γ for k ≥ 1, 0 at k = 0."""
    k = np.asarray(k, dtype=float)
    return np.where(k > 0, np.log(np.pi * np.maximum(k, 1.0)) + EULER_GAMMA, 0.0)


def row_sum_bias(m: int, n: int) -> float:
    """E[Totvar]/σ²(τ) for flicker angle noise, row by row (O(n)): each reflected second
    difference's −½ Σ c_a c_b D(|a − b|), over the Allan variance's 4D(m) − D(2m)."""
    total = 0.0
    step = 1 << 16
    for start in range(1, n - 1, step):
        i = np.arange(start, min(start + step, n - 1))
        index, coef = [], []
        for k, c in ((i - m, 1.0), (i, -2.0), (i + m, 1.0)):  # reflected: 2x_end − x_mirror
            low, high = k < 0, k > n - 1
            inside = ~(low | high)
            index += [np.where(inside, k, np.where(low, -k, 2 * n - 2 - k)),
                      np.where(high, n - 1, 0)]  # fmt: skip
            coef += [np.where(inside, c, -c), np.where(low | high, 2 * c, 0.0)]
        for u in range(len(index)):
            for v in range(u + 1, len(index)):
                total -= float(np.sum(coef[u] * coef[v] * structure(np.abs(index[u] - index[v]))))
    return float(total / (n - 2) / (4 * structure(m) - structure(2 * m)))


def per_tau(sizes, count, rng):
    row_sum_bias(2, 5), hg.allan.totvar_bias(1, 2, 5)  # imports and first calls
    print("n phase points | factors | O(n) row sum, per τ | totvar_bias, per τ | ratio | "
          "max rel. diff")  # fmt: skip
    for n in sizes:
        ms = {1, 2, 3, n // 2 - 1, n // 2, n // 2 + 1, n - 2, n - 1}
        ms |= set(rng.integers(1, n, size=max(count - len(ms), 0)).tolist())
        ms = sorted(ms)
        t0 = time.perf_counter()
        ref = [row_sum_bias(m, n) for m in ms]
        t_ref = (time.perf_counter() - t0) / len(ms)
        t0 = time.perf_counter()
        got = [hg.allan.totvar_bias(1, m, n) for m in ms]
        t_new = (time.perf_counter() - t0) / len(ms)
        diff = max(abs(g / r - 1) for g, r in zip(got, ref, strict=True))
        print(f"{n:>14d} | {len(ms):7d} | {t_ref * 1e3:14.2f} ms | {t_new * 1e6:15.1f} µs | "
              f"{t_ref / t_new:6.0f}× | {diff:.1e}")  # fmt: skip


def all_grid(samples, noise="flicker-angle"):
    rng = np.random.default_rng(0)
    if noise == "white-rate":  # rate noises read by B1 at τ ≥ T/8: totdev's span there
        y = rng.normal(size=samples)
    else:
        size = 4 * samples
        f = np.fft.rfftfreq(size)
        psd = np.zeros_like(f)
        psd[1:] = 1 / f[1:]
        spec = np.sqrt(psd) * (rng.normal(size=f.size) + 1j * rng.normal(size=f.size))
        y = np.diff(np.fft.irfft(spec, size)[: samples + 1])  # flicker angle noise's rate
    hg.allan.deviation(y[:64], 1.0, "totdev", "all")  # compile the small case
    walls = []
    for _ in range(2):  # first call, then again (its EDFs cached)
        t0 = time.perf_counter()
        r = hg.allan.deviation(y, 1.0, "totdev", "all")
        walls.append(time.perf_counter() - t0)
    kinds, counts = np.unique(r.alpha, return_counts=True)
    read = dict(zip(kinds.astype(int).tolist(), counts.tolist(), strict=True))
    print(f"deviation(totdev, 'all'), {samples} samples of {noise} noise, {r.m.size} τ: "
          f"{walls[0]:.2f} s, again {walls[1]:.2f} s (α read: {read})")  # fmt: skip


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="1025,16385,65537")
    ap.add_argument("--factors", type=int, default=40)
    ap.add_argument("--samples", type=int, default=16384)
    ap.add_argument("--noise", default="flicker-angle", choices=("flicker-angle", "white-rate"))
    a = ap.parse_args()
    rng = np.random.default_rng(1)
    if a.sizes:
        per_tau([int(s) for s in a.sizes.split(",")], a.factors, rng)
    if a.samples > 0:
        all_grid(a.samples, a.noise)


if __name__ == "__main__":
    main()
