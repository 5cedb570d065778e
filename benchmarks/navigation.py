"""Navigation-grade INS (issue 48): the mechanization against its exact increments and the
physical integrals, the linear error model against the nonlinear difference, and the
loosely-coupled filter's consistency over Monte Carlo flights.

1. The example flight (`hrgjax.ins.motion.example()`: 1 h, take-off, climb to 5 km, 90° and
   180° banked turns, descent) at 100 Hz: free integration of its exact increments against the
   truth (target ≤ 1 mm, ≤ 1e-6 m/s), and of the physical integrals ∫ω dt, ∫f dt (Gauss–
   Legendre, 5 nodes) at 50, 100 and 200 Hz (the two-sample algorithm's own error, second
   order).
2. Constant gyro and accelerometer biases (0.01 °/h, 10 µg per axis, times 1, 10, 100, 1000)
   through the mechanization against `strapdown.propagate` on the same truth (every 10th
   epoch): the relative gap, which must be ≤ 1 % and grow in proportion to the errors.
3. Monte Carlo flights of the example at `--rate` Hz with a 60-s GNSS outage: the 15-state
   filter with an IMU it models exactly (the tactical preset's biases and noise), and with the
   full tactical preset (misalignments, scale factors, bias instability): the fraction of
   epochs whose mean NEES lies inside its 95 % band (target ≥ 90 %), for all states and for
   the nine navigation states.
4. Speed: mechanization steps per second, one flight against a vmapped batch per flight.
5. Seed 000's INS impact (`hrgjax.calibration.ins_impact`, the three 1-h flights of two level
   HRGs warming from −40 °C) recomputed through the mechanization
   (`ins_impact.mechanized_errors`, 10 Hz, altitude held) beside the linear error model, for
   the raw gyro and the Fourier compensator fitted on the seed's quick plan (`--ins-impact`).

Usage: `.venv/bin/python benchmarks/navigation.py [--runs 100] [--rate 20] [--ins-impact]`.
"""

import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import machine, report

from hrgjax.ins import ekf, flights, gnss, motion, sensors, strapdown
from hrgjax.ins import mechanization as me
from hrgjax.units import DEG_PER_H, G0


def physical_increments(mot, truth, nodes=5):
    """∫ω_ib^b dt, ∫f^b dt over each interval (tests/test_navigation.py's quadrature)."""
    sys.path.insert(0, "tests")
    from test_navigation import _physical_increments

    return _physical_increments(mot, truth, nodes)


def free_integration(mot):
    truth = mot.truth(100.0)
    t0 = time.perf_counter()
    nav = me.mechanize(truth.initial, truth.dtheta, truth.dv, truth.dt)
    jax.block_until_ready(nav.lat)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    nav = me.mechanize(truth.initial, truth.dtheta, truth.dv, truth.dt)
    jax.block_until_ready(nav.lat)
    warm = time.perf_counter() - t0
    p, v, a = (np.abs(np.asarray(x)).max() for x in me.navigation_errors(nav, truth.states))
    report(
        "free integration of exact increments, 1 h at 100 Hz: position", p, "m", target="≤ 1e-3 m"
    )
    report("  velocity", v, "m/s", target="≤ 1e-6 m/s")
    report("  attitude", a, "rad")
    n = truth.dtheta.shape[0]
    report("mechanization steps per second (warm)", n / warm, "steps/s",
           comparison="first call / warm call", ratio=first / warm)  # fmt: skip
    prev = None
    for hz in (50.0, 100.0, 200.0):
        t = truth if hz == 100.0 else mot.truth(hz)
        dth, dv = physical_increments(mot, t)
        nav = me.mechanize(t.initial, jnp.asarray(dth), jnp.asarray(dv), t.dt)
        p, _, a = me.navigation_errors(nav, t.states)
        hor = float(np.abs(np.asarray(p)[:, :2]).max())
        report(f"physical increments through the mechanization, {hz:g} Hz: horizontal", hor, "m",
               comparison="previous rate / this", ratio=None if prev is None else prev / hor)  # fmt: skip
        prev = hor
    return truth


def linear_vs_nonlinear(truth):
    every = 10
    traj = truth.trajectory(every)
    bg = np.array([1.0, -0.7, 0.5]) * 0.01 * DEG_PER_H
    ba = np.array([-0.6, 1.0, 0.8]) * 10e-6 * G0
    prev = None
    for scale in (1.0, 10.0, 100.0):  # (×1000: the free vertical channel diverges, 10 km)
        nav = me.mechanize(truth.initial, truth.dtheta + (bg * scale * truth.dt)[None],
                           truth.dv + (ba * scale * truth.dt)[None], truth.dt, every=every)  # fmt: skip
        p, v, a = (np.asarray(x) for x in me.navigation_errors(nav, truth.states[::every]))
        dx = strapdown.propagate(traj, gyro_error=bg * scale, accel_error=ba * scale)
        lin = (np.asarray(strapdown.position_metres(traj, dx)), np.asarray(dx[:, 3:6]),
               np.asarray(dx[:, 6:9]))  # fmt: skip
        gaps = [np.abs(x - y).max() / np.abs(y).max() for x, y in zip((p, v, a), lin, strict=True)]
        gap = max(gaps)
        report(f"linear model vs nonlinear, {0.01 * scale:g} °/h and {10 * scale:g} µg: worst "
               "relative gap (position, velocity, attitude)", gap, "",
               comparison="this / previous", ratio=None if prev is None else gap / prev,
               target="≤ 1e-2 at ×1, ∝ error size")  # fmt: skip
        prev = gap


