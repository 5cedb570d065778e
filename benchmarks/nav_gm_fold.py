"""The GNSS/INS filter's σ against Gauss–Markov IMU biases of correlation time τ
(docs/navigation.md, "Gauss–Markov biases in the filter").

`ekf.LooselyCoupled` by default has no Gauss–Markov decay state: it folds each bias
instability (σ, τ) into a bias random walk of density 2σ²/τ. The walk's spectrum q/ω² lies above the
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

`--gauss-markov` flies each run through both filters, the fold and
`LooselyCoupled(gauss_markov=True)` (six Gauss–Markov bias states), on the same draws. The
latter needs a fixed-bias prior σ > 0, so the sensor then also has fixed biases (gyro 3 °/h,
accelerometer 50 µg: a tenth of σ), drawn per run (`sensors.random_unit`) and told to both
filters; the bias columns are the total bias's (fixed plus Gauss–Markov: its error over the σ
of the sum of the two states). The truths: for the fold each interval's mean total bias (as
`flights.fly`), for the Gauss–Markov filter the Gauss–Markov bias at the fix (its state is
that instant's value) and the rest's interval mean (`return_bias="gauss_markov"`).

Usage: `.venv/bin/python benchmarks/nav_gm_fold.py [--taus 0.1,1,10,100,1e5] [--runs 64]
[--gauss-markov]`
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


def gm_imu(tau, fixed=False):
    return sensors.ImuModel(
        gyro_bias=3 * DEG_PER_H if fixed else 0.0,
        accel_bias=50 * sensors.MICRO_G if fixed else 0.0,
        arw=0.01 * DEG_PER_SQRT_H,
        vrw=10 * sensors.MICRO_G,
        gyro_bias_instability=30 * DEG_PER_H,
        accel_bias_instability=500 * sensors.MICRO_G,
        gyro_correlation_time=tau,
        accel_correlation_time=tau,
    )


def z_scores(res, e):
    """(M, 15) error / σ; with Gauss–Markov states the bias columns are the total bias's."""
    p = res.P
    var = jnp.diagonal(p, axis1=-2, axis2=-1)
    if not res.gauss_markov:
        return e / jnp.sqrt(var[..., :15])
    i = 21 if res.scale_factors else 15
    k, g = jnp.arange(9, 15), jnp.arange(i, i + 6)
    total = e[..., 9:15] + e[..., i : i + 6]
    v = var[..., 9:15] + var[..., i : i + 6] + 2 * p[..., k, g]
    return jnp.concatenate([e[..., :9] / jnp.sqrt(var[..., :9]), total / jnp.sqrt(v)], -1)


def runs_program(truth, settings, mask, gm_settings=None):
    """One jitted, vmapped run: z = error / σ (M, 15) and the NIS (M,) at the GNSS epochs, of
    the fold (and of the Gauss–Markov filter on the same draws, with `gm_settings`)."""
    m = int(round(1.0 / (settings.gnss.rate_hz * truth.dt)))
    n = truth.dtheta.shape[0]
    at = jnp.concatenate([jnp.zeros(1, int), jnp.arange(m - 1, n, m)])
    tn = truth.states[::m]

    def one(key):
        k_imu, k_gnss, k_init = jax.random.split(key, 3)
        k_unit = jax.random.fold_in(key, 1)  # the fold's draws stay those of its table
        imu = settings.imu if gm_settings is None else sensors.random_unit(settings.imu, k_unit)
        # the fold's bias truth: each interval's mean total (as flights.fly); the
        # Gauss–Markov filter's: the Gauss–Markov bias at the fix and the rest's mean
        dth, dv, bg_mean, ba_mean = imu.apply(
            k_imu, truth.dtheta, truth.dv, truth.dt, return_bias=True
        )
        _, _, bg, ba, gg, ga = imu.apply(
            k_imu, truth.dtheta, truth.dv, truth.dt, return_bias="gauss_markov"
        )
        fixes = gnss.measure(truth, settings.gnss, k_gnss)
        fixes = eqx.tree_at(lambda f: f.valid, fixes, fixes.valid & mask)
        p0 = settings.initial_covariance(truth.initial)
        e0 = kalman.psd_factor(p0[:9, :9]) @ jax.random.normal(k_init, (9,))
        start = ekf.feedback(truth.initial, -e0)
        out = []
        for s in (settings,) if gm_settings is None else (settings, gm_settings):
            res = ekf.loosely_coupled(s, start, dth, dv, truth.dt, fixes)
            b = (bg, ba) if s.gauss_markov else (bg_mean, ba_mean)
            e = ekf.error_states(res, tn, b[0][at], b[1][at], truth.earth, gyro_gm=gg[at],
                                 accel_gm=ga[at])  # fmt: skip
            out += [z_scores(res, e), res.nis]
        return tuple(out)

    return eqx.filter_jit(jax.vmap(one))


