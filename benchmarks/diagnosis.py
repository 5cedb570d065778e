"""Three-INS fault diagnosis (issue 6 targets, seed 002): every method on every scenario, and
the filter bank's throughput.

1. For each scenario (stationary; 3 g and 10 g east with an accelerometer fault at 3700 s;
   ξ-, ζ- and η-gyro faults) the comparison table of `hrgjax.diagnosis.compare` — detection time,
   false alarms, wrong diagnoses, cost per step — printed beside the thesis's figures.
2. Filter-bank throughput vmapped over Monte Carlo runs, side by side in one run: the full
   interacting bank (covariances recursed and mixed every step), the gain-schedule IMM, and
   the exact independent bank with gains computed ahead; steps/s against the ≥ 1e5 target
   and the thesis's 0.04 s per step (MATLAB).

Writes `out/diagnosis.json` and `out/diagnosis_<scenario>.png` (decision traces).
Usage: `.venv/bin/python benchmarks/diagnosis.py [--quick] [--scenarios a,b]`;
`--throughput` runs part 2 alone (about a minute). The gain-schedule IMM's agreement with the
full IMM: `benchmarks/diagnosis_agreement.py`; whether the banks' probabilities are
calibrated (Monte Carlo with known truth, before/after the calibration fixes):
`benchmarks/diagnosis_calibration.py`.
"""

import dataclasses
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
from _common import best_of, machine, report

from hrgjax.diagnosis import compare as cp
from hrgjax.diagnosis import complex as cx
from hrgjax.diagnosis import filter_bank as fb
from hrgjax.plots import diagnosis_figure

QUICK = "--quick" in sys.argv
ARG = sys.argv[sys.argv.index("--scenarios") + 1] if "--scenarios" in sys.argv else None


def throughput(runs=64, k_len=4000):
    sc = cp.SCENARIOS["stationary"]
    ins = sc.ins()
    zs = cp._measure(ins, sc, jax.random.split(jax.random.key(1), runs), 1e-9)[:, :k_len]
    bank = cx.fault_bank(ins, sc.sensor, sc.dt, switch_prob=1e-4)
    gb = fb.GainBank.from_bank(bank, 1000)
    full = jax.jit(jax.vmap(lambda z: fb.run_bank(bank, z, interacting=True)[1]))
    imm = jax.jit(lambda z: fb.run_gains(gb, z, interacting=True)[1])
    ind = jax.jit(lambda z: fb.run_gains(gb, z, interacting=False)[1])
    n = zs.shape[0] * zs.shape[1]
    out = {}
    for name, f in (
        ("full IMM", full),
        ("gain-schedule IMM", imm),
        ("independent, gains ahead", ind),
    ):
        jax.block_until_ready(f(zs))
        t = best_of(lambda f=f: f(zs), repeat=3)
        out[name] = n / t
    print(f"\nFilter-bank throughput ({runs} runs × {zs.shape[1]} steps, {bank.phi.shape[1]} states,"
          f" 4 hypotheses, vmapped):")  # fmt: skip
    for name, v in out.items():
        print(f"  {name:>26}: {v:10.3g} steps/s  ({v / 1e5:6.2f}× the 1e5 target; "
              f"{0.04 * v:8.0f}× the thesis's 0.04 s/step)")  # fmt: skip
    print(f"  gain-schedule IMM / full IMM: {out['gain-schedule IMM'] / out['full IMM']:.1f}×")
    for name, v in out.items():
        report(f"filter-bank throughput, {name}", v, "steps/s", "vs the 1e5 steps/s target",
               v / 1e5, "≥ 1e5 steps/s")  # fmt: skip
    return out


def main():
    print(f"machine: {machine()}")
    if "--throughput" in sys.argv:
        throughput(runs=16 if QUICK else 64)
        return
    names = (
        ARG.split(",")
        if ARG
        else ["stationary", "accel3g", "accel10g", "gyro", "gyro_zeta", "gyro_eta"]
    )
    results = {}
    Path("out").mkdir(exist_ok=True)
    for name in names:
        sc = cp.SCENARIOS.get(name) or dataclasses.replace(
            cp.SCENARIOS["gyro"], name=name, sensor=name
        )
        t0 = time.perf_counter()
        res = cp.compare(sc, key=jax.random.key(0), n_faulty=6 if QUICK else 12,
                         n_healthy=3 if QUICK else 6, traces=True,
                         predictor_steps=10 if QUICK else 20)  # fmt: skip
        traces = res.pop("traces")
        print()
        print(cp.table(res))
        print(f"({time.perf_counter() - t0:.0f} s including training)")
        print(f"wrote {diagnosis_figure(traces, f'out/diagnosis_{name}.png', title=name)}")
        results[name] = res
        for r in res["methods"]:
            if r["detection_time_s"] is not None:
                report(f"{name}: {r['name']} median detection time", r["detection_time_s"], "s",
                       "detected share", r["detected"])  # fmt: skip
    results["throughput_steps_per_s"] = throughput(runs=16 if QUICK else 64)
    results["machine"] = machine()
    Path("out/diagnosis.json").write_text(json.dumps(results, indent=2))
    print("wrote out/diagnosis.json")


if __name__ == "__main__":
    jnp.zeros(1)
    main()
