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

These sessions have no Earth's rate, and are calibrated with `earth_rate=0` (declared
absent: the method's σ). Two more kinds turn with the Earth at 45° (`lat_deg=45`, the faces'
attitudes of `ferraris_session`, each pair reversing the horizontal rate: the worst case
for G):

- `earth_mems`: white noise as above (the docs' MEMS session);
- `earth_tactical`: white noise of 1e-5 rad/s and 1e-3 m/s² per sample (σ(G) ≈ 3e-8
  against the Earth's 5.26e-6 rad/s per m/s²);
- `earth_tactical_random`: the same with each face at a heading drawn uniformly (the pair
  sums then hold part of the horizontal rate: b_g reads M_g Σh/6, Ω cos φ √2/6 RMS);
- `earth_tactical_tumble`: the same tumbled about north (`TUMBLE_NORTH`: two pairs keep the
  rate, b_g's y takes 2Ω cos φ / 3, the worst case for b_g).

Their "before" is the method's σ as it was (`earth_rate=0`: white noise and the bias
drift), "after" the σ with `lat_deg=45` (the vertical rate removed, the horizontal one in
the covariance), and "no latitude" the default `ferraris` call (`lat_deg=None`: both in the
covariance, for a latitude anywhere on the globe).

Pooled over the parameters with a finite, non-zero σ: the fraction within ±1σ and ±2σ
(targets 68 ± 8 % and ≥ 90 %), the RMS of z (target 0.8–1.25) and the parameter whose mean
z is furthest from 0 (target |mean z| ≤ 2); and per bias parameter (b_g x, y, z; b_a x, y,
z), whose σ the drift dominates and which the pooled figures hide (6 of 33), the RMS of z
and the largest |z| over the sessions. "before": the σ from white noise alone (the
estimator until issue 43); "after": the σ the estimator reports now (white noise and the
bias random walk the faces allow, its intensity q's posterior mean).

`ferraris_coverage(n, noise, seed)` returns the "after" figures for `benchmarks/coverage.py`.

Usage: `.venv/bin/python benchmarks/coverage_ferraris.py [--quick] [--n N] [--seed S]
[--repeats R] [--earth-only]` (quick: 40 datasets per noise, under a minute on 2 cores;
default 200, about 2 minutes on 2 cores; `--earth-only`: the four Earth-rate kinds alone). `--repeats 3`: sessions of three repeats, whose σ come from the repeats'
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
_TACTICAL = {"lat_deg": 45.0, "gyro_noise": 1e-5, "accel_noise": 1e-3}
EARTH = {
    "earth_mems": {"lat_deg": 45.0},
    "earth_tactical": _TACTICAL,
    "earth_tactical_random": _TACTICAL,
    "earth_tactical_tumble": _TACTICAL,
}
"""Sessions on a bench at 45° that turns with the Earth: the docs' MEMS noise, a tactical one
(the simulator's faces, every pair reversing the horizontal rate), the tactical one with free
headings, and the tactical one tumbled about north (`HEADINGS`)."""
TUMBLE_NORTH = {"x_p": 90.0, "x_a": 90.0, "z_a": 180.0}
"""`ferraris_session`'s `face_headings_deg` that keeps the y axis north on the x and z faces:
those pairs keep the horizontal rate, b_g's y takes 2Ω cos φ / 3 (the y pair reverses it)."""
HEADINGS = {"earth_tactical_random": "random", "earth_tactical_tumble": TUMBLE_NORTH}
"""The faces' headings per kind (others: the simulator's): "random" draws each face's
uniformly, independently, per session."""


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
    scatter. For the `EARTH` kinds: (with the latitude, the method's σ as before)."""
    got = all_z_scores(n, noise, seed, repeats)
    return got["after"], got["before"]


def all_z_scores(n: int, noise: str, seed: int, repeats: int = 1) -> dict[str, np.ndarray]:
    """`z_scores`' standardised errors by σ: "after", "before" and, for the `EARTH` kinds,
    "no latitude" (the default call)."""
    if noise not in NOISES and noise not in EARTH:
        raise ValueError(f"noise must be one of {', '.join([*NOISES, *EARTH])}; got {noise!r}")
    rng = np.random.default_rng(seed)
    key = jax.random.key(seed)
    earth = noise in EARTH
    out = {k: np.zeros((n, 33)) for k in ("after", "before", *(("no latitude",) if earth else ()))}
    for i in range(n):
        truth = _truth(rng)
        layout = {"repeats": repeats, "static_s": 3.0} if repeats > 1 else {}
        if HEADINGS.get(noise) == "random":
            layout["face_headings_deg"] = rng.uniform(0.0, 360.0, 6).tolist()
        elif noise in HEADINGS:
            layout["face_headings_deg"] = HEADINGS[noise]
        data, sections = hg.imu.ferraris_session(
            truth,
            jax.random.fold_in(key, i),
            **layout,
            **(EARTH[noise] if earth else NOISES[noise]),
        )
        if earth:
            cals = {"after": hg.imu.ferraris(data, sections, lat_deg=EARTH[noise]["lat_deg"]),
                    "before": hg.imu.ferraris(data, sections, earth_rate=0.0),
                    "no latitude": hg.imu.ferraris(data, sections)}  # fmt: skip
            for which, cal in cals.items():
                err = np.asarray(cal.vector()) - np.asarray(truth.vector())
                out[which][i] = _standardise(err, np.diag(np.asarray(cal.covariance)))
            continue
        cal = hg.imu.ferraris(data, sections, earth_rate=0.0)  # simulated without it
        err = np.asarray(cal.vector()) - np.asarray(truth.vector())
        stats = _statistics(data, sections)
        jac, _ = _estimate_and_jacobian(stats.stats, cal.g, np.deg2rad(np.asarray(cal.turn_deg)))
        white = np.asarray(jac) @ stats.white @ np.asarray(jac).T
        out["after"][i] = _standardise(err, np.diag(np.asarray(cal.covariance)))
        out["before"][i] = _standardise(err, np.diag(white))
    return out


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
        "g_rms_z": [float(rms[i]) for i in range(24, 33)],
        "mg_rms_z": [float(rms[i]) for i in range(12, 21)],
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
        f"{noise:14s} {which:11s} {100 * s['within_1sigma']:6.1f} % {100 * s['within_2sigma']:6.1f} %"
        f" {s['z_rms']:6.2f}   {mean:+5.2f} {name:24s} {rms:5.2f} {rname}"
    )


def main():
    from _common import machine, report

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="40 datasets per noise")
    parser.add_argument("--n", type=int, default=None, help="datasets per noise (default 200)")
    parser.add_argument("--seed", type=int, default=43)
    parser.add_argument("--repeats", type=int, default=1, help="sessions of R repeats")
    parser.add_argument("--earth-only", action="store_true", help="the Earth-rate kinds alone")
    args = parser.parse_args()
    n = args.n or (40 if args.quick else 200)
    layout = f", {args.repeats} repeats of 3-s faces" if args.repeats > 1 else ""
    print(f"machine: {machine()}  ({n} sessions per noise{layout}, seed {args.seed})")
    print(
        f"{'noise':13s} {'σ':7s} {'±1σ':>8s} {'±2σ':>8s} {'z RMS':>6s}   worst mean z"
        f"{'':19s} worst RMS z"
    )
    kinds = [*([] if args.earth_only else NOISES), *([] if args.repeats > 1 else EARTH)]
    for noise in kinds:
        t0 = time.perf_counter()
        got = {w: summarise(z) for w, z in all_z_scores(n, noise, args.seed, args.repeats).items()}
        for which, s in got.items():
            print(_row(noise, which, s) + (f"   ({time.perf_counter() - t0:.0f} s)"
                                           if which == "after" else ""))  # fmt: skip
        for which, s in got.items():
            print(f"{'':14s} {which:11s} biases' RMS z (b_g x y z, b_a x y z): "
                  + " ".join(f"{r:.2f}" for r in s["bias_rms_z"])
                  + f"; largest |z| {s['bias_max_abs_z']:.1f}")  # fmt: skip
            if noise in EARTH:
                for name, key in (("G", "g_rms_z"), ("M_g", "mg_rms_z")):
                    print(f"{'':14s} {which:11s} {name}'s RMS z (row by row): "
                          + " ".join(f"{r:.2f}" for r in s[key]))  # fmt: skip
        tag = f"{noise}, {args.repeats} repeats" if args.repeats > 1 else noise
        for which, s in got.items():
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
