"""Does `hrgjax.ins.alignment.align`'s σ cover the truth at every latitude? Monte Carlo.

Each draw: a stationary IMU at a random heading (uniform), pitch and roll (N(0, 2°)), 1 Hz
(`trajectory.stationary`), with constant body-frame gyro and accelerometer biases drawn from
the scenario's truth, gyro angle random walk and accelerometer white noise; then `align` with
the scenario's assumed grade, and z = (estimate − truth) / σ per angle. Printed per angle: the
RMS of z with its Monte Carlo 1σ (delta method: sd(z²) / (2 RMS √n)) and the fractions within
±1σ, ±1.96σ and ±2σ (a right σ: 1.0, 68 %, 95 %, 95 %), and the median σ.

Scenarios (latitude; true gyro bias σ / ARW → assumed; duration):

- `matched`: 45°, 0.05 °/h, 0.01 °/√h, assumed the same (`align`'s defaults), 30 min;
- `bias2x`: true bias 0.1 °/h, assumed 0.05 °/h: the heading σ is the *assumption's*
  (stationary alignment cannot measure the east gyro bias) and does not cover — no filter
  change can; `hrgjax align --gyro-bias` gives the right grade;
- `grade1`: 1 °/h, 0.1 °/√h, assumed the same;
- `lat0`, `lat70`, `lat85`, `lat88`, `lat89`: `matched` at that latitude (89° is the last
  `align` takes: the heading σ there is 11°);
- `lat88_arw5`: ARW 0.05 °/√h at 88°; `lat88_10min`: 10 min at 88°; `lat88_grade1`:
  `grade1` at 88° (heading σ 108°: a heading error that is not small — see the README).

Near the pole two things made the σ small (benchmarks/README.md has the figures before):
body-frame bias states mapped through the current attitude estimate, which the fine stage's
heading corrections turned — the filter read the turn as information about the unobservable
level accelerometer biases (pitch/roll σ below σ_∇/g); and the coarse heading's prior, a fixed
5° beyond the biases, where its white-noise part is (arw/√T)/(ω_ie cos φ) (8.45° at 88°, 17°
at 89°), with a bias jacobian taken at the noisy means.

`--threshold`: where `align`'s `AlignmentWarning` must fire. The bias-limited heading error is
the gyrocompass solution atan2(ε_E, ω_h + ε_N) (ω_h = ω_ie cos φ; `align`'s estimate follows
it to 0.1° RMS), heavy-tailed where σ_ε is not ≪ ω_h: z = that/F for F = σ_ε/ω_h, by
quadrature over the Gaussian bias, against F; then `align` itself, `--n` draws per point
(300 for the thresholds), along the end σ (80°, low ARW, gyro grade varied) and the start σ
(88°, 0.05 °/h, ARW and coarse span varied: the coarse heading's tail reaches 140–180°, where
the fine filter does not recover). Printed: start and end σ, z-RMS, ±1.96σ, the largest |z|
and how many draws warned.

Usage: `.venv/bin/python benchmarks/coverage_alignment.py [--n 100] [--seed 0]
[--scenarios matched,bias2x,...] [--threshold]` (100 draws × 11 scenarios: about 10 minutes on
2 shared cores; `--threshold --n 300`: 11 points, about 8 minutes).
"""

from __future__ import annotations

import argparse
import time
import warnings

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

from hrgjax._progress import bar  # noqa: E402
from hrgjax.ins import alignment as al  # noqa: E402
from hrgjax.ins import trajectory as tr  # noqa: E402
from hrgjax.ins.constants import OMEGA_IE  # noqa: E402

DEG = np.pi / 180
DPH = DEG / 3600  # °/h in rad/s
RTH = DEG / 60  # °/√h in rad/√s

