"""Do hrgjax's error bars cover the truth? Monte Carlo with known truth (issue 43).

For each workflow: datasets simulated with known parameters, the workflow run as a user runs
it, and every reported ± compared with the truth: the share of truths within ±1σ and ±2σ
(nominal 68 % and 95 %), the RMS of the standardised errors z = (value − truth)/σ (nominal 1)
and the parameter with the largest mean z. Targets (issue 43): 68 ± 8 % / ≥ 90 %, z-RMS
0.8–1.25, no parameter's mean z beyond 2.

Workflows:

- `discover`, one hidden effect: dwell grids of the default gyro reduced to the nominal
  physics with a bias–temperature slope of 0.02 °/h/°C hidden
  (`hrgjax.discovery.generate.hidden_effect_dataset`, its coloured noise and switch-on bias).
  Truths: the slope b1 = 0.02 °/h/°C, the curvature b2 = 0, the angular gain k_e.
- `discover`, two effects, one outside the catalogue: the same with an apparent input rate
  of 0.5 °/h · cos 4θ added to the measured wave angle (integrated along each run's own
  path) — structure the model cannot name, which pulls the slope.
- Ferraris (`benchmarks/coverage_ferraris.py`, when present): white and random-walk sensor
  noise.
- The physical grey box (`--physical`): the quick seed plan on the default gyro (real closed
  loops, temperature laws) against the gyro's true laws — the ideal-loop grey box (its g
  and cross-talk are effective values; also against its own noise-free fit) and the grey
  box given the gyro's loops (`PhysicalCompensator(plant=gyro)`).
- The physical grey box on many short runs (`--physical-runs [--run-bias σ]`): 3
  temperatures × 6 wave angles of 60-s static and rotation runs against the plan's
  noise-free fit; with `--run-bias`, each run its own switch-on bias as well.

"Before" is the textbook σ ((JᵀJ)⁻¹ of the noise model's whitening, kept in the report as
`std_textbook`); "after" is what `discover` now reports
([`honest`][hrgjax.discovery.trust.honest]), both from the same fits in one run.

Also elsewhere: the test session's offset (`benchmarks/session_offset.py`), the design's
predicted accuracy against the achieved one (`benchmarks/design_mc.py`), the Allan
deviation's χ² intervals at long τ (`benchmarks/coverage_allan.py`) and the composite noise
model's intervals and term selection (`benchmarks/noise_identification.py`); the physical
grey box against injected laws on the ideal-loop model gyro — white noise, gaps, jittered
stamps, a Gauss–Markov rate — with its σ's before and after their Student-t widening
(`benchmarks/coverage_physical.py`).

- `discover`, a drift over temperature outside the catalogue (`--temperature-drift cubic|step`):
  the one-effect grids (seeds 3000…) with 5·10⁻⁶ °/h/°C³·ΔT³ or a 0.3 °/h step above 20 °C
  added to the wave angle: structure no angle shape fits, which inflates the static
  windows' noise level ×2–15 (audit 2026-11-30).

Usage: `.venv/bin/python benchmarks/coverage.py [--quick] [--physical] [--only-physical]
[--physical-runs [--run-bias σ]] [--temperature-drift cubic|step] [--n N]`.
"""

import argparse
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from _common import machine, report  # noqa: E402

from hrgjax.data import MeasuredData  # noqa: E402
from hrgjax.discovery import discover  # noqa: E402
from hrgjax.discovery.generate import base_gyro, hidden_effect_dataset  # noqa: E402
from hrgjax.units import DEG  # noqa: E402

SLOPE = 0.02  # °/h/°C
FOUR_THETA = 0.5  # °/h


def add_four_theta(data: MeasuredData, amp_dph: float, k_e: float) -> MeasuredData:
    """`data` with an apparent input rate `amp_dph`·cos 4θ [°/h] added to its wave angle,
    integrated (trapezoid) along each run's own measured angle: a drift outside the catalogue."""
    cols = dict(data.columns)
    theta, t, run = np.asarray(cols["wave_angle_deg"], float), cols["time_s"], data.run
    out = theta.copy()
    for r in np.unique(run):
        m = np.flatnonzero(run == r)
        rate = -k_e * amp_dph * np.cos(4 * theta[m] * DEG) / 3600.0  # pattern °/s
        inc = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t[m]))])
        out[m] = theta[m] + inc
    cols["wave_angle_deg"] = out
    return MeasuredData(cols)


