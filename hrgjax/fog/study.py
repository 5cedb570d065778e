r"""The seed-003 pipeline end to end, as `hrgjax vibration` runs it.

1. **Calibration** (step 2's angles, beyond the patent, which assumes them known): the true
   IMU is put through a multi-position test — 14 static positions for the accelerometers,
   rate-table rotations (±20 °/s about the axes and the diagonals) plus Earth rate for the
   gyros — and [`calibrate`][hrgjax.fog.misalignment.calibrate] estimates both triads. The
   rest of the pipeline uses the estimates, not the truth.
2. **Samples:** a grid of table conditions, with the scenario's held-out conditions left
   out, and a test set at the held-out conditions
   ([`training_set`][hrgjax.fog.compensation.training_set]).
3. **Networks:** Elman and MLP 2–7–1 per axis ([`fit`][hrgjax.fog.compensation.fit]), and
   the Elman trained end to end through the IMU output
   ([`fit_end_to_end`][hrgjax.fog.compensation.fit_end_to_end]); prediction RMSE against
   the noise-free error on the held-out test set.
4. **Alignment:** the scenario's record (the table vibrating during a stationary
   alignment), aligned raw, compensated by each network, and with the true error removed;
   heading and tilt errors against the analytic limit of the remaining (static) drift.
"""

from __future__ import annotations

import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import finite_number
from ..ins.constants import earth_rate_ned
from ..units import DEG, DEG_PER_H, G0
from . import compensation as cp
from .misalignment import TriadCalibration, calibrate
from .spectrum import psd, vibration_features
from .vibration import FogImu, VibrationSchedule, default_imu, simulate, to_body

HELD_OUT = ((10.0, 0.5), (10.0, 1.0))
"""The patent's test conditions (f [Hz], A [g])."""
FREQS_HZ = (5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 40.0)
AMPS_G = (0.25, 0.5, 0.75, 1.0, 1.25, 1.5)

SCENARIOS = {
    "10hz_1g": VibrationSchedule.constant(10.0, 1.0, 600.0),
    "10hz_0.5g": VibrationSchedule.constant(10.0, 0.5, 600.0),
    "on_off": VibrationSchedule(
        [60, 100, 60, 100, 60, 100, 120], [0, 10, 0, 10, 0, 10, 0], [0, 1.0, 0, 0.5, 0, 1.0, 0]
    ),
}
"""Alignment records (600 s, vibration along body z): the patent's Fig. 9 conditions,
switched on at the start, and an on/off sequence where the error's memory matters."""


def _positions():
    axes = np.concatenate([np.eye(3), -np.eye(3)])
    diag = np.array([[a, b, c] for a in (1, -1) for b in (1, -1) for c in (1, -1)]) / np.sqrt(3)
    return np.concatenate([axes, diag])


def multi_position(true: TriadCalibration, inputs, noise_std: float, key) -> TriadCalibration:
    """Estimate a triad from a multi-position test: sensor outputs of `true` at the
    body-frame `inputs` (n, 3), each averaged with white noise of `noise_std` (sensor
    units), fitted by [`calibrate`][hrgjax.fog.misalignment.calibrate]."""
    inputs = jnp.asarray(inputs)
    s = true.sensor(inputs) + noise_std * jax.random.normal(key, inputs.shape)
    return calibrate(np.asarray(inputs), np.asarray(s))


def calibrated(imu: FogImu, key, dwell_s: float = 100.0, lat_deg: float = 45.0) -> FogImu:
    """`imu` with its triad models replaced by multi-position estimates (module docstring):
    accelerometers at ±g along the axes and diagonals; gyros on a rate table at ±20 °/s
    about the same directions plus Earth rate (table level, axis x north); `dwell_s` [s]
    per position sets the averaging noise."""
    dwell_s, lat_deg = (
        finite_number("dwell_s", dwell_s, "s"),
        finite_number("lat_deg", lat_deg, "°"),
    )
    if not dwell_s > 0.0:  # its noise 1/√dwell_s read "b and s must be finite" at 0 or below
        raise ValueError(f"dwell_s must be > 0 s (the time per position); got {dwell_s:g}")
    if not -90.0 <= lat_deg <= 90.0:  # 4000 read "lat = 69.8 rad … is in radians here"
        raise ValueError(
            f"lat_deg must be the table's latitude in degrees, -90 … 90; got {lat_deg:g}"
        )
    ka, kg = jax.random.split(key)
    p = _positions()
    acc = multi_position(imu.accel, p * G0, float(imu.vrw) / np.sqrt(dwell_s), ka)
    w_e = np.asarray(earth_rate_ned(jnp.asarray(lat_deg * DEG)))
    gyr = multi_position(imu.gyro, p * 20.0 * DEG + w_e, float(imu.arw) / np.sqrt(dwell_s), kg)
    return eqx.tree_at(lambda m: (m.gyro, m.accel), imu, (gyr, acc))