SCENARIOS = {  # latitude [°], true gyro bias σ [°/h], true ARW [°/√h], assumed bias, ARW, s
    "matched": (45.0, 0.05, 0.01, 0.05, 0.01, 1800.0),
    "bias2x": (45.0, 0.1, 0.01, 0.05, 0.01, 1800.0),
    "grade1": (45.0, 1.0, 0.1, 1.0, 0.1, 1800.0),
    "lat0": (0.0, 0.05, 0.01, 0.05, 0.01, 1800.0),
    "lat70": (70.0, 0.05, 0.01, 0.05, 0.01, 1800.0),
    "lat85": (85.0, 0.05, 0.01, 0.05, 0.01, 1800.0),
    "lat88": (88.0, 0.05, 0.01, 0.05, 0.01, 1800.0),
    "lat89": (89.0, 0.05, 0.01, 0.05, 0.01, 1800.0),
    "lat88_arw5": (88.0, 0.05, 0.05, 0.05, 0.05, 1800.0),
    "lat88_10min": (88.0, 0.05, 0.01, 0.05, 0.01, 600.0),
    "lat88_grade1": (88.0, 1.0, 0.1, 1.0, 0.1, 1800.0),
}
THRESHOLD_POINTS = (  # latitude [°], gyro bias σ [°/h], ARW [°/√h] (true = assumed), coarse_s
    (80.0, 0.547, 0.001, 60.0), (80.0, 0.684, 0.001, 60.0), (80.0, 0.821, 0.001, 60.0),
    (80.0, 1.0, 0.001, 60.0),  # end σ 12°, 15°, 18°, 21.9°
    (88.0, 0.05, 0.015, 60.0), (88.0, 0.05, 0.02, 60.0), (88.0, 0.05, 0.025, 60.0),
    (88.0, 0.05, 0.03, 60.0), (88.0, 0.05, 0.05, 60.0),  # start σ 14.7°, 18.5°, 22.4°, 26.4°, 43°
    (88.0, 0.05, 0.05, 300.0), (88.0, 0.05, 0.05, 600.0),  # start σ 20.3°, 15.3°
)  # fmt: skip
VRW, ACCEL_BIAS, DT = 1e-4, 1e-3, 1.0
ANGLES = ("heading", "pitch", "roll")


def _coverage(z):
    z = np.asarray(z)
    rms = float(np.sqrt(np.mean(z**2)))
    return {"z_rms": rms, "z_rms_mc": float(np.std(z**2) / (2 * rms * np.sqrt(z.size))),
            "within_1sigma": float(np.mean(abs(z) < 1)),
            "within_1.96sigma": float(np.mean(abs(z) < 1.96)),
            "within_2sigma": float(np.mean(abs(z) < 2))}  # fmt: skip


def _draws(scenario, n, seed, coarse_s=60.0, label=""):
    """`n` draws of `scenario` (latitude, true and assumed grades, duration): per draw the
    errors and σ (heading, pitch, roll) [°], the heading σ at the fine stage's start, whether
    `align` warned."""
    lat, bg, arw, bg_assumed, arw_assumed, duration = scenario
    rng = np.random.default_rng(seed)
    kw = dict(gyro_bias_std=bg_assumed * DPH, arw=arw_assumed * RTH, coarse_s=coarse_s)
    d_all, s_all, start, warned = [], [], [], []
    with bar(n, f"alignment {label}", unit="draw") as progress:
        for _ in range(n):
            traj = tr.stationary(lat, heading_deg=rng.uniform(0, 360),
                                 pitch_deg=rng.normal(0, 2), roll_deg=rng.normal(0, 2),
                                 duration_s=duration, dt=DT)  # fmt: skip
            f_b, w_b = traj.imu()
            size = len(traj.t) - 1
            eps, nab = rng.normal(0, bg * DPH, 3), rng.normal(0, ACCEL_BIAS, 3)
            dth = (np.asarray(w_b[1:]) + eps) * DT + arw * RTH * np.sqrt(DT) * rng.standard_normal(
                (size, 3)
            )
            dv = (np.asarray(f_b[1:]) + nab) * DT + VRW * np.sqrt(DT) * rng.standard_normal(
                (size, 3)
            )
            log = al.ImuLog(traj.t[1:], jnp.asarray(dth), jnp.asarray(dv), lat * DEG)
            truth = np.asarray(al.euler_deg(jnp.asarray(traj.c_bn[0])))
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", al.AlignmentWarning)
                r = al.align(log, **kw)
            d = np.array([r.heading_deg, r.pitch_deg, r.roll_deg]) - truth
            d[0] = (d[0] + 180) % 360 - 180
            d_all.append(d)
            s_all.append([r.heading_std_deg, r.pitch_std_deg, r.roll_std_deg])
            start.append(float(r.std_history_deg[0, 0]))
            warned.append(any(issubclass(w.category, al.AlignmentWarning) for w in caught))
            progress.update(1)
    return np.array(d_all), np.array(s_all), np.array(start), np.array(warned)


def coverage(name: str, n: int, seed: int = 0) -> dict:
    """Heading, pitch and roll coverage of `align`'s σ over `n` draws of scenario `name`."""
    d, sigma, _, _ = _draws(SCENARIOS[name], n, seed, label=name)
    zz = d / sigma
    out = {k: _coverage(zz[:, i]) for i, k in enumerate(ANGLES)}
    out["median_sigma_deg"] = np.median(sigma, 0).tolist()
    return out