def add_temperature_drift(data: MeasuredData, kind: str, k_e: float) -> MeasuredData:
    """`data` with an apparent input rate outside the catalogue that follows temperature
    only, integrated along each run: `cubic` 5·10⁻⁶ °/h/°C³·ΔT³ or `step` 0.3 °/h above
    20 °C (the audit's t2.py; the static windows' noise level rises ×2–15)."""
    cols = dict(data.columns)
    theta, t, run = np.asarray(cols["wave_angle_deg"], float), cols["time_s"], data.run
    dT = np.asarray(cols["temperature_c"], float) - 20.0
    drift = 5e-6 * dT**3 if kind == "cubic" else 0.3 * (dT > 0.0)  # °/h
    out = theta.copy()
    for r in np.unique(run):
        m = np.flatnonzero(run == r)
        rate = -k_e * drift[m] / 3600.0  # pattern °/s
        out[m] = theta[m] + np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1])
                                                            * np.diff(t[m]))])  # fmt: skip
    cols["wave_angle_deg"] = out
    return MeasuredData(cols)


def summarise(z: dict[str, list]) -> dict:
    """Pooled coverage of standardised errors `{parameter: [z, …]}`."""
    allz = np.concatenate([np.asarray(v, float) for v in z.values()])
    means = {k: float(np.mean(v)) for k, v in z.items()}
    worst = max(means.items(), key=lambda kv: abs(kv[1]))
    return {
        "within_1sigma": float(np.mean(np.abs(allz) < 1)),
        "within_2sigma": float(np.mean(np.abs(allz) < 2)),
        "z_rms": float(np.sqrt(np.mean(allz**2))),
        "worst_mean_z": worst,
        "n": int(allz.size),
    }


def discover_coverage(
    n: int, four_theta: float = 0.0, seed0: int = 1000, drift: str | None = None
) -> tuple[dict, dict, dict]:
    """(before, after) coverage of discover's b1, b2 and k_e over `n` dwell grids, and how
    often each leftover shape was fitted beside the model."""
    k_e = float(base_gyro(noise=False).k_e)
    truth = {("bias_temperature", "b1"): SLOPE, ("bias_temperature", "b2"): 0.0,
             ("angular_gain", "k_e"): k_e}  # fmt: skip
    before, after = {}, {}
    shapes = {}
    for s in range(n):
        data = hidden_effect_dataset("bias_temperature", SLOPE, key=jax.random.key(seed0 + s))
        if four_theta:
            data = add_four_theta(data, four_theta, k_e)
        if drift:
            data = add_temperature_drift(data, drift, k_e)
        found = discover(data)
        user = found.parameters
        raw = found.fit_parameters
        for shape in found.uncertainty["shapes"]:
            shapes[shape] = shapes.get(shape, 0) + 1
        for (name, p), value in truth.items():
            if name not in user:
                continue
            v, scale = user[name][p], abs(user[name][p]["value"] / raw[name][p]["value"])
            if name == "angular_gain":
                scale = 1.0
            key = f"{name}.{p}"
            old = raw[name][p].get("std_textbook", raw[name][p]["std"]) * scale
            before.setdefault(key, []).append((v["value"] - value) / old)
            after.setdefault(key, []).append((v["value"] - value) / v["sigma"])
        print(f"  dataset {s}: {found.verdict} {list(found.accepted)}, "
              f"shapes fitted beside: {found.uncertainty['shapes']}", flush=True)  # fmt: skip
    return summarise(before), summarise(after), shapes


def _row(name, res):
    w = res["worst_mean_z"]
    count = res.get("n", res.get("n_datasets"))
    return (
        f"{name:<44} {100 * res['within_1sigma']:6.0f} % {100 * res['within_2sigma']:6.0f} % "
        f"{res['z_rms']:7.2f}   {w[0]} {w[1]:+.2f}   (n = {count})"
    )


