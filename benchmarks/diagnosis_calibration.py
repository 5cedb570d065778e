"""Are the fault-diagnosis bank's probabilities calibrated? Monte Carlo with known truth, the
package's banks before and after the calibration fixes, side by side (docs/diagnosis.md,
"Calibration"). North accelerometer at rest, dt = 1 s, 300-s records, threshold 0.9.

"before" = `fault_bank`'s former default `fault_walk=1e-8`, no model-fit test (what
`compare` runs, as `compare` builds it: `switch_prob=1e-4`); "after" = `fault_walk=1e-9` (the
new default) and the model-fit test at `fit_level=FIT_LEVEL` (decision −2 where the most
probable hypothesis fails it).

1. A fault present from the first sample, records drawn from the bank's own prior
   (hypothesis uniform over S0 … S3, size ~ N(0, fault_sigma²); uniform prior). The
   independent bank with switch_prob 0 and fault_walk 0 is then the exact posterior: the
   reference. Mean reported max-p at the end against the accuracy of the argmax, and the
   reliability table (mean max-p against the observed share right, per probability bin,
   all steps after the fifth).
2. Records that start healthy (prior 0.97 on S0) with a fault of 0, 3e-8, 5e-8 or 2e-7 at
   150 s: false alarms, post-onset steps right / S0 / "does not fit", and the decided steps'
   wrong share against the share the probabilities claim.
3. Model mismatch on healthy records: measurement noise 3× and 10× `meas_sigma`, sensor
   errors 2× nominal: false alarms and "does not fit".
4. The model-fit test's false "does not fit" rate under the matched model: the exact
   Kalman filter's (independent bank, S0) at levels 1e-2 and 1e-3, and the IMMs' −2 rate.

5. (`--from-t0` alone) The measured limit of the IMMs (docs/diagnosis.md): a fault present
   from sample 0 under a uniform prior, at the current settings (`switch_prob` 1e-4,
   `fault_walk` 1e-9, no fit test): steps after the fifth at max-p > 0.99 and the share of
   them naming the wrong hypothesis — records from the bank's prior, and a fixed ±2e-7
   fault in INS (run mod 3).

Usage: `.venv/bin/python benchmarks/diagnosis_calibration.py [--quick | --from-t0]` (about
8 min on 2 cores; `--quick` a third of the runs; `--from-t0` part 5 alone, about 2 min).
"""

import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import machine  # x64 on

from hrgjax.diagnosis import complex as cx
from hrgjax.diagnosis import filter_bank as fb
from hrgjax.ins.platform import FAULTS, Fault, PlatformINS, simulate

QUICK = "--quick" in sys.argv
FROM_T0 = "--from-t0" in sys.argv
K = 300
INS = PlatformINS()
COL = FAULTS.index("accel_y")
HEALTHY_PRIOR = jnp.asarray([0.97, 0.01, 0.01, 0.01])
UNIFORM = jnp.full(4, 0.25)
BINS = (0.0, 0.5, 0.9, 0.99, 0.999, 1.0 + 1e-12)


def records(ins, keys, e, t_fault, sigma):
    """(R, K, 2) measurements: INS i's fault e[r, i] from t_fault[r, i] [s], white noise sigma."""

    def one(key, e3, t3):
        k_sim, k_noise = jax.random.split(key)
        f = Fault(jnp.zeros((3, 6)).at[:, COL].set(e3), t3)
        run = lambda k, f: simulate(ins, dt=1.0, n_steps=K, key=k, fault=f)[2]
        z = cx.measurements(jax.vmap(run)(jax.random.split(k_sim, 3), f), 1.0, "accel_y", ins)
        return z + sigma * jax.random.normal(k_noise, z.shape)

    return np.asarray(jax.jit(jax.vmap(one))(keys, jnp.asarray(e), jnp.asarray(t_fault)))


