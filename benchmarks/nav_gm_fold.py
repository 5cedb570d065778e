"""The GNSS/INS filter's σ against Gauss–Markov IMU biases of correlation time τ
(docs/navigation.md, "Gauss–Markov biases in the filter").

`ekf.LooselyCoupled` has no Gauss–Markov decay state: it folds each bias instability (σ, τ)
into a bias random walk of density 2σ²/τ. The walk's spectrum q/ω² lies above the
Gauss–Markov's q/(ω² + 1/τ²) at every frequency, which bounds the bias's changes but, with
the prior σ², not the bias itself in every direction: whether the σ it reports are too
small or too large is what this measures (too large in every row, the more so the shorter
τ).

This flies the tests' 120-s motion (take-off, banked turn, climb, cruise; 10 Hz IMU, 1 Hz
GNSS position and velocity, an outage at 70–90 s) R times per τ with a Gauss–Markov-only
IMU (gyro σ 30 °/h, accelerometer 500 µg, the same τ for both; ARW 0.01 °/√h, VRW
10 µg/√Hz; no fixed bias), each run with its own initial error drawn from P0, and the filter
told the sensor's exact model. Per τ it prints the mean NIS / 6 and the z-RMS — the RMS over
runs, epochs after the start and axes of (true error) / (reported σ) — of each state group:
position, velocity, attitude, gyro bias, accelerometer bias, and position and attitude in
the outage. z = 1 is an honest σ; z < 1 a σ larger than the errors by 1/z. The τ = 1e5 s row
(a bias constant over the flight, which the walk models exactly) is the control: it must be
consistent, or the figures are not counted.

Usage: `.venv/bin/python benchmarks/nav_gm_fold.py [--taus 0.1,1,10,100,1e5] [--runs 64]`
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import machine, report  # noqa: E402

from hrgjax import kalman  # noqa: E402
from hrgjax.ins import ekf, gnss, motion, sensors  # noqa: E402
from hrgjax.units import DEG_PER_H, DEG_PER_SQRT_H  # noqa: E402

Z = (0.0, 0.0, 0.0)
OUTAGE = (70.0, 90.0)
GROUPS = {"pos": slice(0, 3), "vel": slice(3, 6), "att": slice(6, 9), "bg": slice(9, 12),
          "ba": slice(12, 15)}  # fmt: skip


def flight():
    """The tests' 120-s motion (tests/test_navigation_filter.py), 10 Hz."""
    s = motion.Segment
    segs = (
        s(1, Z, (2.0, 0.0, 0.0), 30.0),
        s(3, (0.0, 0.0, 20.0), Z, 5.0),
        s(1, (3.0, 0.0, 0.0), Z, 25.0),
        s(3, (0.0, 4.0, -20.0), Z, 5.0),
        s(1, Z, Z, 55.0),
    )
    return motion.Motion(40.0, 10.0, 200.0, (20.0, 0.0, 0.0), 10.0, 0.0, 0.0, segs).truth(10.0)


def gm_imu(tau):
    return sensors.ImuModel(
        arw=0.01 * DEG_PER_SQRT_H,
        vrw=10 * sensors.MICRO_G,
        gyro_bias_instability=30 * DEG_PER_H,
        accel_bias_instability=500 * sensors.MICRO_G,
        gyro_correlation_time=tau,
        accel_correlation_time=tau,
    )


