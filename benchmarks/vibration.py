"""FOG vibration compensation (issue 7 targets, seed 003).

1. Training time for 120 epochs on the full grid (7 frequencies × 6 amplitudes less the two
   held-out conditions), Elman and MLP side by side (compile included and excluded).
2. For 120 and 1000 epochs and several seeds: held-out prediction RMSE of the Elman network,
   the MLP, the Elman trained end to end and no compensation; then the heading and tilt
   errors of the alignment on each scenario, raw, compensated by each network and with the
   true error removed, against the analytic limit of the remaining drift.

The pipeline is `hrgjax.fog.study.run`'s, with the training shared across scenarios.
Writes `out/vibration.json`. Usage: `.venv/bin/python benchmarks/vibration.py [--quick]`.
"""

import json
import sys
import time
from pathlib import Path

import jax
import numpy as np
from _common import machine, report

from hrgjax.fog import compensation as cp
from hrgjax.fog import study
from hrgjax.fog import vibration as vb
from hrgjax.units import DEG_PER_H

QUICK = "--quick" in sys.argv
SEEDS = (0,) if QUICK else (0, 1, 2)
EPOCHS = (120,) if QUICK else (120, 1000)


def timed(fn):
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    return time.perf_counter() - t0, out


def main():
    print(f"# FOG vibration compensation ({machine()})\n")
    imu = vb.default_imu()
    out = {"machine": machine(), "runs": []}

    # 1. training time, 120 epochs, shared data
    est = study.calibrated(imu, jax.random.key(100))
    conds = cp.grid(study.FREQS_HZ, study.AMPS_G, exclude=study.HELD_OUT)
    t_data, (train, test) = timed(lambda: (
        cp.training_set(imu, conds, key=jax.random.key(101), model=est),
        cp.training_set(imu, study.HELD_OUT, key=jax.random.key(102), model=est),
    ))  # fmt: skip
    n_seq, n_win = train.features.shape[:2]
    print(f"training set: {n_seq} sequences × {n_win} windows of 2 s, built in {t_data:.1f} s\n")
    rows = {}
    for kind in cp.KINDS:
        net = cp.VibrationCompensator(kind, key=jax.random.key(0))
        t = {}
        for ep in (120, 240):  # each fit compiles its own loop: the difference is the run
            t[ep], _ = timed(lambda net=net, ep=ep: cp.fit(net, train, key=jax.random.key(1),
                                                           epochs=ep)[1])  # fmt: skip
        per_epoch = (t[240] - t[120]) / 120
        rows[kind] = (t[120], per_epoch, t[120] - 120 * per_epoch)
    print("| network | 120 epochs [s] | per epoch [ms] | compile (≈) [s] |")
    print("|---|---|---|---|")
    for kind, (t120, pe, comp) in rows.items():
        print(f"| {kind} 2–7–1 ×3 | {t120:.2f} | {1e3 * pe:.1f} | {comp:.2f} |")
    ratio = rows["elman"][1] / rows["mlp"][1]
    print(f"\nElman / MLP time per epoch: {ratio:.1f}× (the recurrence is a scan over windows)\n")
    out["train_120_s"] = {k: {"total": a, "per_epoch": p, "compile": c}
                          for k, (a, p, c) in rows.items()}  # fmt: skip

    # 2. accuracy and alignment
    records = {
        name: vb.simulate(imu, sch, fs=200.0, key=jax.random.key(200 + i))
        for i, (name, sch) in enumerate(study.SCENARIOS.items())
    }
    fine = dict(arw=float(imu.arw), vrw=float(imu.vrw))
    raw = {}
    for name, rec in records.items():
        raw[name] = cp.align_record(est, rec, **fine)[1]
        raw[name + "/perfect"] = cp.align_record(est, rec, rec.gyro - rec.gyro_error, **fine)[1]
    eps = vb.to_body(est.gyro, imu.gyro.bias)
    nab = vb.to_body(est.accel, imu.accel.bias)
    limit = cp.heading_limit_deg(eps, nab, records["10hz_1g"].c_bn, records["10hz_1g"].lat)
    for epochs in EPOCHS:
        for seed in SEEDS:
            k = jax.random.split(jax.random.key(seed), 4)
            nets = {
                "elman": cp.fit(cp.VibrationCompensator("elman", key=k[0]), train, key=k[3],
                                epochs=epochs)[0],
                "mlp": cp.fit(cp.VibrationCompensator("mlp", key=k[1]), train, key=k[3],
                              epochs=epochs)[0],
                "elman_end_to_end": cp.fit_end_to_end(
                    cp.VibrationCompensator("elman", key=k[2]), est, train, key=k[3],
                    epochs=epochs)[0],
            }  # fmt: skip
            rmse = {n: float(cp.rmse(c, test)) / DEG_PER_H for n, c in nets.items()}
            rmse["none"] = float(cp.rmse(None, test)) / DEG_PER_H
            heading = {}
            for name, rec in records.items():
                h = {"raw": float(raw[name][0]), "perfect": float(raw[name + "/perfect"][0])}
                for n, c in nets.items():
                    g, _ = cp.compensate(c, est, rec)
                    h[n] = float(cp.align_record(est, rec, g, **fine)[1][0])
                heading[name] = h
            out["runs"].append({"epochs": epochs, "seed": seed, "prediction_rmse_dph": rmse,
                                "heading_error_deg": heading})  # fmt: skip
            print(f"epochs {epochs}, seed {seed}: RMSE [°/h] " + ", ".join(
                f"{n} {v:.4f}" for n, v in rmse.items()), flush=True)  # fmt: skip

    print(f"\nheading limit of the remaining (static) drift: {limit:+.4f}°\n")
    for epochs in EPOCHS:
        runs = [r for r in out["runs"] if r["epochs"] == epochs]
        print(f"## {epochs} epochs ({len(runs)} seeds: mean and range)\n")
        print("| held-out RMSE [°/h] | " + " | ".join(runs[0]["prediction_rmse_dph"]) + " |")
        print("|---|" + "---|" * len(runs[0]["prediction_rmse_dph"]))
        cells = []
        for n in runs[0]["prediction_rmse_dph"]:
            v = np.array([r["prediction_rmse_dph"][n] for r in runs])
            cells.append(f"{v.mean():.4f} [{v.min():.4f}, {v.max():.4f}]")
        print("| | " + " | ".join(cells) + " |\n")
        cols = ["raw", "elman", "mlp", "elman_end_to_end", "perfect"]
        print("| heading error [°] | " + " | ".join(cols) + " |")
        print("|---|" + "---|" * len(cols))
        for name in records:
            cells = []
            for col in cols:
                v = np.array([r["heading_error_deg"][name][col] for r in runs])
                cells.append(f"{v.mean():+.3f} [{v.min():+.3f}, {v.max():+.3f}]"
                             if np.ptp(v) > 0 else f"{v.mean():+.3f}")  # fmt: skip
            print(f"| {name} | " + " | ".join(cells) + " |")
        print()
        rmse = {n: np.mean([r["prediction_rmse_dph"][n] for r in runs]) for n in ("elman", "mlp")}
        none = np.mean([r["prediction_rmse_dph"]["none"] for r in runs])
        for n, v in rmse.items():
            report(f"{n} held-out prediction RMSE, {epochs} epochs", v, "°/h",
                   "uncompensated / this", none / v, "Elman best")  # fmt: skip
        for name in records:
            raw_h = np.mean([r["heading_error_deg"][name]["raw"] for r in runs])
            comp = np.mean([r["heading_error_deg"][name]["elman"] for r in runs])
            report(f"{name}: heading error after Elman compensation, {epochs} epochs", comp,
                   "°", "raw / compensated (magnitudes)", abs(raw_h) / abs(comp),
                   f"toward the limit {limit:+.3f}°")  # fmt: skip
    out["heading_limit_deg"] = limit
    Path("out").mkdir(exist_ok=True)
    Path("out/vibration.json").write_text(json.dumps(out, indent=2))
    print("wrote out/vibration.json")


if __name__ == "__main__":
    main()