def detectors(walk, fit_level, switch=1e-4):
    """Full and gain-schedule IMM of one bank configuration: name → fn(zs, prior) →
    (probabilities, decisions)."""
    bank = cx.fault_bank(INS, "accel_y", 1.0, switch_prob=switch, fault_walk=walk)
    gb = fb.GainBank.from_bank(bank, K)
    kw = dict(interacting=True, fit_level=fit_level)
    full = jax.jit(jax.vmap(lambda z, p: fb.run_bank(bank, z, prior=p, **kw)[:2], (0, None)))
    return {"full IMM": full, "gain IMM": lambda z, p: fb.run_gains(gb, z, prior=p, **kw)}


BEFORE = dict(walk=1e-8, fit_level=None)
AFTER = dict(walk=1e-9, fit_level=fb.FIT_LEVEL)


def reliability(probs, right):
    """Rows (bin, n, mean max-p, observed share right)."""
    p, r = probs.ravel(), right.ravel()
    rows = []
    for lo, hi in zip(BINS[:-1], BINS[1:], strict=True):
        m = (p >= lo) & (p < hi)
        rows.append((f"[{lo:.3f}, {min(hi, 1.0):.3f}{']' if hi > 1 else ')'}", int(m.sum()),
                     p[m].mean() if m.any() else np.nan, r[m].mean() if m.any() else np.nan))  # fmt: skip
    return rows


def part1(n):
    print(f"\n1. Fault present from the first sample, {n} records from the bank's prior, "
          f"uniform prior over S0…S3")  # fmt: skip
    rng = np.random.default_rng(1)
    truth = np.arange(n) % 4
    e, t = np.zeros((n, 3)), np.full((n, 3), np.inf)
    rows = np.flatnonzero(truth > 0)
    e[rows, truth[rows] - 1] = rng.normal(0.0, 3e-7, rows.size)
    t[rows, truth[rows] - 1] = 0.0
    z = records(INS, jax.random.split(jax.random.key(5), n), e, t, 1e-9)
    exact = cx.fault_bank(INS, "accel_y", 1.0, switch_prob=0.0, fault_walk=0.0)
    default = cx.fault_bank(INS, "accel_y", 1.0)  # switch_prob 1e-5, fault_walk 1e-9
    ind = lambda b: jax.jit(jax.vmap(lambda z: fb.run_bank(b, z, prior=UNIFORM, floor=1e-12)[:2]))
    runs = {"exact posterior (independent, switch 0, walk 0)": ind(exact)(z),
            "after: independent bank, fault_bank defaults": ind(default)(z)}  # fmt: skip
    for tag, cfg in (("before", BEFORE), ("after", AFTER)):
        for name, fn in detectors(cfg["walk"], cfg["fit_level"]).items():
            runs[f"{tag}: {name}"] = fn(z, UNIFORM)
    table = {}
    print(f"  {'detector':50s} {'mean max-p':>10s} {'accuracy':>9s} {'decided':>8s} "
          f"{'wrong|decided':>13s} {'unfit':>6s}   (at the last step)")  # fmt: skip
    for name, (p, d) in runs.items():
        p, d = np.asarray(p), np.asarray(d)
        right = p.argmax(-1) == truth[:, None]
        dk = d[:, -1]
        dec = dk >= 0
        wrong = np.mean(dk[dec] != truth[dec]) if dec.any() else np.nan
        print(f"  {name:50s} {p[:, -1].max(-1).mean():10.3f} {right[:, -1].mean():9.3f} "
              f"{dec.mean():8.2f} {wrong:13.3f} {np.mean(dk == -2):6.2f}")  # fmt: skip
        table[name] = reliability(p.max(-1)[:, 5:], right[:, 5:])
    print("  reliability, all steps after the fifth: n / mean max-p / observed share right")
    names = list(table)
    print("  " + f"{'bin':16s}" + "".join(f" | {nm.split(':')[0][:28]:>28s}" for nm in names))
    short = ["exact", "independent, defaults", "before full", "before gain", "after full",
             "after gain"]  # fmt: skip
    print("  " + f"{'':16s}" + "".join(f" | {s:>28s}" for s in short))
    for i in range(len(BINS) - 1):
        cells = [table[nm][i] for nm in names]
        print("  " + f"{cells[0][0]:16s}" + "".join(
            f" | {c[1]:7d} {c[2]:9.4f} {c[3]:9.4f}" for c in cells))  # fmt: skip