def physical_coverage(n: int) -> tuple[dict, dict, dict]:
    """z of the physical grey box's parameters over `n` seeds of the quick seed plan (the
    API's and CLI's default window), (against the noise-free fit of the same plan — the
    effective values an ideal-loop grey box takes from this gyro —, against the gyro's true
    laws). The difference of the two truths is what the real closed loops put into the
    ideal-loop model: at one rotation rate their 2θ ripple (∝ Ω) reads as readout gain
    mismatch and cross-talk. Third: the grey box given the gyro's loops (`plant=`), against
    the laws."""
    from hrgjax.calibration import PhysicalCompensator, run_plan, seed_plan
    from hrgjax.calibration.design import nominal_values
    from hrgjax.calibration.physical import NAMES
    from hrgjax.data import concat
    from hrgjax.presets import tvg3_like

    def session(gyro, s):
        key = jax.random.key(2000 + s)
        static, rotation = seed_plan(quick=True)
        a = run_plan(gyro, static, key=key, bias_key=key)
        b = run_plan(gyro, rotation, key=jax.random.fold_in(key, 1), bias_key=key,
                     first_run=static.size)  # fmt: skip
        return concat([a, b])

    gyro = tvg3_like()
    laws = np.asarray(nominal_values(gyro))  # the preset's laws in the grey box's terms
    clean = PhysicalCompensator().fit(session(gyro.without_noise(), 0)).parameters()
    effective = np.asarray([clean[name][0] for name in NAMES])
    print("  the real loops' pull on the ideal-loop grey box (noise-free fit − laws):")
    for i, name in enumerate(NAMES):
        if abs(effective[i] - laws[i]) > 1e-3 * max(abs(laws[i]), 1e-12):
            print(f"    {name:>18}: {effective[i] - laws[i]:+.3g}")
    z_eff, z_laws, z_plant = {}, {}, {}
    for s in range(n):
        data = session(gyro, s)
        p = PhysicalCompensator().fit(data).parameters()
        q = PhysicalCompensator(plant=gyro).fit(data).parameters()
        for i, name in enumerate(NAMES):
            v, e = p[name]
            if name == "bias0":  # its truth holds this session's switch-on bias (0.2 °/h
                continue  # spread), which the noise-free fit lacks: the fit measures it
            if e > 0 and np.isfinite(e):
                z_eff.setdefault(name, []).append((v - effective[i]) / e)
                z_laws.setdefault(name, []).append((v - laws[i]) / e)
            v, e = q[name]
            if e > 0 and np.isfinite(e):  # (bias0 skipped above, as for the others)
                z_plant.setdefault(name, []).append((v - laws[i]) / e)
        print(f"  seed {s}: fitted", flush=True)
    return summarise(z_eff), summarise(z_laws), summarise(z_plant)


def with_run_biases(data, sigma_dph: float, key, k_e: float):
    """`data` with an independent constant rate bias of σ `sigma_dph` [°/h] per run on its
    wave angle (each run its own switch-on, as on a bench that powers the gyro per run)."""
    cols = dict(data.columns)
    runs = np.unique(cols["run"])
    bias = np.asarray(jax.random.normal(key, (runs.size,))) * sigma_dph / 3600.0  # °/s
    b = bias[np.searchsorted(runs, cols["run"])]
    t0 = {r: cols["time_s"][cols["run"] == r][0] for r in runs}
    t = cols["time_s"] - np.array([t0[r] for r in cols["run"]])
    cols["wave_angle_deg"] = cols["wave_angle_deg"] - k_e * b * t
    return MeasuredData(cols)


def physical_runs_coverage(n: int, run_bias_dph: float = 0.0) -> dict:
    """z of the physical grey box on a plan of many short runs — 3 temperatures × 6 wave
    angles, 60-s static and 5 °/s rotation runs, one switch-on — over `n` seeds of the
    default gyro, against the plan's noise-free fit (its effective values); with
    `run_bias_dph`, each run also gets its own constant bias of that σ [°/h], as on a bench
    that powers the gyro per run (the fit counts a run's 10-s windows as independent)."""
    from hrgjax.calibration import (
        PhysicalCompensator,
        physical,
        rotation_plan,
        run_plan,
        static_plan,
    )
    from hrgjax.data import concat
    from hrgjax.presets import tvg3_like

    temps, angles = (-40.0, 20.0, 60.0), tuple(range(-90, 90, 30))
    static = static_plan(temps, angles, duration_s=60.0, dt_out=0.5)
    rotation = rotation_plan(temps, angles, duration_s=60.0, dt_out=0.5)

    def session(gyro, key):
        bias = jax.random.fold_in(key, 7)
        a = run_plan(gyro, static, key=key, bias_key=bias)
        b = run_plan(gyro, rotation, key=jax.random.fold_in(key, 1), bias_key=bias,
                     first_run=static.size)  # fmt: skip
        return concat([a, b])

    truth = np.asarray(
        PhysicalCompensator().fit(session(tvg3_like(noise=False), jax.random.key(0))).values
    )
    z = {}
    for s in range(n):
        data = session(tvg3_like(), jax.random.key(1000 + s))
        if run_bias_dph:
            data = with_run_biases(data, run_bias_dph, jax.random.key(5000 + s),
                                   float(tvg3_like().k_e))  # fmt: skip
        fit = PhysicalCompensator().fit(data)
        v, e = np.asarray(fit.values), np.sqrt(np.diag(np.asarray(fit.covariance)))
        for i, name in enumerate(physical.NAMES):
            if name != "bias0":  # its truth holds each session's switch-on bias
                z.setdefault(name, []).append((v[i] - truth[i]) / e[i])
        print(f"  seed {s}: fitted", flush=True)
    print(f"  {'parameter':>18}  z-RMS  mean z")
    for name, values in z.items():
        print(f"  {name:>18}  {np.sqrt(np.mean(np.square(values))):5.2f}  {np.mean(values):+6.2f}")
    return summarise(z)


