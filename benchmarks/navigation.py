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
   full tactical preset (also misalignments and scale factors, which the 15 states do not
   model, and bias instability, which the filter models as a random walk): the fraction of
   epochs whose mean NEES lies inside its 95 % band (target ≥ 90 %), for all states and for
   the nine navigation states.
4. Speed: mechanization steps per second; one flight against a vmapped batch per flight; and
   the issue's figure, an hour at 100 Hz through the mechanization and the 15-state filter
   (GNSS at 1 Hz) after compile, alone and 100 flights vmapped (`--only speed`).
5. pyins 1.0 (`python-ins`, test-only dependency) on the same data with its gravity model:
   its strapdown integrator on the example's exact increments (its own truncation, at 100 and
   200 Hz) and the response to a navigation-grade IMU's errors beside ours; its feedback
   filter (`run_feedback_filter`, the same IMU model, fixes, initial state and 1-s covariance
   step) beside `loosely_coupled` on `--pyins N` flights at 20 Hz (target: horizontal error
   statistics within 10 %), and their wall times.
6. Seed 000's INS impact (`hrgjax.calibration.ins_impact`, the three 1-h flights of two level
   HRGs warming from −40 °C) recomputed through the mechanization
   (`ins_impact.mechanized_errors`, 10 Hz, altitude held) beside the linear error model, for
   the raw gyro and the Fourier compensator fitted on the seed's quick plan (`--ins-impact`).

Usage: `.venv/bin/python benchmarks/navigation.py [--runs 100] [--rate 20] [--pyins 5]
[--ins-impact] [--only free,linear,monte-carlo,pyins,ins-impact]`.
"""

import sys
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from _common import best_of, machine, report

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
        report(f"  free inertial (height held) final horizontal error (median, {name})",
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


def _pyins_earth():
    import pyins.earth as pe

    from hrgjax.ins.constants import E2, GAMMA_E, A, Earth

    class PyinsGravity(Earth):
        """WGS-84 with pyins's gravity: Somigliana with the linear free-air term."""

        def gravity(self, lat, h=0.0):
            s2 = jnp.sin(lat) ** 2
            return GAMMA_E * (1 + pe.F * s2) / jnp.sqrt(1 - E2 * s2) * (1 - 2 * h / A)

    return PyinsGravity()


def _pyins_pva(state):
    import pandas as pd

    from hrgjax.units import DEG

    r, p, h = (float(np.asarray(x)) / DEG for x in state.euler)
    v = np.asarray(state.v_ned)
    return pd.Series({"lat": float(state.lat) / DEG, "lon": float(state.lon) / DEG,
                      "alt": float(state.h), "VN": v[0], "VE": v[1], "VD": v[2], "roll": r,
                      "pitch": p, "heading": h}, name=0.0)  # fmt: skip


def _pyins_increments(dth, dv, dt):
    import pandas as pd
    import pyins.strapdown as ps

    cols = ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]
    rows = np.vstack([np.zeros((1, 6)), np.hstack([np.asarray(dth), np.asarray(dv)])])
    imu = pd.DataFrame(rows, index=np.arange(rows.shape[0]) * dt, columns=cols)
    return ps.compute_increments_from_imu(imu, "increment")


def _horizontal(lat, lon, states, earth):
    lat0, h0 = np.asarray(states.lat), np.asarray(states.h)
    r_m, r_n = (np.asarray(x) for x in earth.radii(lat0))
    north = (lat - lat0) * (r_m + h0)
    east = (lon - np.asarray(states.lon)) * (r_n + h0) * np.cos(lat0)
    return np.hypot(north, east)


def _import_pyins():
    """Import pyins with this folder off the path: numba imports `coverage` if it can, and
    would find benchmarks/coverage.py."""
    import os

    here = os.path.dirname(os.path.abspath(__file__))
    saved = sys.path[:]
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != here]
    try:
        import pyins.filters  # noqa: F401
        import pyins.strapdown  # noqa: F401
    finally:
        sys.path[:] = saved