def runs_program(truth, settings, mask):
    """One jitted, vmapped run: z = error / σ (M, 15) and the NIS (M,) at the GNSS epochs."""
    m = int(round(1.0 / (settings.gnss.rate_hz * truth.dt)))
    n = truth.dtheta.shape[0]
    at = jnp.concatenate([jnp.zeros(1, int), jnp.arange(m - 1, n, m)])
    tn = truth.states[::m]

    def one(key):
        k_imu, k_gnss, k_init = jax.random.split(key, 3)
        dth, dv, bg, ba = settings.imu.apply(
            k_imu, truth.dtheta, truth.dv, truth.dt, return_bias=True
        )
        fixes = gnss.measure(truth, settings.gnss, k_gnss)
        fixes = eqx.tree_at(lambda f: f.valid, fixes, fixes.valid & mask)
        p0 = settings.initial_covariance(truth.initial)
        e0 = kalman.psd_factor(p0[:9, :9]) @ jax.random.normal(k_init, (9,))
        res = ekf.loosely_coupled(
            settings, ekf.feedback(truth.initial, -e0), dth, dv, truth.dt, fixes
        )
        e = ekf.error_states(res, tn, bg[at], ba[at], truth.earth)
        return e / jnp.sqrt(jnp.diagonal(res.P, axis1=-2, axis2=-1)), res.nis

    return eqx.filter_jit(jax.vmap(one))


def row(truth, tau, runs, chunk=32):
    rx = gnss.Gnss()
    settings = ekf.LooselyCoupled(gm_imu(tau), rx)
    t = np.concatenate([[0.0], rx.epochs(truth.dtheta.shape[0], truth.dt) * truth.dt])
    mask = ~((t[1:] >= OUTAGE[0]) & (t[1:] <= OUTAGE[1]))
    f = runs_program(truth, settings, jnp.asarray(mask))
    keys = jax.random.split(jax.random.key(0), runs)
    parts = [jax.block_until_ready(f(keys[i : i + chunk])) for i in range(0, runs, chunk)]
    z, nis = (np.concatenate(p) for p in zip(*parts, strict=True))
    after, gap = t > 0, (t >= OUTAGE[0]) & (t <= OUTAGE[1])
    rms = lambda zz: float(np.sqrt(np.mean(zz**2)))  # noqa: E731
    out = {g: rms(z[:, after, s]) for g, s in GROUPS.items()}
    out.update(pos_outage=rms(z[:, gap, 0:3]), att_outage=rms(z[:, gap, 6:9]))
    out["nis/6"] = float(np.nanmean(nis[:, 1:]) / 6)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--taus", default="0.1,1,10,100,1e5", help="correlation times [s]")
    ap.add_argument("--runs", type=int, default=64, help="Monte Carlo runs per τ")
    args = ap.parse_args()
    taus = [float(x) for x in args.taus.split(",")]
    print(machine())
    truth = flight()
    cols = ("nis/6", "pos", "vel", "att", "bg", "ba", "pos_outage", "att_outage")
    print(f"{args.runs} runs per τ; z-RMS = RMS of (true error)/(reported σ); < 1: σ too large")
    print(f"{'τ [s]':>8s} | {'NIS/6':>6s} | z-RMS filter: {'pos':>5s} {'vel':>5s} {'att':>5s} "
          f"{'bg':>5s} {'ba':>5s} | outage: {'pos':>5s} {'att':>5s} | s")  # fmt: skip
    rows = {}
    for tau in taus:
        t0 = time.perf_counter()
        r = rows[tau] = row(truth, tau, args.runs)
        v = [r[c] for c in cols]
        print(f"{tau:8g} | {v[0]:6.3f} | z-RMS filter: " + " ".join(f"{x:5.2f}" for x in v[1:6])
              + " | outage: " + " ".join(f"{x:5.2f}" for x in v[6:])
              + f" | {time.perf_counter() - t0:.0f}", flush=True)  # fmt: skip
    control = rows.get(1e5)
    if control is not None:  # a bias constant over the flight: the walk is exact
        bad = {k: control[k] for k in ("att", "bg", "ba") if not 0.85 < control[k] < 1.15}
        assert not bad, f"the τ = 1e5 s control is not consistent: z-RMS {bad}"
    short = min(taus)
    report(f"attitude σ / its errors' RMS, τ = {short:g} s", 1.0 / rows[short]["att"], "x")
    report(f"gyro-bias σ / its errors' RMS, τ = {short:g} s", 1.0 / rows[short]["bg"], "x")
    report(f"mean NIS / 6, τ = {short:g} s", rows[short]["nis/6"], "")


if __name__ == "__main__":
    main()