def run(
    scenario: str = "10hz_1g", *, key: jax.Array, epochs: int = 1000, imu: FogImu | None = None,
    freqs_hz=FREQS_HZ, amps_g=AMPS_G, held_out=HELD_OUT, fs: float = 200.0,
    window_s: float = 2.0, log=None,
) -> dict:  # fmt: skip
    """Run the pipeline (module docstring) on `scenario` (a key of `SCENARIOS` or a
    [`VibrationSchedule`][hrgjax.fog.vibration.VibrationSchedule]). `epochs` defaults to
    1000: the patent's 120 leave the Elman network short of convergence on this error model
    (`benchmarks/vibration.py` compares both).

    **Returns** a dict with the DESIGN keys `heading_error_deg` {raw, compensated} and
    `prediction_rmse` {elman, mlp, none} [°/h], plus `compensated_mlp`, `perfect` (true
    error removed) and `compensated_end_to_end` headings, `tilt_error_deg`,
    `heading_limit_deg` {remaining_drift, raw}, `prediction_rmse.elman_end_to_end`,
    `features` (the scenario record's PSD peak,
    [`scenario_features`][hrgjax.fog.study.scenario_features]: None where it vibrates but
    is not measurable), `calibration` (the estimated angles against the truth [arcsec]),
    `train_s` and, under `"_figures"`, arrays for
    [`vibration_figure`][hrgjax.plots.vibration_figure]."""
    log = log or (lambda msg: None)
    if isinstance(scenario, str):
        if scenario not in SCENARIOS:
            raise ValueError(f"unknown scenario {scenario!r}; known: {tuple(SCENARIOS)}")
        name, schedule = scenario, SCENARIOS[scenario]
    else:
        name, schedule = "custom", scenario
    if int(epochs) < 1:
        raise ValueError(f"epochs must be >= 1; got {epochs}")
    true_imu = default_imu() if imu is None else imu
    k_cal, k_tr, k_te, k_rec, k_e, k_m, k_x, k_fit = jax.random.split(key, 8)

    log("calibration: multi-position estimates of both triads")
    est = calibrated(true_imu, k_cal)
    log("samples: training grid and held-out test set")
    conds = cp.grid(freqs_hz, amps_g, exclude=held_out)
    kw = dict(fs=fs, window_s=window_s, model=est)  # the pipeline knows only the estimates
    train = cp.training_set(true_imu, conds, key=k_tr, **kw)
    test = cp.training_set(true_imu, held_out, key=k_te, **kw)

    nets, hist, train_s = {}, {}, {}
    for label, kind, fit, k_net in (
        ("elman", "elman", cp.fit, k_e),
        ("mlp", "mlp", cp.fit, k_m),
        ("elman_end_to_end", "elman", None, k_x),
    ):
        log(f"training: {label}, {epochs} epochs")
        c = cp.VibrationCompensator(kind, key=k_net)
        t0 = time.perf_counter()
        if fit is None:
            c, h = cp.fit_end_to_end(c, est, train, key=k_fit, epochs=epochs, test=test)
        else:
            c, h = fit(c, train, key=k_fit, epochs=epochs, test=test)
        jax.block_until_ready(h)
        train_s[label] = time.perf_counter() - t0
        nets[label], hist[label] = c, {k: np.asarray(v) for k, v in h.items()}
    rmse = {k: float(cp.rmse(c, test)) / DEG_PER_H for k, c in nets.items()}
    rmse["none"] = float(cp.rmse(None, test)) / DEG_PER_H

    log(f"alignment: scenario {name}")
    rec = simulate(true_imu, schedule, fs=fs, key=k_rec)
    fine = dict(arw=float(true_imu.arw), vrw=float(true_imu.vrw))
    runs = {"raw": rec.gyro, "perfect": rec.gyro - rec.gyro_error}
    for label, c in nets.items():
        runs[label] = cp.compensate(c, est, rec, window_s=window_s)[0]
    results, errors = {}, {}
    for label, g in runs.items():
        results[label], errors[label] = cp.align_record(est, rec, g, **fine)
    eps = to_body(est.gyro, true_imu.gyro.bias)
    nab = to_body(est.accel, true_imu.accel.bias)
    mean_vib = to_body(est.gyro, jnp.mean(rec.gyro_error, axis=0))
    limit = {
        "remaining_drift": cp.heading_limit_deg(eps, nab, rec.c_bn, rec.lat),
        "raw": cp.heading_limit_deg(eps + mean_vib, nab, rec.c_bn, rec.lat),
    }
    acc_b = to_body(est.accel, rec.accel)
    feats = np.asarray(vibration_features(acc_b, fs, window_s))
    names = {"elman": "compensated", "mlp": "compensated_mlp",
             "elman_end_to_end": "compensated_end_to_end"}  # fmt: skip
    out = {
        "scenario": name,
        "heading_error_deg": {names.get(k, k): float(e[0]) for k, e in errors.items()},
        "tilt_error_deg": {names.get(k, k): [float(e[1]), float(e[2])] for k, e in errors.items()},
        "heading_limit_deg": limit,
        "prediction_rmse": rmse,
        "prediction_rmse_unit": "deg/h",
        "features": scenario_features(feats),
        "calibration": {
            "gyro_angles_error_arcsec": (
                np.asarray(est.gyro.angles - true_imu.gyro.angles) / DEG * 3600
            ).tolist(),
            "gyro_angles_std_arcsec": (np.asarray(est.gyro.angles_std) / DEG * 3600).tolist(),
        },  # fmt: skip
        "epochs": int(epochs),
        "train_s": train_s,
    }
    f, p = psd(acc_b[:, 2] / G0, fs, 1024)
    # its own noise: k_rec's would make the rest record the scenario's first minute again
    rest = simulate(true_imu, VibrationSchedule.constant(0.0, 0.0, 60.0), fs=fs,
                    key=jax.random.fold_in(k_rec, 1))  # fmt: skip
    _, p0 = psd(to_body(est.accel, rest.accel)[:, 2] / G0, fs, 1024)
    test_pred = {k: np.asarray(jax.vmap(c)(test.features)) / DEG_PER_H for k, c in nets.items()}
    out["_figures"] = {
        "t": np.asarray(rec.t), "accel_z_g": np.asarray(acc_b[:, 2]) / G0,
        "vibration_start_s": float(rec.t[int(np.argmax(np.asarray(rec.amp_g) > 0))]),
        "psd_f": np.asarray(f), "psd": np.asarray(p), "psd_rest": np.asarray(p0),
        "history": hist, "test_truth": np.asarray(test.truth) / DEG_PER_H,
        "test_pred": test_pred, "test_conditions": np.asarray(test.conditions),
        "window_s": window_s,
        "align_t": np.asarray(results["raw"].t),
        "align_heading": {names.get(k, k): np.asarray(r.history_deg[:, 0]) for k, r in results.items()},
        "true_heading": float(np.degrees(np.arctan2(rec.c_bn[1, 0], rec.c_bn[0, 0]))),
        "limit": limit, "scenario": name,
    }  # fmt: skip
    return out


