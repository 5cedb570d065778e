"""The Kalman filters' small factorisations in plain XLA operations (`hrgjax._linalg`) against
LAPACK's, side by side: the LAPACK arm puts jaxlib's Cholesky kernels (potrf, trsm) where
`_linalg`'s now stand (the filters as they were also used LU solves, getrf, for the NIS, the
smoother's gain, the NEES and the filter bank's inverse).

Each arm runs in its own process, XLA:CPU's pool widened (`hg.widen_cpu_thread_pool`) so
that the LAPACK arm cannot wedge:

- `fly`: `ins.flights.fly`, 20 tactical-grade flights of 10 min at 20 Hz, one batch
  (docs/navigation.md's call on a shorter motion): filter, smoother, free inertial, NEES;
- `bank`: `diagnosis.filter_bank.run_bank` of 3 models over 2 000 steps, 64 records vmapped;
- `filter`: `kalman.kalman_filter` + `rts_smoother` of a 15-state, 6-measurement model over
  2 000 steps, 32 records vmapped; and one record alone (`single`: nothing batched, the
  case where LAPACK never wedges and its kernels cost the least);

each record with its own measurement noise, so that the covariances are batched too.

Best of 5 after the first call (which compiles); the first call's time too.

`--wedge [REV]`: instead, the docs' `fly` (the whole hour, 20 flights) with XLA:CPU's own
pool (`PJRT_NPROC` and `NPROC` unset: one thread per core; run it on a two-core machine),
`TRIES` times each under `LIMIT_S`, by this tree's hrgjax and by the filters as they were
(hrgjax at `REV`, default `BEFORE`, taken with `git archive`): does it finish? The filters as
they were sat idle in `lapack_dtrsm_ffi` → `ParallelBatchMap` (gdb, hrgjax/_threads.py). The
wedge is a race (two kernels must meet on the pool): a run of old filters may finish. The
LAPACK arm above is not the filters as they were, so it is not run here.

    .venv/bin/python benchmarks/filter_linalg.py            # ≈ 2 min on 2 cores
    .venv/bin/python benchmarks/filter_linalg.py --wedge [REV]   # ≈ 5–8 min
"""

import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

from _common import machine, report

LAPACK = r"""
# jaxlib's LAPACK Cholesky kernels where hrgjax._linalg's stand
import jax.numpy as jnp
from jax.scipy.linalg import cho_solve as _cs, solve_triangular
from hrgjax import kalman
from hrgjax.diagnosis import filter_bank
from hrgjax.ins import ekf

chol = lambda a: jnp.linalg.cholesky(a)
solve = lambda l, b: _cs((l, True), b)
whiten = lambda l, b: solve_triangular(l, b, lower=True)
for m in (kalman, ekf, filter_bank):
    for name, fn in (("cholesky", chol), ("cho_solve", solve), ("whiten", whiten)):
        if hasattr(m, name):
            setattr(m, name, fn)
"""

CHILD = r"""
import dataclasses, json, sys, time
arm, case = sys.argv[1], sys.argv[2]
if case != "wedge":
    import hrgjax as hg
    hg.widen_cpu_thread_pool()
import equinox as eqx, jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
import hrgjax as hg
print("hrgjax from", hg.__file__, file=sys.stderr, flush=True)
if arm == "lapack":
    exec(LAPACK)
from hrgjax import kalman
from hrgjax.diagnosis import filter_bank
from hrgjax.ins import ekf, flights, gnss, motion, sensors

def timed(fn, repeat=5):
    t0 = time.perf_counter(); jax.block_until_ready(fn()); first = time.perf_counter() - t0
    best = []
    for _ in range(repeat):
        t0 = time.perf_counter(); jax.block_until_ready(fn()); best.append(time.perf_counter() - t0)
    return first, min(best)

def fly_case(short, repeat):
    flight = motion.example()
    if short:  # the first 10 min: ground run, rotation, climb, level-off, 150 s of cruise
        segs = flight.segments[:5] + (dataclasses.replace(flight.segments[5], duration=150.0),)
        flight = dataclasses.replace(flight, segments=segs)
    truth = flight.truth(rate_hz=20.0)
    imu = sensors.preset("tactical")
    settings = ekf.LooselyCoupled(imu, gnss.Gnss(outages=((300.0, 360.0),)))
    fn = lambda: flights.fly(truth, imu, settings, key=jax.random.key(0), runs=20, chunk=20)
    out = timed(fn, repeat)
    return out + (float(fn().summary()["filter"]["horizontal_rms_m"]),)

def bank_case():
    rng = np.random.default_rng(0)
    n, m, k = 4, 2, 2000
    models = [(np.eye(n) + 0.01 * rng.normal(size=(n, n)), 1e-3 * np.eye(n), np.eye(m, n),
               0.1 * np.eye(m), np.zeros(n), np.eye(n)) for _ in range(3)]
    bank = filter_bank.Bank.build(models, switch_prob=0.01)
    zs = jnp.asarray(rng.normal(size=(64, k, m)))
    scale = jnp.linspace(0.5, 2.0, 64)  # each run its own noise: S and P batched too
    with_r = lambda s: eqx.tree_at(lambda b: b.r, bank, bank.r * s)
    run = jax.jit(jax.vmap(lambda z, s: filter_bank.run_bank(with_r(s), z)[0]))
    return timed(lambda: run(zs, scale))

def filter_case():
    rng = np.random.default_rng(1)
    n, m, k = 15, 6, 2000
    phi = jnp.asarray(np.eye(n) + 0.01 * rng.normal(size=(n, n)))
    qd, h, r = 1e-3 * jnp.eye(n), jnp.asarray(rng.normal(size=(m, n))), 0.1 * jnp.eye(m)
    prior = kalman.Gaussian(jnp.zeros(n), jnp.eye(n))
    zs = jnp.asarray(rng.normal(size=(32, k, m)))
    scale = jnp.linspace(0.5, 2.0, 32)  # each record its own noise: S and P batched too
    def one(z, s):
        xs, ps, ll = kalman.kalman_filter(prior, phi, qd, h, r * s, z)
        xs2, _, _ = kalman.rts_smoother(prior, phi, qd, h, r * s, z)
        return ll, xs2
    run = jax.jit(jax.vmap(one))
    single = jax.jit(one)  # one record, nothing batched (where LAPACK never wedges)
    return timed(lambda: run(zs, scale)), timed(lambda: single(zs[0], scale[0]))

out = {}
if case == "wedge":
    t0 = time.perf_counter()
    flight = motion.example()
    truth = flight.truth(rate_hz=20.0)
    imu = sensors.preset("tactical")
    settings = ekf.LooselyCoupled(imu, gnss.Gnss(outages=((1400.0, 1460.0),)))
    flights.fly(truth, imu, settings, key=jax.random.key(0), runs=20).summary()
    out["fly"] = (time.perf_counter() - t0,)
    out["hrgjax"] = hg.__file__
else:
    out["fly"] = fly_case(True, 5)
    out["bank"] = bank_case()
    out["filter"], out["single"] = filter_case()
print(json.dumps(out))
"""