def part2(n):
    print(f"\n2. Healthy start (prior 0.97 on S0), fault at 150 s in INS (run mod 3), {n} records "
          "per size")  # fmt: skip
    fi = np.arange(n) % 3
    dets = {tag: detectors(cfg["walk"], cfg["fit_level"]) for tag, cfg in
            (("before", BEFORE), ("after", AFTER))}  # fmt: skip
    k_on = 149  # measurement k is navigation step k + 2; the fault acts from step 151
    print(f"  {'size':>8s} {'detector':18s} {'FA':>6s} {'right':>6s} {'S0':>6s} {'unfit':>6s} "
          f"{'wrong|decided':>13s} {'claimed':>8s}  reliability [0.999, 1]: n, observed")  # fmt: skip
    for size, seed in ((0.0, 31), (3e-8, 13), (5e-8, 32), (2e-7, 12)):
        e, t = np.zeros((n, 3)), np.full((n, 3), np.inf)
        e[np.arange(n), fi], t[np.arange(n), fi] = size, 150.0
        z = records(INS, jax.random.split(jax.random.key(seed), n), e, t, 1e-9)
        steps = np.arange(z.shape[1])[None]
        truth = np.where((steps >= k_on) & (size != 0), fi[:, None] + 1, 0)
        post, quiet = truth > 0, truth == 0
        for tag, ds in dets.items():
            for name, fn in ds.items():
                p, d = (np.asarray(a) for a in fn(z, HEALTHY_PRIOR))
                dec = d >= 0
                pm = p.max(-1)
                rel = reliability(pm, p.argmax(-1) == truth)[-1]
                msg = f"  {size:8.1e} {tag + ' ' + name:18s} {np.mean(d[quiet] > 0):6.3f} "
                if post.any():
                    msg += (f"{np.mean(d[post] == truth[post]):6.3f} {np.mean(d[post] == 0):6.3f} "
                            f"{np.mean(d[post] == -2):6.3f} ")  # fmt: skip
                else:
                    msg += f"{'–':>6s} {'–':>6s} {np.mean(d == -2):6.3f} "
                msg += (f"{np.mean(d[dec] != truth[dec]):13.3f} {1 - pm[dec].mean():8.4f}  "
                        f"{rel[1]:6d}, {rel[3]:.3f}")  # fmt: skip
                print(msg, flush=True)


def part3(n):
    print(f"\n3. Model mismatch, healthy records ({n} each), prior 0.97 on S0: share of steps "
          "naming a fault (FA) and decided −2 (unfit)")  # fmt: skip
    cases = (("matched", INS, 1e-9), ("meas. noise 3e-9 (3x)", INS, 3e-9),
             ("meas. noise 1e-8 (10x)", INS, 1e-8),
             ("sensor errors 2x", PlatformINS(accel_sigma=2e-7, gyro_sigma=2e-7), 1e-9))  # fmt: skip
    cfgs = (("before", BEFORE), ("after, no fit test", dict(walk=1e-9, fit_level=None)),
            ("after", AFTER))  # fmt: skip
    dets = {tag: detectors(cfg["walk"], cfg["fit_level"]) for tag, cfg in cfgs}
    no_e, no_t = np.zeros((n, 3)), np.full((n, 3), np.inf)
    for label, ins, sigma in cases:
        z = records(ins, jax.random.split(jax.random.key(7), n), no_e, no_t, sigma)
        cells = []
        for tag, ds in dets.items():
            for name, fn in ds.items():
                p, d = (np.asarray(a) for a in fn(z, HEALTHY_PRIOR))
                fa = d > 0
                pfa = p.max(-1)[fa].mean() if fa.any() else np.nan
                cells.append(f"{tag} {name}: FA {fa.mean():.3f} (p {pfa:.3f}), "
                             f"unfit {np.mean(d == -2):.3f}")  # fmt: skip
        print(f"  {label}:\n    " + "\n    ".join(cells), flush=True)