def pyins_comparison(mot, flights_n):
    import warnings

    _import_pyins()
    import pyins.filters as pf
    import pyins.inertial_sensor as pis
    import pyins.measurements as pm
    import pyins.strapdown as ps

    from hrgjax import kalman
    from hrgjax.units import DEG

    warnings.filterwarnings("ignore")  # pyins on pandas 3: copy-keyword deprecations
    earth = _pyins_earth()
    imu = sensors.preset("navigation")
    for hz in (100.0, 200.0):
        t = mot.truth(hz, earth=earth)
        run = lambda a, b, t=t: ps.Integrator(_pyins_pva(t.states[0])).integrate(
            _pyins_increments(a, b, t.dt)
        )
        tj0 = run(t.dtheta, t.dv)
        own = _horizontal(tj0.lat.values * DEG, tj0.lon.values * DEG, t.states, earth)
        report(
            f"pyins integrator on the exact increments, {hz:g} Hz: horizontal after 1 h",
            own.max(),
            "m",
        )
        dth, dv = imu.apply(jax.random.key(0), t.dtheta, t.dv, t.dt)
        t0 = time.perf_counter()
        tj = run(dth, dv)
        t_p = time.perf_counter() - t0
        t0 = time.perf_counter()
        nav = me.mechanize(t.initial, dth, dv, t.dt, earth=earth)
        jax.block_until_ready(nav.lat)
        t_h = time.perf_counter() - t0
        ours = np.stack(me.navigation_errors(nav, t.states, earth)[0].T[:2], -1)
        r_m, r_n = (np.asarray(x) for x in earth.radii(np.asarray(t.states.lat)))
        rh = np.asarray(t.states.h)
        theirs = np.stack([(tj.lat.values - tj0.lat.values) * DEG * (r_m + rh),
                           (tj.lon.values - tj0.lon.values) * DEG * (r_n + rh)
                           * np.cos(np.asarray(t.states.lat))], -1)  # fmt: skip
        gap = np.abs(np.asarray(ours) - theirs).max()
        report(f"  response to navigation-grade IMU errors, hrgjax vs pyins, {hz:g} Hz: largest gap",
               gap, "m", comparison="response's largest value",
               ratio=np.abs(np.asarray(ours)).max())  # fmt: skip
        report(
            f"  integrator wall time, pyins (numba, second call) / hrgjax, {hz:g} Hz", t_p / t_h, ""
        )
    if flights_n <= 0:
        return
    t = mot.truth(20.0, earth=earth)
    tac = sensors.preset("tactical")
    model = sensors.ImuModel(
        gyro_bias=tac.gyro_bias, accel_bias=tac.accel_bias, arw=tac.arw, vrw=tac.vrw
    )
    rx = gnss.Gnss(position_sigma=2.0, velocity_sigma=0.05, outages=((1400.0, 1460.0),))
    settings = ekf.LooselyCoupled(model, rx, position_sigma=3.0, velocity_sigma=0.1,
                                  attitude_sigma=(1e-3, 1e-3, 5e-3), earth=earth)  # fmt: skip
    n = t.dtheta.shape[0]
    idx = rx.epochs(n, t.dt)
    tfix = idx * t.dt

    @jax.jit
    def draw(key):
        k_unit, k_imu, k_gnss, k_init = jax.random.split(key, 4)
        dth, dv = sensors.random_unit(model, k_unit).apply(k_imu, t.dtheta, t.dv, t.dt)
        p0 = settings.initial_covariance(t.initial)
        e0 = kalman.psd_factor(p0[:9, :9]) @ jax.random.normal(k_init, (9,))
        return ekf.feedback(t.initial, -e0), dth, dv, gnss.measure(t, rx, k_gnss)

    ours, theirs, times = [], [], []
    for r in range(flights_n):
        start, dth, dv, fixes = draw(jax.random.key(r))
        t0 = time.perf_counter()
        res = ekf.loosely_coupled(settings, start, dth, dv, t.dt, fixes)
        jax.block_until_ready(res.nav.lat)
        t_ours = time.perf_counter() - t0
        ours.append(
            _horizontal(
                np.asarray(res.nav.lat[1:]), np.asarray(res.nav.lon[1:]), t.states[idx], earth
            )
        )
        ok = np.asarray(fixes.valid)
        pos = {"lat": np.asarray(fixes.lat)[ok] / DEG, "lon": np.asarray(fixes.lon)[ok] / DEG,
               "alt": np.asarray(fixes.h)[ok]}  # fmt: skip
        vel = {k: np.asarray(fixes.v_ned)[ok, i] for i, k in enumerate(("VN", "VE", "VD"))}
        import pandas as pd

        meas = [pm.Position(pd.DataFrame(pos, index=tfix[ok]), 2.0),
                pm.NedVelocity(pd.DataFrame(vel, index=tfix[ok]), 0.05)]  # fmt: skip
        gm = pis.EstimationModel(bias_sd=np.asarray(model.gyro_bias), noise=np.asarray(model.arw))
        am = pis.EstimationModel(bias_sd=np.asarray(model.accel_bias), noise=np.asarray(model.vrw))
        t0 = time.perf_counter()
        out = pf.run_feedback_filter(_pyins_pva(start), 3.0, 0.1, 1e-3 / DEG, 5e-3 / DEG,
                                     _pyins_increments(dth, dv, t.dt), gm, am, meas, time_step=1.0)  # fmt: skip
        times.append((time.perf_counter() - t0, t_ours))
        tj = out.trajectory.loc[tfix]
        theirs.append(_horizontal(tj.lat.values * DEG, tj.lon.values * DEG, t.states[idx], earth))
    o, p = np.asarray(ours), np.asarray(theirs)
    gap = (tfix >= 1400.0) & (tfix <= 1460.0)
    rms = lambda x: float(np.sqrt(np.mean(x**2)))
    report(f"{flights_n} flights, hrgjax filter vs pyins feedback filter: horizontal RMS", rms(o), "m",
           comparison="hrgjax / pyins", ratio=rms(o) / rms(p), target="within 10 %")  # fmt: skip
    report("  in the 60-s outage: horizontal RMS", rms(o[:, gap]), "m", comparison="hrgjax / pyins",
           ratio=rms(o[:, gap]) / rms(p[:, gap]), target="within 10 %")  # fmt: skip
    report("  epoch by epoch, median |hrgjax − pyins|", float(np.median(np.abs(o - p))), "m")
    tp, th = np.median(np.asarray(times), 0)
    report("  filter wall time, one 1-h flight at 20 Hz: hrgjax (after its first call)", th, "s",
           comparison="pyins / hrgjax", ratio=tp / th)  # fmt: skip