def scenario_features(features) -> dict:
    """What `run` reports of a record's window features (K, 2) [Hz, g]
    ([`vibration_features`][hrgjax.fog.spectrum.vibration_features]): `freq_hz` and `amp_g`,
    the medians over the measured vibrating windows; 0.0 for a record at rest throughout;
    None when it vibrates but no window is measurable (a tone too near DC or Nyquist: NaN
    features — 0.0 read as rest); `windows_not_measurable`, their count."""
    x = np.asarray(features, dtype=float).reshape(-1, 2)
    nan, on = np.isnan(x).any(axis=1), x[:, 1] > 0
    stat = lambda v: float(np.median(v[on])) if on.any() else (None if nan.any() else 0.0)  # noqa: E731
    return {"freq_hz": stat(x[:, 0]), "amp_g": stat(x[:, 1]),
            "windows_not_measurable": int(nan.sum())}  # fmt: skip


def table(result: dict) -> str:
    """A markdown table of the headings, limits and prediction RMSEs."""
    h, r, lim = result["heading_error_deg"], result["prediction_rmse"], result["heading_limit_deg"]
    ft = result["features"]
    seen = (
        f"vibration {ft['freq_hz']:.2f} Hz, {ft['amp_g']:.3f} g (PSD peak)"
        if ft["freq_hz"] is not None
        else "vibration not measurable (a tone within 2 bins of DC or 1 of Nyquist)"
    )
    rows = [
        f"scenario {result['scenario']}: {seen}; {result['epochs']} epochs",
        "",
        "| alignment | heading error [°] | tilt errors [°] |",
        "|---|---|---|",
    ]
    for k, v in h.items():
        t = result["tilt_error_deg"][k]
        rows.append(f"| {k} | {v:+.4f} | {t[0]:+.4f}, {t[1]:+.4f} |")
    rows.append(f"| analytic limit, remaining drift | {lim['remaining_drift']:+.4f} | |")
    rows.append(f"| analytic limit, raw drift | {lim['raw']:+.4f} | |")
    rows += ["", "| prediction (held-out) | RMSE [°/h] | train [s] |", "|---|---|---|"]
    for k, v in r.items():
        ts = result["train_s"].get(k)
        rows.append(f"| {k} | {v:.4f} | {'' if ts is None else f'{ts:.1f}'} |")
    return "\n".join(rows)
