"""Do the Ferraris calibration's ± 1σ cover the truth? Monte Carlo with known truth.

Each dataset draws an IMU (1 % scale and misalignment, biases, g-sensitivity), simulates
its six-axis Ferraris session (`hg.imu.ferraris_session`: six faces of 6 s and three turns,
100 Hz, 78 s) with one of three noises, calibrates it (`hg.imu.ferraris` on the true
sections) and standardises each of the 33 parameters' errors, z = (value − truth) / σ:

- `white`: white noise, 1e-3 rad/s (0.06 °/s) and 0.01 m/s² per sample;
- `random_walk`: the same plus a random walk of every channel's bias from the session's
  start, 2e-5 rad/s/√s (Kalibr's figure for an ADIS16448, EuRoC) and 3e-4 m/s²/√s;
- `gauss_markov`: the same drive as a first-order Gauss–Markov bias with τ = 20 s (bias
  instability 6.3e-5 rad/s = 13 °/h and 9.5e-4 m/s² ≈ 0.1 mg).

Pooled over the parameters with a finite, non-zero σ: the fraction within ±1σ and ±2σ
(targets 68 ± 8 % and ≥ 90 %), the RMS of z (target 0.8–1.25) and the parameter whose mean
z is furthest from 0 (target |mean z| ≤ 2); and per bias parameter (b_g x, y, z; b_a x, y,
z), whose σ the drift dominates and which the pooled figures hide (6 of 33), the RMS of z
and the largest |z| over the sessions. "before": the σ from white noise alone (the
estimator until issue 43); "after": the σ the estimator reports now (white noise and the
bias random walk the faces allow, its intensity q's posterior mean).

`ferraris_coverage(n, noise, seed)` returns the "after" figures for `benchmarks/coverage.py`.

Usage: `.venv/bin/python benchmarks/coverage_ferraris.py [--quick] [--n N] [--seed S]
[--repeats R]` (quick: 40 datasets per noise, under a minute on 2 cores; default 200,
about 2 minutes). `--repeats 3`: sessions of three repeats, whose σ come from the repeats'
scatter (Student-t with R − 1 degrees of freedom: wider than ±1σ suggests).
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import hrgjax as hg  # noqa: E402
from hrgjax.imu.ferraris import _estimate_and_jacobian, _statistics  # noqa: E402

NOISES = {
    "white": {},
    "random_walk": {"gyro_walk": 2e-5, "accel_walk": 3e-4},
    "gauss_markov": {"gyro_walk": 2e-5, "accel_walk": 3e-4, "drift_tau_s": 20.0},
}
"""The sessions' noise beyond white (1e-3 rad/s, 0.01 m/s² per sample), per kind."""


def _truth(rng: np.random.Generator) -> hg.imu.ImuCalibration:
    return hg.imu.ImuCalibration.known(
        accel_matrix=np.eye(3) + rng.normal(0, 0.01, (3, 3)),
        accel_bias=rng.normal(0, 0.1, 3),
        gyro_matrix=np.eye(3) + rng.normal(0, 0.01, (3, 3)),
        gyro_bias=rng.normal(0, 0.01, 3),
        gyro_g_sensitivity=rng.normal(0, 1e-4, (3, 3)),
    )