def row(truth, tau, runs, chunk=32, gauss_markov=False):
    """{filter: figures} for τ: the fold's ("fold"), and with `gauss_markov` the
    Gauss–Markov filter's ("gm") on the same runs."""
    rx = gnss.Gnss()
    settings = ekf.LooselyCoupled(gm_imu(tau, gauss_markov), rx)
    gm = ekf.LooselyCoupled(settings.imu, rx, gauss_markov=True) if gauss_markov else None
    t = np.concatenate([[0.0], rx.epochs(truth.dtheta.shape[0], truth.dt) * truth.dt])
    mask = ~((t[1:] >= OUTAGE[0]) & (t[1:] <= OUTAGE[1]))
    f = runs_program(truth, settings, jnp.asarray(mask), gm)
    keys = jax.random.split(jax.random.key(0), runs)
    parts = [jax.block_until_ready(f(keys[i : i + chunk])) for i in range(0, runs, chunk)]
    arrays = [np.concatenate(p) for p in zip(*parts, strict=True)]
    after, gap = t > 0, (t >= OUTAGE[0]) & (t <= OUTAGE[1])
    rms = lambda zz: float(np.sqrt(np.mean(zz**2)))  # noqa: E731
    rows = {}
    names = ("fold", "gm")[: len(arrays) // 2]
    for name, (z, nis) in zip(names, zip(arrays[::2], arrays[1::2], strict=True), strict=True):
        out = {g: rms(z[:, after, s]) for g, s in GROUPS.items()}
        out.update(pos_outage=rms(z[:, gap, 0:3]), att_outage=rms(z[:, gap, 6:9]))
        out["nis/6"] = float(np.nanmean(nis[:, 1:]) / 6)
        rows[name] = out
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--taus", default="0.1,1,10,100,1e5", help="correlation times [s]")
    ap.add_argument("--runs", type=int, default=64, help="Monte Carlo runs per τ")
    ap.add_argument("--gauss-markov", action="store_true",
                    help="also the filter with Gauss–Markov states, on the same runs")  # fmt: skip
    args = ap.parse_args()
    taus = [float(x) for x in args.taus.split(",")]
    print(machine())
    truth = flight()
    cols = ("nis/6", "pos", "vel", "att", "bg", "ba", "pos_outage", "att_outage")
    print(f"{args.runs} runs per τ; z-RMS = RMS of (true error)/(reported σ); < 1: σ too large")
    print(f"{'τ [s]':>8s} {'filter':>6s} | {'NIS/6':>6s} | z-RMS filter: {'pos':>5s} {'vel':>5s} "
          f"{'att':>5s} {'bg':>5s} {'ba':>5s} | outage: {'pos':>5s} {'att':>5s} | s")  # fmt: skip
    rows = {}
    for tau in taus:
        t0 = time.perf_counter()
        rows[tau] = row(truth, tau, args.runs, gauss_markov=args.gauss_markov)
        for name, r in rows[tau].items():
            v = [r[c] for c in cols]
            print(f"{tau:8g} {name:>6s} | {v[0]:6.3f} | z-RMS filter: "
                  + " ".join(f"{x:5.2f}" for x in v[1:6])
                  + " | outage: " + " ".join(f"{x:5.2f}" for x in v[6:])
                  + f" | {time.perf_counter() - t0:.0f}", flush=True)  # fmt: skip
    control = rows.get(1e5)
    for name, c in (control or {}).items():  # a bias constant over the flight: the walk is exact
        bad = {k: c[k] for k in ("att", "bg", "ba") if not 0.85 < c[k] < 1.15}
        assert not bad, f"the τ = 1e5 s control is not consistent ({name}): z-RMS {bad}"
    short = min(taus)
    for name, r in rows[short].items():
        report(f"{name}: attitude σ / its errors' RMS, τ = {short:g} s", 1.0 / r["att"], "x")
        report(f"{name}: gyro-bias σ / its errors' RMS, τ = {short:g} s", 1.0 / r["bg"], "x")
        report(f"{name}: mean NIS / 6, τ = {short:g} s", r["nis/6"], "")


if __name__ == "__main__":
    main()