def gyrocompass_tail(f_deg: float, points: int = 801) -> tuple[float, float]:
    """(z-RMS, fraction within ±1.96σ) of z = atan2(ε_E, ω_h + ε_N)/F for biases N(0, (F ω_h)²)
    (F [°] the bias-limited σ), by quadrature on ±8σ."""
    x = np.linspace(-8, 8, points)
    xx, yy = np.meshgrid(x, x)
    w = np.exp(-(xx**2 + yy**2) / 2)
    w /= w.sum()
    f = np.radians(f_deg)
    z = np.arctan2(f * xx, 1 + f * yy) / f
    return float(np.sqrt(np.sum(w * z**2))), float(np.sum(w * (abs(z) < 1.96)))


def threshold(n: int, seed: int) -> None:
    """The study behind `END_HEADING_STD_DEG` and `START_HEADING_STD_DEG` (module docstring)."""
    print(f"bias-limited heading (gyrocompass solution; END_HEADING_STD_DEG = "
          f"{al.END_HEADING_STD_DEG:g}°):")  # fmt: skip
    for f in (5.0, 10.0, 12.0, 14.0, 15.0, 16.0, 18.0, 20.0, 22.0, 25.0, 30.0):
        rms, cover = gyrocompass_tail(f)
        print(f"  F {f:4.0f}°: z-RMS {rms:.3f}, within ±1.96σ {100 * cover:.1f} %")
    print(f"\nalign, {n} draws per point (START_HEADING_STD_DEG = {al.START_HEADING_STD_DEG:g}°):")
    for lat, bg, arw, coarse_s in THRESHOLD_POINTS:
        t0 = time.perf_counter()
        d, sigma, start, warned = _draws((lat, bg, arw, bg, arw, 1800.0), n, seed, coarse_s,
                                         f"{lat:g}° {bg:g} °/h {arw:g} °/√h {coarse_s:g} s")  # fmt: skip
        c = _coverage(d[:, 0] / sigma[:, 0])
        limit = bg * DPH / (OMEGA_IE * np.cos(lat * DEG)) / DEG
        print(f"  {lat:g}°, {bg:g} °/h, {arw:g} °/√h, coarse {coarse_s:g} s: start σ "
              f"{np.median(start):.1f}°, end σ {np.median(sigma[:, 0]):.2f}° (grade limit "
              f"{limit:.2f}°): z-RMS {c['z_rms']:.3f} ± {c['z_rms_mc']:.3f}, "
              f"{100 * c['within_1.96sigma']:.1f} % within ±1.96σ, max |z| "
              f"{np.max(abs(d[:, 0] / sigma[:, 0])):.1f}, warned {int(warned.sum())}/{n} "
              f"[{time.perf_counter() - t0:.0f} s]", flush=True)  # fmt: skip


def main():
    from _common import report

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100, help="draws per scenario")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--threshold", action="store_true", help="the warning's thresholds")
    args = parser.parse_args()
    if args.threshold:
        return threshold(args.n, args.seed)
    for name in args.scenarios.split(","):
        if name not in SCENARIOS:
            parser.error(f"--scenarios: unknown {name!r}; expected some of {', '.join(SCENARIOS)}")
    for name in args.scenarios.split(","):
        t0 = time.perf_counter()
        res = coverage(name, args.n, args.seed)
        lat, bg, arw, bga, arwa, duration = SCENARIOS[name]
        print(f"\n{name}: lat {lat:g}°, true gyro bias σ {bg:g} °/h, ARW {arw:g} °/√h; assumed "
              f"{bga:g} °/h, {arwa:g} °/√h; {duration / 60:g} min; {args.n} draws, "
              f"{time.perf_counter() - t0:.0f} s")  # fmt: skip
        print(
            f"  {'angle':8} {'z RMS':>12} {'±1σ':>5} {'±1.96σ':>7} {'±2σ':>5} {'median σ [°]':>13}"
        )
        for i, k in enumerate(ANGLES):
            c = res[k]
            print(f"  {k:8} {c['z_rms']:6.2f} ± {c['z_rms_mc']:.2f} "
                  f"{100 * c['within_1sigma']:4.0f}% "
                  f"{100 * c['within_1.96sigma']:6.0f}% {100 * c['within_2sigma']:4.0f}% "
                  f"{res['median_sigma_deg'][i]:13.4f}")  # fmt: skip
        h = res["heading"]
        report(f"alignment {name}: heading RMS of (value − truth)/σ", h["z_rms"], "",
               target="0.9–1.1 (bias2x: the assumption's, > 1 expected)")  # fmt: skip
        report(f"alignment {name}: headings within ±1.96σ", 100 * h["within_1.96sigma"], "%",
               target="95 ± 3 %")  # fmt: skip
        level = max(res["pitch"]["z_rms"], res["roll"]["z_rms"])
        report(f"alignment {name}: pitch/roll RMS of (value − truth)/σ, larger", level, "",
               target="0.9–1.1")  # fmt: skip


if __name__ == "__main__":
    main()