def z_scores(n: int, noise: str, seed: int, repeats: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Standardised errors (n, 33) of `n` simulated sessions: (after, before) — the σ the
    estimator reports, and the σ of white noise alone, on the same datasets. With
    `repeats` > 1 the session runs that many times (3-s faces) and both are the repeats'
    scatter."""
    if noise not in NOISES:
        raise ValueError(f"noise must be one of {', '.join(NOISES)}; got {noise!r}")
    rng = np.random.default_rng(seed)
    key = jax.random.key(seed)
    after, before = np.zeros((n, 33)), np.zeros((n, 33))
    for i in range(n):
        truth = _truth(rng)
        layout = {"repeats": repeats, "static_s": 3.0} if repeats > 1 else {}
        data, sections = hg.imu.ferraris_session(
            truth, jax.random.fold_in(key, i), **layout, **NOISES[noise]
        )
        cal = hg.imu.ferraris(data, sections)
        err = np.asarray(cal.vector()) - np.asarray(truth.vector())
        stats = _statistics(data, sections)
        jac, _ = _estimate_and_jacobian(stats.stats, cal.g, np.deg2rad(np.asarray(cal.turn_deg)))
        white = np.asarray(jac) @ stats.white @ np.asarray(jac).T
        after[i] = _standardise(err, np.diag(np.asarray(cal.covariance)))
        before[i] = _standardise(err, np.diag(white))
    return after, before


def _standardise(err: np.ndarray, var: np.ndarray) -> np.ndarray:
    ok = np.isfinite(var) & (var > 0)
    return np.where(ok, err / np.sqrt(np.where(ok, var, 1.0)), np.nan)


def summarise(z: np.ndarray) -> dict:
    """Coverage figures of standardised errors `z` (datasets, parameters); NaN where a
    parameter was not identified (σ zero or not finite)."""
    pooled = z[np.isfinite(z)]
    mean = np.nanmean(z, axis=0)
    worst = int(np.nanargmax(np.abs(mean)))
    rms = np.sqrt(np.nanmean(z**2, axis=0))
    worst_rms = int(np.nanargmax(rms))
    bias = [hg.imu.PARAMETERS.index(f"{s}_bias[{c}]") for s in ("gyro", "accel") for c in "xyz"]
    return {
        "within_1sigma": float(np.mean(np.abs(pooled) < 1.0)),
        "within_2sigma": float(np.mean(np.abs(pooled) < 2.0)),
        "z_rms": float(np.sqrt(np.mean(pooled**2))),
        "worst_mean_z": (hg.imu.PARAMETERS[worst], float(mean[worst])),
        "worst_rms_z": (hg.imu.PARAMETERS[worst_rms], float(rms[worst_rms])),
        "bias_rms_z": [float(rms[i]) for i in bias],
        "bias_max_abs_z": float(np.nanmax(np.abs(z[:, bias]))),
        "n_params": int(np.sum(np.any(np.isfinite(z), axis=0))),
        "n_datasets": int(z.shape[0]),
    }


def ferraris_coverage(n: int, noise: str, seed: int) -> dict:
    """Coverage of `hg.imu.ferraris`'s reported σ over `n` simulated sessions with `noise`
    ("white", "random_walk" or "gauss_markov"): `{"within_1sigma", "within_2sigma",
    "z_rms", "worst_mean_z": (name, value), "worst_rms_z": (name, value), "bias_rms_z" (6:
    b_g x, y, z, b_a x, y, z), "bias_max_abs_z", "n_params", "n_datasets"}`, pooled over
    the identified parameters (the bias figures per parameter)."""
    return summarise(z_scores(n, noise, seed)[0])


def _row(noise: str, which: str, s: dict) -> str:
    name, mean = s["worst_mean_z"]
    rname, rms = s["worst_rms_z"]
    return (
        f"{noise:13s} {which:7s} {100 * s['within_1sigma']:6.1f} % {100 * s['within_2sigma']:6.1f} %"
        f" {s['z_rms']:6.2f}   {mean:+5.2f} {name:24s} {rms:5.2f} {rname}"
    )


def main():
    from _common import machine, report

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="40 datasets per noise")
    parser.add_argument("--n", type=int, default=None, help="datasets per noise (default 200)")
    parser.add_argument("--seed", type=int, default=43)
    parser.add_argument("--repeats", type=int, default=1, help="sessions of R repeats")
    args = parser.parse_args()
    n = args.n or (40 if args.quick else 200)
    layout = f", {args.repeats} repeats of 3-s faces" if args.repeats > 1 else ""
    print(f"machine: {machine()}  ({n} sessions per noise{layout}, seed {args.seed})")
    print(
        f"{'noise':13s} {'σ':7s} {'±1σ':>8s} {'±2σ':>8s} {'z RMS':>6s}   worst mean z"
        f"{'':19s} worst RMS z"
    )
    for noise in NOISES:
        t0 = time.perf_counter()
        after, before = z_scores(n, noise, args.seed, args.repeats)
        sa, sb = summarise(after), summarise(before)
        print(_row(noise, "before", sb))
        print(_row(noise, "after", sa) + f"   ({time.perf_counter() - t0:.0f} s)")
        for which, s in (("before", sb), ("after", sa)):
            print(f"{'':13s} {which:7s} biases' RMS z (b_g x y z, b_a x y z): "
                  + " ".join(f"{r:.2f}" for r in s["bias_rms_z"])
                  + f"; largest |z| {s['bias_max_abs_z']:.1f}")  # fmt: skip
        tag = f"{noise}, {args.repeats} repeats" if args.repeats > 1 else noise
        for which, s in (("before", sb), ("after", sa)):
            report(f"ferraris {tag} {which}: truths within ±1σ", 100 * s["within_1sigma"], "%",
                   target="68 ± 8 %")  # fmt: skip
            report(f"ferraris {tag} {which}: truths within ±2σ", 100 * s["within_2sigma"], "%",
                   target="≥ 90 %")  # fmt: skip
            report(f"ferraris {tag} {which}: RMS of (value − truth)/σ", s["z_rms"], "",
                   target="0.8–1.25")  # fmt: skip
            report(f"ferraris {tag} {which}: worst bias's RMS of (value − truth)/σ",
                   max(s["bias_rms_z"]), "", target="0.8–1.25")  # fmt: skip


if __name__ == "__main__":
    main()
