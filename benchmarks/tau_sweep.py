"""A sweep over the IMU's Gauss–Markov correlation time τ through `ins.flights.fly`: what
each new τ costs, and what the filter's compiled run costs at a τ it has seen.

`ImuModel.gyro_correlation_time` and `accel_correlation_time` were static fields (the
covariance step chose its number of squarings from 1/τ on the host), so each τ compiled the
flights' batch again; they are values now (`hrgjax.ins.discretisation`: the squarings as
binary digits under `lax.cond`). This flies the tests' 120-s motion (10 Hz IMU, 1 Hz GNSS)
`--runs` runs per τ through `LooselyCoupled(gauss_markov=True)` told the sensor's model, the
sensor and the filter sharing τ, and prints per τ the wall time of the call (compile
included) and the number of programs compiled; then the best of 3 warm calls at the first
and the last τ (the same compiled program: the price of the conds, against a build whose
squarings were static, is the before/after of that figure).

Usage: `.venv/bin/python benchmarks/tau_sweep.py [--taus 3600,600,60,5,0.5] [--runs 8]`
(run it on an older checkout with `PYTHONPATH=` that checkout for the before column).
"""

import argparse
import sys
import time

import jax
from _common import best_of, machine, report
from nav_gm_fold import gm_imu

from hrgjax.ins import ekf, flights, gnss

sys.path.insert(0, "tests")
from helpers import CompileCounter, flight_motion  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--taus", default="3600,600,60,5,0.5", help="correlation times [s]")
    ap.add_argument("--runs", type=int, default=8, help="runs per τ (one vmapped batch)")
    args = ap.parse_args()
    taus = [float(t) for t in args.taus.split(",")]
    truth = flight_motion().truth(10.0)  # the tests' 120-s motion, 10 Hz
    key = jax.random.key(0)
    print(machine())

    def fly(tau):
        imu = gm_imu(tau, fixed=True)  # nav_gm_fold's sensor, fixed biases too
        settings = ekf.LooselyCoupled(imu, gnss.Gnss(), gauss_markov=True)
        return flights.fly(truth, imu, settings, key=key, runs=args.runs)

    total = 0.0
    for tau in taus:
        with CompileCounter() as c:
            t0 = time.perf_counter()
            out = jax.block_until_ready(fly(tau))
            dt = time.perf_counter() - t0
        total += dt
        z = float(out.filter["nees"].mean()) / out.n_states
        print(f"τ = {tau:g} s: {dt:.2f} s, {c.compiles} programs compiled, mean NEES / n {z:.3f}")
    report("τ sweep through fly, all calls", total, "s", f"{len(taus)} values of τ")
    for tau in (taus[0], taus[-1]):
        warm = best_of(lambda tau=tau: fly(tau), repeat=3)
        report(f"fly at τ = {tau:g} s, compiled", warm * 1e3, "ms", f"{args.runs} runs")


if __name__ == "__main__":
    main()
