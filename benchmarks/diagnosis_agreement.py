"""How closely the gain-schedule IMM (`GainBank` + `run_gains`) follows the full IMM
(`run_bank`, covariances recursed and mixed every step): the share of steps on which the two
decide the same (docs/diagnosis.md, "Gains computed ahead").

1. Per sensor (north accelerometer, ξ gyro, η gyro): 600-s runs at 1 s, `switch_prob` 1e-4,
   prior 0.97 on S0, measurement noise 1e-9 (R/g units); faults 2e-7 at 5, 20, 45 s,
   ±5e-8, 3e-8 and −2e-7 at 300 s, and healthy runs; 3 runs per case (keys 0–2, the fault in
   INS 1, 2, 3 in turn): 24 runs per sensor.
2. The `compare` scenarios (stationary, accel3g, accel10g, gyro): 4000-s runs, faults of
   1.5–3e-7 at 3700 s, 12 faulty and 6 healthy runs drawn as `hrgjax.diagnosis.compare` draws
   them (key 0): agreement on all steps and after the onset, and the faulty runs that hold
   the right INS at the end.

Usage: `.venv/bin/python benchmarks/diagnosis_agreement.py [--no-scenarios]` (about 2 min on
2 cores).
"""

import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import machine, report

from hrgjax.diagnosis import compare as cp
from hrgjax.diagnosis import complex as cx
from hrgjax.diagnosis import filter_bank as fb
from hrgjax.ins.platform import Fault, PlatformINS

PRIOR = jnp.asarray([0.97, 0.01, 0.01, 0.01])
SENSORS = ("accel_y", "gyro_xi", "gyro_eta")


def _runs(ins, sensor, dt, n_steps, key, meas_sigma, fault_ins, size, t_fault):
    """One run's noisy measurements (compare's draw: simulation key, then noise key)."""
    k_sim, k_noise = jax.random.split(key)
    if fault_ins is None:
        _, nav = cx.simulate_complex(ins, dt=dt, n_steps=n_steps, key=k_sim)
    else:
        f = Fault.on(sensor, 1.0, t_fault)
        f = Fault(f.e * size, f.t_fault)
        _, nav = cx.simulate_complex(ins, dt=dt, n_steps=n_steps, key=k_sim,
                                     fault_ins=fault_ins, fault=f)  # fmt: skip
    z = cx.measurements(nav, dt, sensor, ins)
    return z + meas_sigma * jax.random.normal(k_noise, z.shape)


_run = jax.jit(_runs, static_argnames=("sensor", "dt", "n_steps", "fault_ins"))


def _deciders(bank, n_gain):
    gb = fb.GainBank.from_bank(bank, n_gain)
    gain = jax.jit(lambda z: fb.run_gains(gb, z, interacting=True, prior=PRIOR)[1])
    full = jax.jit(jax.vmap(lambda z: fb.run_bank(bank, z, interacting=True, prior=PRIOR)[1]))
    return gain, full


def per_sensor(n_steps=600):
    ins = PlatformINS()
    cases = [(5.0, 2e-7), (20.0, 2e-7), (45.0, 2e-7), (300.0, 5e-8), (300.0, -5e-8),
             (300.0, 3e-8), (300.0, -2e-7), (None, 0.0)]  # fmt: skip
    out = {}
    print(f"Agreement per sensor ({len(cases)} cases × 3 runs, {n_steps} s at 1 s):")
    print("| sensor | same decision, all steps | worst run | post-onset steps naming the faulty "
          "INS: gain-schedule / full | per case |")  # fmt: skip
    print("|---|---|---|---|---|")
    for sensor in SENSORS:
        bank = cx.fault_bank(ins, sensor, 1.0, switch_prob=1e-4)
        gain, full = _deciders(bank, min(n_steps, 1000))
        zs, truth, onset = [], [], []
        for tf, size in cases:
            for s in range(3):
                fi = None if tf is None else s
                truth.append(0 if fi is None else fi + 1)
                onset.append(n_steps if tf is None else int(np.ceil(tf)) - 1)
                zs.append(_run(ins, sensor, 1.0, n_steps, jax.random.key(s), 1e-9, fi, size,
                               tf or 0.0))  # fmt: skip
        zs = jnp.stack(zs)
        d, f = np.asarray(gain(zs)), np.asarray(full(zs))
        same = d == f  # (runs, K)
        post = np.arange(d.shape[1])[None, :] >= np.asarray(onset)[:, None]
        right = [float(np.mean((x == np.asarray(truth)[:, None])[post])) for x in (d, f)]
        per_run = same.mean(axis=1)
        per_case = per_run.reshape(len(cases), 3).mean(axis=1)
        out[sensor] = float(same.mean())
        print(f"| {sensor} | {same.mean():.1%} | {per_run.min():.1%} | {right[0]:.1%} / "
              f"{right[1]:.1%} | "
              + " ".join(f"{v:.3f}" for v in per_case) + " |")  # fmt: skip
        report(f"gain-schedule vs full IMM agreement, {sensor}", 100 * same.mean(), "%")
    return out


def scenarios(names=("stationary", "accel3g", "accel10g", "gyro")):
    print("\nAgreement on the compare scenarios (12 faulty + 6 healthy runs, key 0):")
    print("| scenario | all steps | post-onset | right INS held at the end: gain / full |")
    print("|---|---|---|---|")
    out = {}
    for name in names:
        sc = cp.SCENARIOS[name]
        ins = sc.ins()
        n_steps = int(round(sc.duration / sc.dt))
        k_test, k_healthy, _, _, _, k_sizes = jax.random.split(jax.random.key(0), 6)
        nf, nh = 12, 6
        truth = np.r_[np.arange(nf) % 3 + 1, np.zeros(nh, int)]
        sizes = np.asarray(jax.random.uniform(k_sizes, (nf,), minval=sc.sizes[0],
                                              maxval=sc.sizes[1]))  # fmt: skip
        zs = [_run(ins, sc.sensor, sc.dt, n_steps, k, 1e-9, int(truth[i] - 1), sizes[i],
                   sc.t_fault) for i, k in enumerate(jax.random.split(k_test, nf))]  # fmt: skip
        zs += [_run(ins, sc.sensor, sc.dt, n_steps, k, 1e-9, None, 0.0, 0.0)
               for k in jax.random.split(k_healthy, nh)]  # fmt: skip
        zs = jnp.stack(zs)
        bank = cx.fault_bank(ins, sc.sensor, sc.dt, meas_sigma=1e-9, switch_prob=1e-4)
        gain, full = _deciders(bank, min(zs.shape[1], 1000))
        d, f = np.asarray(gain(zs)), np.asarray(full(zs))
        on = int(np.ceil(sc.t_fault / sc.dt)) - 1
        held = int(np.sum(d[:nf, -1] == truth[:nf])), int(np.sum(f[:nf, -1] == truth[:nf]))
        out[name] = float(np.mean(d == f))
        print(f"| {name} | {np.mean(d == f):.1%} | {np.mean(d[:nf, on:] == f[:nf, on:]):.1%} | "
              f"{held[0]}/{nf} / {held[1]}/{nf} |")  # fmt: skip
    return out


def main():
    print(f"machine: {machine()}")
    t0 = time.perf_counter()
    per_sensor()
    if "--no-scenarios" not in sys.argv:
        scenarios()
    print(f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
