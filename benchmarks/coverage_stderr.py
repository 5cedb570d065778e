"""Do the reduction's standard errors cover the truth? (audit of the batch-means σ)

`hg.calibration.static_drift(data)['stderr_dph']` and `reduce(data).stderr_dps` are batch
means with a trend removed: `batches − 2` degrees of freedom (3 by default), reported as
`dof`. Monte Carlo with known truth (drift 0 on static runs; the table rate on rotation
windows), through the public API, every row from the same draws:

- "as normal" (before): the standard error read as a normal 1σ — ±1σ, ±2σ (nominal 68.3 %,
  95.4 %) and the RMS of z = (value − truth)/σ (nominal 1);
- "as t(dof)" (after): the interval the reported `dof` gives, ±t_dof(0.841)·σ and
  ±t_dof(0.977)·σ (nominal 68.3 %, 95.4 %), and the RMS of z's normal score Φ⁻¹(F_t(z))
  (nominal 1); `t-RMS` is z-RMS's nominal under t, √(dof/(dof − 2)).

Cases: a pure angle random walk (60-s static runs at 10 Hz, where the module calls the size
right); the default gyro's noise (white angle 4.85·10⁻⁶ rad/sample + ARW 5.82·10⁻⁷ rad/√s in
pattern angle) on 300-s static runs at 10 Hz; and 3-s rotation windows (5 °/s) of the same
gyro, where white angle noise dominates and the errors are conservative. Each with the
default 5 batches and with 10.

Usage: `.venv/bin/python benchmarks/coverage_stderr.py [--n N]` (N static runs per case,
default 400; ≈ 30 s on the 2-core machine).
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

import hrgjax as hg  # noqa: E402
from hrgjax.data import MeasuredData  # noqa: E402
from hrgjax.units import K_E_NOMINAL  # noqa: E402

WHITE = 4.84813681109536e-06  # rad per sample, pattern angle (the default gyro)
ARW = 5.817764173314431e-07  # rad/√s
P1, P2 = stats.norm.cdf(1) - stats.norm.cdf(-1), stats.norm.cdf(2) - stats.norm.cdf(-2)


def _data(rng, runs, n, dt, white, walk, rate_dps=0.0):
    t = np.tile(np.arange(n) * dt, runs)
    ang = np.cumsum(rng.standard_normal((runs, n)) * walk * np.sqrt(dt), axis=1)
    ang = ang + white * rng.standard_normal((runs, n))
    table = rate_dps * t  # the table angle [°]; the wave turns by −k_e of it
    cols = {"time_s": t, "temperature_c": np.full(t.size, 25.0),
            "table_rate_dps": np.full(t.size, rate_dps), "run": np.repeat(np.arange(runs), n),
            "wave_angle_deg": np.degrees(ang.ravel()) - K_E_NOMINAL * table}  # fmt: skip
    if rate_dps:
        cols["table_angle_deg"] = table
    return MeasuredData(cols)


def _row(label, err, sigma, dof):
    z = err / sigma
    q1, q2 = stats.t.ppf(0.5 + P1 / 2, dof), stats.t.ppf(0.5 + P2 / 2, dof)
    score = stats.norm.ppf(np.clip(stats.t.cdf(z, dof), 1e-300, 1 - 1e-16))
    nominal = np.sqrt(np.mean(dof / (dof - 2.0))) if np.all(dof > 2) else np.inf
    print(f"| {label} | {len(z)} | {int(np.median(dof))} "
          f"| {np.mean(abs(z) < 1):.1%} | {np.mean(abs(z) < 2):.1%} | {np.sqrt(np.mean(z**2)):.2f} "
          f"| {nominal:.2f} | {np.mean(abs(z) < q1):.1%} | {np.mean(abs(z) < q2):.1%} "
          f"| {np.sqrt(np.mean(score**2)):.2f} |")  # fmt: skip


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=400, help="static runs per case")
    args = ap.parse_args()
    rng = np.random.default_rng(20261201)
    print("| case | windows | dof | as normal ±1σ | ±2σ | z-RMS | t-RMS "
          "| as t(dof) 68 % | 95 % | normal-score RMS |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    t0 = time.perf_counter()
    cases = (("pure ARW, 60-s static runs", 600, 0.1, 0.0, 1e-3 / np.sqrt(0.1)),
             ("default gyro, 300-s static runs", 3000, 0.1, WHITE, ARW))  # fmt: skip
    for name, n, dt, white, walk in cases:
        data = _data(rng, args.n, n, dt, white, walk)
        for b in (5, 10):
            d = hg.calibration.static_drift(data, batches=b)
            _row(f"{name}, static_drift(batches={b})", d["drift_dph"], d["stderr_dph"], d["dof"])
    data = _data(rng, max(args.n // 100, 1), 6000, 0.1, WHITE, ARW, rate_dps=5.0)
    for b in (5, 10):
        w = hg.calibration.reduce(data, batches=b)
        err = (w.rate_dps - w.table_rate_dps) * 3600.0
        _row(f"default gyro, 3-s rotation windows, reduce(batches={b})", err,
             w.stderr_dps * 3600.0, w.dof)  # fmt: skip
    print(
        f"\n({time.perf_counter() - t0:.0f} s; t(dof): P(|t|<1) = "
        f"{2 * stats.t.cdf(1, 3) - 1:.1%} at 3 dof, {2 * stats.t.cdf(1, 8) - 1:.1%} at 8; "
        f"P(|t|<2) = {2 * stats.t.cdf(2, 3) - 1:.1%}, {2 * stats.t.cdf(2, 8) - 1:.1%})"
    )


if __name__ == "__main__":
    main()