def part4(n):
    print(f"\n4. Model-fit test under the matched model ({n} healthy records × {K} steps): "
          "false 'does not fit' rate")  # fmt: skip
    no_e, no_t = np.zeros((n, 3)), np.full((n, 3), np.inf)
    z = records(INS, jax.random.split(jax.random.key(17), n), no_e, no_t, 1e-9)
    exact = cx.fault_bank(INS, "accel_y", 1.0, switch_prob=0.0, fault_walk=0.0)
    for window in (1, 10, fb.FIT_WINDOW):
        for level in (1e-2, 1e-3):
            f = jax.jit(jax.vmap(lambda z, w=window, lv=level: fb.run_bank(
                exact, z, fit_window=w, fit_level=lv, return_fit=True)[3]["fits"][:, 0]))  # fmt: skip
            print(f"  exact Kalman filter (S0), window {window:3d}, level {level:.0e}: "
                  f"{np.mean(~np.asarray(f(z))):.4f}")  # fmt: skip
    for name, fn in detectors(**AFTER).items():
        d = np.asarray(fn(z, HEALTHY_PRIOR)[1])
        print(f"  after {name} (window {fb.FIT_WINDOW}, level {fb.FIT_LEVEL:.0e}): decided −2 on "
              f"{np.mean(d == -2):.4f} of the steps")  # fmt: skip


def part5(n):
    print("\n5. Fault from sample 0, uniform prior, switch_prob 1e-4, fault_walk 1e-9: steps "
          "after the fifth at max-p > 0.99 and the share of them wrong")  # fmt: skip
    rng = np.random.default_rng(1)
    truth = np.arange(n) % 4
    e, t = np.zeros((n, 3)), np.full((n, 3), np.inf)
    rows = np.flatnonzero(truth > 0)
    e[rows, truth[rows] - 1] = rng.normal(0.0, 3e-7, rows.size)
    t[rows, truth[rows] - 1] = 0.0
    fi = np.arange(n // 2) % 3
    e2, t2 = np.zeros((n // 2, 3)), np.full((n // 2, 3), np.inf)
    e2[np.arange(n // 2), fi] = np.where(np.arange(n // 2) % 2, 2e-7, -2e-7)
    t2[np.arange(n // 2), fi] = 0.0
    sets = ((f"{n} records from the bank's prior", jax.random.key(5), e, t, truth),
            (f"{n // 2} records, ±2e-7 from sample 0", jax.random.key(6), e2, t2, fi + 1))  # fmt: skip
    exact = cx.fault_bank(INS, "accel_y", 1.0, switch_prob=0.0, fault_walk=0.0)
    dets = {"exact posterior": jax.jit(jax.vmap(
        lambda z, p: fb.run_bank(exact, z, prior=p, floor=1e-12)[:2], (0, None)))}  # fmt: skip
    dets.update(detectors(1e-9, None))
    for label, key, e_, t_, tr in sets:
        z = records(INS, jax.random.split(key, e_.shape[0]), e_, t_, 1e-9)
        print(f"  {label}:")
        for name, fn in dets.items():
            p = np.asarray(fn(z, UNIFORM)[0])[:, 5:]
            sure = p.max(-1) > 0.99
            wrong = p.argmax(-1) != tr[:, None]
            share = f"{wrong[sure].mean():.3f}" if sure.any() else "–"
            print(f"    {name:16s} steps {sure.sum():6d} of {sure.size}, wrong {share}", flush=True)


def main():
    print(f"machine: {machine()}")
    if FROM_T0:
        t0 = time.perf_counter()
        part5(96)
        print(f"\n({time.perf_counter() - t0:.0f} s)")
        return
    s = 3 if QUICK else 1
    t0 = time.perf_counter()
    part1(120 // s)
    part2(30 // s)
    part3(24 // s)
    part4(32 // s)
    print(f"\n({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