TRIES, LIMIT_S = 3, 120  # a finished run takes ≈ 25 s on 2 cores
BEFORE = "76dea07"
"""The last commit whose filters factorised with LAPACK (LU and Cholesky kernels)."""


def child(arm, case, env=None, timeout=None, cwd=None):
    """One arm in a fresh process (`cwd`: where it starts; `python -c` puts that folder first
    on `sys.path`, so only a folder without `hrgjax/` lets `PYTHONPATH` choose the tree)."""
    code = "LAPACK = " + repr(LAPACK) + "\n" + CHILD
    try:
        res = subprocess.run([sys.executable, "-c", code, arm, case], capture_output=True,
                             text=True, env=env, timeout=timeout, cwd=cwd)  # fmt: skip
    except subprocess.TimeoutExpired as e:  # what it said before it was killed
        said = e.stderr.decode() if isinstance(e.stderr, bytes) else e.stderr or ""
        where = said.split("hrgjax from ", 1)[1].split()[0] if "hrgjax from " in said else "?"
        return {"killed": True, "hrgjax": where}
    if res.returncode != 0:
        sys.exit(f"the {arm} arm failed:\n{res.stderr[-3000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def main():
    print(f"machine: {machine()}")
    if "--wedge" in sys.argv:
        i = sys.argv.index("--wedge")
        rev = sys.argv[i + 1] if len(sys.argv) > i + 1 else BEFORE
        root = pathlib.Path(__file__).resolve().parents[1]
        with tempfile.TemporaryDirectory() as old, tempfile.TemporaryDirectory() as start:
            subprocess.run(f"git -C {root} archive {rev} hrgjax | tar -x -C {old}", shell=True,
                           check=True)  # fmt: skip
            for label, path in (("this tree", root), (f"hrgjax at {rev}", old)):
                env = {k: v for k, v in os.environ.items() if k not in ("PJRT_NPROC", "NPROC")}
                env["PYTHONPATH"] = str(path)  # XLA's own pool: one thread per core
                for attempt in range(TRIES):
                    t0 = time.perf_counter()
                    out = child("plain", "wedge", env, timeout=LIMIT_S, cwd=start)
                    took = time.perf_counter() - t0
                    verdict = "did not finish (killed)" if out.get("killed") else "finished"
                    where = f" (hrgjax from {out['hrgjax']})"
                    print(f"  {label:18s} try {attempt + 1}: 20 flights of the hour, XLA's own "
                          f"pool: {verdict} after {took:.0f} s{where}", flush=True)  # fmt: skip
        return
    arms = {arm: child(arm, "speed") for arm in ("lapack", "plain")}
    names = {"fly": "20 INS flights, 10 min at 20 Hz", "bank": "filter bank, 64 × 2 000 steps",
             "filter": "Kalman filter + RTS, 15 states, 32 × 2 000 steps",
             "single": "the same, one record (not batched)"}  # fmt: skip
    for case, label in names.items():
        (f0, b0), (f1, b1) = arms["lapack"][case][:2], arms["plain"][case][:2]
        print(f"  {label:48s} LAPACK {b0 * 1e3:8.1f} ms (first {f0:5.1f} s), plain XLA "
              f"{b1 * 1e3:8.1f} ms (first {f1:5.1f} s): {b1 / b0:.2f}×")  # fmt: skip
        report(f"filters' factorisations in plain XLA, {label}", b1 * 1e3, "ms",
               "plain / LAPACK", b1 / b0)  # fmt: skip
    rms = arms["lapack"]["fly"][2], arms["plain"]["fly"][2]
    print(f"  filter's horizontal RMS over the 20 flights: LAPACK {rms[0]:.9g} m, plain "
          f"{rms[1]:.9g} m")  # fmt: skip


if __name__ == "__main__":
    main()