def monte_carlo(mot, runs, rate):
    truth = mot.truth(rate)
    tactical = sensors.preset("tactical")
    consistent = sensors.ImuModel(
        gyro_bias=tactical.gyro_bias, accel_bias=tactical.accel_bias, arw=tactical.arw,
        vrw=tactical.vrw, gyro_misalignment=np.zeros((3, 3)), accel_misalignment=np.zeros((3, 3)),
        gyro_correlation_time=tactical.gyro_correlation_time,
        accel_correlation_time=tactical.accel_correlation_time,
    )  # fmt: skip
    receiver = gnss.Gnss(outages=((1400.0, 1460.0),), lever_arm=(1.0, 0.3, -1.2))
    for name, imu in (
        ("biases and noise (modelled)", consistent),
        ("full tactical preset", tactical),
    ):
        settings = ekf.LooselyCoupled(imu, receiver)
        t0 = time.perf_counter()
        f = flights.fly(truth, imu, settings, key=jax.random.key(0), runs=runs)
        jax.block_until_ready(f.nis)
        wall = time.perf_counter() - t0
        s = f.summary()
        for k in ("filter", "smoother"):
            report(f"{runs} flights, {name}: {k} mean NEES inside its 95 % band", s[k]["nees_inside_95_band"],
                   "of epochs", target="≥ 0.9" if imu is consistent else "")  # fmt: skip
            report(
                f"  {k}, navigation states only",
                s[k]["nees_navigation_inside_95_band"],
                "of epochs",
            )
            report(f"  {k} horizontal error: RMS / max in the outage", s[k]["horizontal_rms_m"], "m",
                   comparison="max in the outage", ratio=s[k]["gap_horizontal_max_m"])  # fmt: skip
        report(f"  NIS mean ({name})", s["nis_mean"], "", comparison="/ innovation dimension",
               ratio=s["nis_mean"] / s["innovation_dim"])  # fmt: skip
        report(f"  free inertial final horizontal error (median, {name})",
               s["free"]["final_horizontal_median_m"], "m")  # fmt: skip
        report(f"  wall time of {runs} flights ({name}, first call)", wall, "s")
    # per-flight cost: one flight against a batch of 16 (warm)
    settings = ekf.LooselyCoupled(consistent, receiver)
    one = lambda: flights.fly(truth, consistent, settings, key=jax.random.key(1), runs=1).nis
    batch = lambda: flights.fly(truth, consistent, settings, key=jax.random.key(1), runs=16).nis
    jax.block_until_ready(one())
    t0 = time.perf_counter()
    jax.block_until_ready(one())
    t1 = time.perf_counter() - t0
    t0 = time.perf_counter()
    jax.block_until_ready(batch())
    t16 = time.perf_counter() - t0
    report("one flight (warm)", t1, "s", comparison="one flight / per flight in a batch of 16",
           ratio=t1 / (t16 / 16))  # fmt: skip


def ins_impact_through_the_mechanization():
    import hrgjax as hg
    from hrgjax.calibration import FourierCompensator, NoCompensation, run_plan, seed_plan
    from hrgjax.calibration import ins_impact as ii

    gyro = hg.presets.tvg3_like()
    key, bias_key = jax.random.key(0), jax.random.key(1)
    data = run_plan(gyro, seed_plan(quick=True), key=jax.random.key(2), bias_key=bias_key)
    comps = {"raw": NoCompensation(), "fourier": FourierCompensator().fit(data)}
    for i, flight in enumerate(ii.FLIGHTS):
        rec = ii.fly(gyro, flight, key=jax.random.fold_in(key, i), bias_key=bias_key)
        for name, comp in comps.items():
            v_lin, p_lin = ii.navigation_errors(comp, rec, flight)
            v_mech, p_mech = ii.mechanized_errors(comp, rec, flight)
            report(f"INS impact, flight {i + 1}, {name}: position after 1 h, mechanization",
                   p_mech / 1e3, "km", comparison="mechanization / linear model",
                   ratio=p_mech / p_lin)  # fmt: skip
            report("  velocity, mechanization", v_mech, "m/s", comparison="/ linear model",
                   ratio=v_mech / v_lin)  # fmt: skip


def main():
    runs = int(sys.argv[sys.argv.index("--runs") + 1]) if "--runs" in sys.argv else 100
    rate = float(sys.argv[sys.argv.index("--rate") + 1]) if "--rate" in sys.argv else 20.0
    print(f"machine: {machine()}")
    mot = motion.example()
    truth = free_integration(mot)
    linear_vs_nonlinear(truth)
    monte_carlo(mot, runs, rate)
    if "--ins-impact" in sys.argv:
        ins_impact_through_the_mechanization()


if __name__ == "__main__":
    main()