def ins_impact_through_the_mechanization():
    import hrgjax as hg
    from hrgjax.calibration import FourierCompensator, NoCompensation, run_plan, seed_plan
    from hrgjax.calibration import ins_impact as ii

    gyro = hg.presets.tvg3_like()
    key, bias_key = jax.random.key(0), jax.random.key(1)
    from hrgjax.data import concat

    static, rotation = seed_plan(quick=True)
    data = concat([
        run_plan(gyro, static, key=jax.random.key(2), bias_key=bias_key),
        run_plan(gyro, rotation, key=jax.random.key(3), bias_key=bias_key, first_run=static.size),
    ])  # fmt: skip
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


def speed(mot, runs=100):
    truth = mot.truth(100.0)
    tac = sensors.preset("tactical")
    settings = ekf.LooselyCoupled(tac, gnss.Gnss())

    @jax.jit
    def data(key):
        k1, k2, k3 = jax.random.split(key, 3)
        dth, dv = sensors.random_unit(tac, k1).apply(k2, truth.dtheta, truth.dv, truth.dt)
        return dth, dv, gnss.measure(truth, settings.gnss, k3)

    one = lambda d: ekf.loosely_coupled(settings, truth.initial, d[0], d[1], truth.dt, d[2])
    d = data(jax.random.key(0))
    jax.block_until_ready(one(d).nav.lat)  # compile
    t1 = best_of(lambda: one(d).nav.lat, repeat=3)
    report("1 h at 100 Hz, mechanization + 15-state filter (GNSS 1 Hz), one flight after compile",
           t1, "s", target="≤ 2 s")  # fmt: skip
    batch = jax.jit(jax.vmap(data))(jax.random.split(jax.random.key(1), runs))
    many = eqx.filter_jit(jax.vmap(one))
    jax.block_until_ready(many(batch).nav.lat)  # compile
    t0 = time.perf_counter()
    jax.block_until_ready(many(batch).nav.lat)
    tm = time.perf_counter() - t0
    report(f"  {runs} such flights vmapped, after compile", tm, "s",
           comparison="per flight, vmapped / alone", ratio=tm / runs / t1, target="≤ 60 s")  # fmt: skip


def main():
    arg = lambda name, default: (
        type(default)(sys.argv[sys.argv.index(name) + 1]) if name in sys.argv else default
    )
    runs, rate, n_pyins = arg("--runs", 100), arg("--rate", 20.0), arg("--pyins", 0)
    parts = arg("--only", "free,linear,monte-carlo,speed,pyins,ins-impact").split(",")
    print(f"machine: {machine()}")
    mot = motion.example()
    if "free" in parts or "linear" in parts:
        truth = free_integration(mot)
        if "linear" in parts:
            linear_vs_nonlinear(truth)
    if "monte-carlo" in parts:
        monte_carlo(mot, runs, rate)
    if "speed" in parts:
        speed(mot)
    if "pyins" in parts and "--pyins" in sys.argv:
        pyins_comparison(mot, n_pyins)
    if "ins-impact" in parts and "--ins-impact" in sys.argv:
        ins_impact_through_the_mechanization()


if __name__ == "__main__":
    main()
