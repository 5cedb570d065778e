"""Monte Carlo of the strapdown INS error model (issue 5 target): 1000 runs of a 1-hour
flight ([`ins.trajectory.flight`]), 15-state φ-angle model with random constant biases and
white sensor noise, exactly discretised per 1-s step (Van Loan), vmapped over runs.

Prints, side by side in one run: wall time and runs/s of the vmapped Monte Carlo; the same
runs done one at a time by a jitted single-run function (the ratio is what vmap buys); the
covariance propagation; and, as a check, the Monte Carlo spread of the horizontal position
error after 1 h against the propagated covariance.

Usage: `.venv/bin/python benchmarks/ins_errors.py [--runs N]`.
"""

import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import best_of, first_call, machine, report

from hrgjax.ins import strapdown as sd
from hrgjax.ins import trajectory as tr
from hrgjax.units import DEG, DEG_PER_H

N_RUNS = int(sys.argv[sys.argv.index("--runs") + 1]) if "--runs" in sys.argv else 1000
EVERY = 60  # keep one state a minute


def main():
    print(f"machine: {machine()}")
    t0 = time.perf_counter()
    traj = tr.flight(dt=1.0)
    t_traj = time.perf_counter() - t0
    imu = sd.ImuErrors(
        gyro_bias=0.01 * DEG_PER_H, accel_bias=1e-4 * 9.80665, arw=0.005 * DEG / 60, vrw=5e-5
    )
    p0 = sd.initial_covariance(
        imu, jnp.diag(jnp.array([0, 0, 0, 0.01, 0.01, 0.01, 1e-8, 1e-8, 1e-6]) ** 1)
    )
    disc = jax.jit(lambda: sd.discretise(traj, imu, altitude_aided=True))
    t_disc_first, (phi, qd) = first_call(disc)
    t_disc = best_of(disc, 3)
    steps = phi.shape[0]
    print(f"1-h flight: {steps} steps of 1 s; trajectory built in {t_traj:.2f} s")
    print(
        f"discretise (15-state, Van Loan per step): {t_disc:.3f} s (first call {t_disc_first:.1f} s)"
    )

    key = jax.random.key(0)
    mc = lambda: sd.monte_carlo(phi, qd, p0, key, N_RUNS, every=EVERY)
    t_first, xs = first_call(mc)
    t_mc = best_of(mc, 3)
    one = jax.jit(lambda k: sd.monte_carlo(phi, qd, p0, k, 1, every=EVERY))
    keys = jax.random.split(key, 20)
    jax.block_until_ready(one(keys[0]))
    t0 = time.perf_counter()
    for k in keys:
        jax.block_until_ready(one(k))
    t_one = (time.perf_counter() - t0) / len(keys)
    cov = jax.jit(lambda: sd.covariance(phi, qd, p0))
    jax.block_until_ready(cov())
    t_cov = best_of(cov, 3)

    print(f"\n{'':>34} {'wall [s]':>10} {'runs/s':>10}")
    print(
        f"{'vmapped Monte Carlo, ' + str(N_RUNS) + ' runs':>34} {t_mc:10.3f} {N_RUNS / t_mc:10.0f}"
    )
    print(f"{'one run at a time (jit), per run':>34} {t_one:10.4f} {1 / t_one:10.0f}")
    print(f"{'vmap speed-up':>34} {t_one * N_RUNS / t_mc:10.1f}×")
    print(f"{'covariance propagation (once)':>34} {t_cov:10.3f}")
    print(f"first call of the Monte Carlo (compile + run): {t_first:.1f} s")
    report(
        f"INS error Monte Carlo, {N_RUNS} runs of a 1-h flight",
        N_RUNS / t_mc,
        "runs/s",
        "vmap / one run at a time",
        t_one * N_RUNS / t_mc,
    )

    ps = cov()
    r_m, r_n = (float(x) for x in traj.earth.radii(traj.lat[-1]))
    h, lat = float(traj.h[-1]), float(traj.lat[-1])
    scale = np.array([r_m + h, (r_n + h) * np.cos(lat)])  # rad → m
    want = np.sqrt(np.diag(np.asarray(ps[-1]))[:2]) * scale
    got = np.asarray(xs)[:, -1, :2].std(0) * scale
    print(
        f"\nafter 1 h: position error std north/east, Monte Carlo {got[0]:.0f} / {got[1]:.0f} m, "
        f"propagated {want[0]:.0f} / {want[1]:.0f} m (ratio {got[0] / want[0]:.3f} / "
        f"{got[1] / want[1]:.3f})"
    )
    report(
        "INS 1-h north position error std, Monte Carlo",
        got[0],
        "m",
        "Monte Carlo / propagated covariance",
        got[0] / want[0],
        "1 within sampling error",
    )


if __name__ == "__main__":
    main()
