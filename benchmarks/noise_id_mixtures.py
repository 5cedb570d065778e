"""Noise identification and the oadev ±1σ interval on mixtures and non-power-law records
(docs/allan.md, "noise identification"; benchmarks/README.md, `noise_id_table.py`).

Records of N rate samples built by FFT shaping (each component a white sequence of 4N
points whose spectrum is multiplied by f^(α/2), a random N-point window kept), so the
overlapping Allan variance's expectation at every factor m is exact:
E[σ²(m)] = Σ_k g(f_k)² |H_m(f_k)|² / (2m²L), H_m the second difference of m-sums. Per
octave m: how often `hg.allan.noise_id` reads each α, and how often the ±1σ interval from
Greenhall's EDF at the α read holds the true deviation (nominal 68.3 %); `--fixed` adds
the coverage with each α imposed.

`--comp` is a JSON list of [α, Allan variance at m = 1]; with two components `--cross M`
rescales the second to equal the first at m = M. `--sine A,P` adds a rate sine (amplitude
A, period P samples, random phase), `--drift D` a linear rate drift per sample, `--lp T`
a first-order low-pass of T samples on every component. The review of 4bd4989 used:

    .venv/bin/python benchmarks/noise_id_mixtures.py --R 400 --comp '[[2,1],[0,1]]' \
        --cross 1024 --seed 32          # white angle + white rate noise crossing at T/4
    ... --comp '[[2,1],[0,1]]' --cross 512 --seed 7
    ... --n 16384 --R 300 --comp '[[2,1],[0,1]]' --cross 2048 --seed 31
    ... --comp '[[0,1]]' --sine 0.3,200 --seed 5
    ... --comp '[[1,1]]' --seed 3      # pure flicker angle noise (the rule's cost)

For the code before a change, run it with `PYTHONPATH=` an archived tree
(`git archive <commit> hrgjax | tar -x -C <dir>`). A few minutes at 400 records of 4 096
samples on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import hrgjax as hg  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=4096, help="rate samples per record")
    ap.add_argument("--R", type=int, default=200, help="records")
    ap.add_argument("--comp", default="[[0, 1.0]]", help="JSON [[alpha, avar at m=1], ...]")
    ap.add_argument("--cross", type=float, default=None, help="two components cross at this m")
    ap.add_argument("--drift", type=float, default=0.0, help="rate drift per sample")
    ap.add_argument("--sine", default=None, help="amplitude,period_samples")
    ap.add_argument("--lp", type=float, default=0.0, help="low-pass time constant [samples]")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--fixed", action="store_true", help="also each α imposed")
    a = ap.parse_args(argv)
    n, big = a.n, 4 * a.n
    ms = 2 ** np.arange(int(np.log2(n // 4)) + 1)
    k = np.arange(big // 2 + 1)
    f = k / big
    fs = f.copy()
    fs[0] = fs[1]

    def gain(alpha):
        g = fs ** (alpha / 2.0)
        g[0] = 0.0
        if a.lp:
            q = np.exp(-1.0 / a.lp)
            g = g * (1 - q) / np.abs(1 - q * np.exp(-2j * np.pi * f))
        return g

    weights = np.full(k.size, 2.0)  # the one-sided spectrum's bins, counted twice
    weights[0] = weights[-1] = 1.0

    def avar_unit(alpha, m):
        with np.errstate(divide="ignore", invalid="ignore"):
            h2 = np.where(k == 0, 0.0, 4 * np.sin(np.pi * f * m) ** 4 / np.sin(np.pi * f) ** 2)
        return float(np.sum(weights * gain(alpha) ** 2 * h2) / big / (2 * m * m))

    comp = json.loads(a.comp)
    scales = [lev / avar_unit(al, 1) for al, lev in comp]
    if a.cross and len(comp) == 2:
        mc = int(a.cross)
        scales[1] = scales[0] * avar_unit(comp[0][0], mc) / avar_unit(comp[1][0], mc)
    truth = np.array([sum(s * avar_unit(al, int(m)) for s, (al, _) in zip(scales, comp, strict=True))
                      for m in ms])  # fmt: skip
    if a.drift:
        truth += a.drift**2 * ms.astype(float) ** 2 / 2
    if a.sine:
        amp, period = map(float, a.sine.split(","))
        f0 = 1 / period
        truth += (
            (amp * amp / 2)
            * 4
            * np.sin(np.pi * f0 * ms) ** 4
            / np.sin(np.pi * f0) ** 2
            / (2 * ms.astype(float) ** 2)
        )
    rng = np.random.default_rng(a.seed)

    def record():
        y = np.zeros(n)
        for s, (al, _) in zip(scales, comp, strict=True):
            w = np.fft.rfft(rng.normal(size=big)) * gain(al)
            start = rng.integers(0, big - n + 1)
            y += np.sqrt(s) * np.fft.irfft(w, big)[start : start + n]
        t = np.arange(n)
        if a.drift:
            y += a.drift * t
        if a.sine:
            y += amp * np.sin(2 * np.pi * t / period + rng.uniform(0, 2 * np.pi))
        return y

    alphas, devs = [], []
    t0 = time.perf_counter()
    for _ in range(a.R):
        y = record()
        x = np.concatenate([[0.0], np.cumsum(y - y.mean())])
        devs.append([np.sqrt(np.mean((x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]) ** 2) / (2.0 * m * m))
                     for m in ms])  # fmt: skip
        alphas.append(hg.allan.noise_id(x, ms))
    alphas, devs = np.array(alphas), np.array(devs)

    def cover(al):
        out = []
        for j, m in enumerate(ms):
            edf = np.array([hg.allan.edf_greenhall(int(max(q, -2)), 2, int(m), n + 1, True, False)
                            for q in al[:, j]])  # fmt: skip
            lo, hi = hg.allan.confidence_interval(devs[:, j], edf)
            out.append(np.mean((lo <= np.sqrt(truth[j])) & (np.sqrt(truth[j]) <= hi)))
        return np.array(out)

    got = cover(alphas)
    fixed = {q: cover(np.full(alphas.shape, q)) for q in (2, 1, 0, -1, -2)} if a.fixed else {}
    print(f"N = {n}, {a.R} records, comp {comp}, cross {a.cross}, drift {a.drift}, sine "
          f"{a.sine}, lp {a.lp}, seed {a.seed} ({time.perf_counter() - t0:.0f} s)")  # fmt: skip
    print("     m   records read α = 2 1 0 −1 −2   ±1σ holds" + ("   α imposed 2 1 0 −1 −2" if
                                                               fixed else ""))  # fmt: skip
    for j, m in enumerate(ms):
        hist = " ".join(f"{int(np.sum(alphas[:, j] == q)):4d}" for q in (2, 1, 0, -1, -2))
        line = f"{m:6d}   {hist}      {got[j]:.2f}"
        if fixed:
            line += "      " + " ".join(f"{fixed[q][j]:.2f}" for q in (2, 1, 0, -1, -2))
        print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