def discover_rows(n: int) -> list:
    """The four discover rows: one effect and one beside a 4θ drift, before and after."""
    b1, a1, _ = discover_coverage(n)
    b2, a2, shapes = discover_coverage(n, FOUR_THETA)
    print(f"  shapes fitted beside the model with 4θ hidden: {shapes}")
    return [
        ("discover, one effect — before (textbook σ)", b1),
        ("discover, one effect — after", a1),
        ("discover, + 4θ outside the catalogue — before", b2),
        ("discover, + 4θ outside the catalogue — after", a2),
    ]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="6 datasets per workflow")
    ap.add_argument("--n", type=int, default=None, help="datasets per workflow")
    ap.add_argument("--physical", action="store_true", help="also the physical grey box")
    ap.add_argument("--only-physical", action="store_true", help="the physical grey box alone")
    ap.add_argument("--physical-runs", action="store_true",
                    help="the physical grey box on 36 short runs alone")  # fmt: skip
    ap.add_argument("--run-bias", type=float, default=0.0,
                    help="with --physical-runs: each run's own bias, σ [°/h]")  # fmt: skip
    ap.add_argument("--temperature-drift", choices=("cubic", "step"), default=None,
                    help="the discover rows with a drift over temperature outside the "
                    "catalogue alone (seeds 3000…)")  # fmt: skip
    args = ap.parse_args(argv)
    if args.run_bias and not args.physical_runs or args.run_bias < 0:
        ap.error("--run-bias takes a σ ≥ 0 [°/h] and goes with --physical-runs")
    n = args.n or (6 if args.quick else 20)
    print(f"coverage.py on {machine()}, {n} datasets per workflow")
    t0 = time.perf_counter()
    rows = []
    if args.temperature_drift:
        b, a, shapes = discover_coverage(n, seed0=3000, drift=args.temperature_drift)
        print(f"  shapes fitted beside the model: {shapes}")
        name = f"discover, + {args.temperature_drift} over temperature"
        rows += [(f"{name} — before", b), (f"{name} — after", a)]
        args.only_physical = args.physical = False  # this case alone
    elif args.physical_runs:
        res = physical_runs_coverage(n, args.run_bias)
        rows += [(f"physical, 36 × 60-s runs, run bias {args.run_bias:g} °/h", res)]
        args.only_physical, args.physical = True, False
    elif args.only_physical:
        args.physical = True
    else:
        rows += discover_rows(n)
    if not args.only_physical and not args.temperature_drift:
        from coverage_ferraris import summarise as ferraris_summary
        from coverage_ferraris import z_scores

        for noise in ("white", "random_walk"):
            after, before = z_scores(10 * n, noise, 0)  # a session costs ≈ 0.3 s
            rows.append((f"Ferraris, {noise} noise — before", ferraris_summary(before)))
            rows.append((f"Ferraris, {noise} noise — after", ferraris_summary(after)))
    if args.physical:
        eff, laws, plant = physical_coverage(min(n, 8))
        rows += [("physical grey box vs its noise-free fit", eff),
                 ("physical grey box vs the gyro's laws", laws),
                 ("physical, plant= the gyro's loops, vs laws", plant)]  # fmt: skip
    print(f"\n{'workflow':<44} {'±1σ':>8} {'±2σ':>8} {'z-RMS':>7}   worst mean z")
    for name, res in rows:
        print(_row(name, res))
    for name, res in rows:
        report(f"z-RMS, {name}", res["z_rms"], "", target="0.8–1.25")
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
