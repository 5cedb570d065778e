"""Same shapes, new values: what compiles again (the compile audit's two findings).

1. `hg.sweep` with the default `cost="auto"` on four grids of the same sizes (4 rates × 2
   temperatures, 2-s averaged runs of an ideal-loop gyro) whose rates move from 0.1–3 to
   0.1–900 °/s: the chunk size used to follow the cost estimates, so new values compiled a
   new batch (and ≈ 11 small eager programs slicing its chunks).
2. `simulate(model="full")` with the default `fixed_step="auto"` at carrier frequencies 40,
   41, 40, 43 Hz (0.2 s) and `presets.tvg3_like()` at 20, 30, 20, 50 °C (0.01 s): the step
   count, static in the program, used to follow every new frequency or temperature.
3. `fog.compensation.compensate` with an Elman and an MLP compensator on three records of
   the same shape (20 s and 200 s at 100 Hz, 2-s windows, 1 g tones at 10, 12, 10 Hz): the
   Elman network's scan, called eagerly, traced a fresh closure and compiled again on every
   call.
4. `fog.compensation.fit` and `fit_end_to_end` (Elman and MLP, 3 epochs on two 16-s
   sequences at 50 Hz, 2-s windows) on two training sets of the same shape with other keys
   and learning rates: `fit` jitted a fresh closure over the loss and the data on every
   call, so each fit compiled its training program again.

5. `diagnosis.compare` (a 200-s scenario at 1 m/s² east, 3 faulty and 1 healthy runs; the
   three filter banks and the MLP classifier, 200 training windows) called twice with other
   keys, then `MLPClassifier.fit` (300 × 8 features, 4 classes, 50 steps) and `nn.train.rprop`
   (an `eqx.Partial` loss, then a closure, 30 steps) twice each: the banks' and detectors'
   runs were fresh `jax.jit(lambda …)`s, the gain schedules and Rprop eager scans over new
   closures, so a second call of the same shapes compiled them all again (a closure loss
   still does: it is traced afresh on every call, so it trains on what it reads now).

6. `--types` (the probe of every public entry point, session 27): the same values or shapes
   given as another number type, or an optional argument given: a weakly typed leaf
   (`jnp.asarray(650.0)`) in a gyro and a given `bias_key` (each compiled `simulate`'s solve
   again), `ImuModel.apply` called twice with the same arguments (an eager scan on a fresh
   closure), `fog.vibration.simulate` at a new latitude, `platform.simulate` with
   `t_fault=200` after `200.0`, `oadev` with `tau0` 1 / `np.float64`, `allan_deviation` with
   `dt` as `np.float64`, `gauss_markov_bridge` on a new length, `bench_time_h` of a new plan
   length.

7. `--settings` (session 28): a setting that is a value, not a shape, changed between two
   calls: `ins.flights.fly` with another Gauss–Markov correlation time (8 runs of a 60-s
   flight, Gauss–Markov filter states), `MLPCompensator.fit` with another learning rate,
   `FourierCompensator` with another `tolerance_c`, `nn.train.rprop(compile_once=True)` with
   another learning rate, `calibration.design` (40 steps) with another learning rate;
   `simulate` (an ideal gyro, 20 s) with another `rtol` and another `fixed_step`,
   `ins.strapdown.propagate` (12 h) with another `rtol`, `diagnosis.compare` (a 400-s
   scenario, the filter bank) with another fault onset, `calibration.design` with another
   `BenchModel(settle_s=…)`.

Each call prints the XLA compiles it caused (jax.monitoring) and its wall time.

Usage: `.venv/bin/python benchmarks/recompile_values.py [--no-full] [--fog] [--diagnosis]`
(`--fog`: only parts 3 and 4, ≈ 60 s; `--diagnosis`: only part 5, ≈ 60–120 s; `--types`: only
part 6, ≈ 60 s; `--settings`: only part 7, ≈ 60 s).
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.monitoring  # noqa: E402
import numpy as np  # noqa: E402

import hrgjax as hg  # noqa: E402

_COUNTS: list = []


def _listen(event, duration, **kw):
    if event == "/jax/core/compile/backend_compile_duration" and _COUNTS:
        _COUNTS[-1].append(kw.get("fun_name"))


_MATCH: list = []  # --match: only the calls whose label holds one of these


def counted(label, run):
    if _MATCH and not any(m in label for m in _MATCH):
        return 0, 0.0
    _COUNTS.append([])
    t0 = time.perf_counter()
    jax.block_until_ready(run())
    dt = time.perf_counter() - t0
    names = _COUNTS.pop()
    print(f"{label}: {len(names)} compiles, {dt:.3f} s  {names}", flush=True)
    return len(names), dt


def sweeps():
    gyro = hg.presets.ideal(hg.Resonator(omega=2 * np.pi * 40.0, tau=50.0, k_e=0.554))

    def fn(rate_dps, temperature_c):
        p = hg.Profile.constant_rate(rate_dps=rate_dps, duration_s=2.0,
                                     temperature_c=temperature_c, wave_angle0_deg=10.0)  # fmt: skip
        return hg.simulate(gyro, p, dt_out=0.5).wave_angle[-1]

    grids = {
        "A (0.1–3 °/s)": ([0.1, 1.0, 2.0, 3.0], [20.0, 30.0]),
        "B (0.2–3.5 °/s)": ([0.2, 1.5, 2.5, 3.5], [22.0, 32.0]),
        "C (0.1–800 °/s)": ([0.1, 5.0, 400.0, 800.0], [21.0, 31.0]),
        "D (0.1–900 °/s)": ([0.1, 6.0, 300.0, 900.0], [21.0, 31.0]),
    }
    for label, (w, t) in grids.items():
        w, t = np.asarray(w), np.asarray(t)
        counted(f"sweep grid {label}", lambda w=w, t=t: hg.sweep(fn, rate_dps=w, temperature_c=t))
    w, t = (np.asarray(x) for x in grids["C (0.1–800 °/s)"])
    counted("sweep grid C, cost=None", lambda: hg.sweep(fn, cost=None, rate_dps=w, temperature_c=t))


def full_runs():
    prof = hg.Profile.constant_rate(rate_dps=1.0, duration_s=0.2, temperature_c=20.0,
                                    wave_angle0_deg=10.0)  # fmt: skip
    for f_hz in (40.0, 41.0, 40.0, 43.0):
        g = hg.presets.ideal(hg.Resonator(omega=2 * np.pi * f_hz, tau=50.0, k_e=0.554))
        counted(f"full, {f_hz:g} Hz",
                lambda g=g: hg.simulate(g, prof, model="full", dt_out=0.05).wave_angle)  # fmt: skip
    gyro = hg.presets.tvg3_like()
    key = jax.random.key(0)
    for temp in (20.0, 30.0, 20.0, 50.0):
        p = hg.Profile.static(duration_s=0.01, temperature_c=temp, wave_angle0_deg=10.0)
        counted(f"full, tvg3_like at {temp:g} °C",
                lambda p=p: hg.simulate(gyro, p, model="full", dt_out=0.005, key=key).wave_angle)  # fmt: skip


def fog_calls():
    from hrgjax.fog import compensation as cp
    from hrgjax.fog import vibration as vb

    imu = vb.default_imu()
    box = ((5.0, 40.0), (0.25, 1.5))  # untrained networks: the calls' cost is the same
    for kind in cp.KINDS:
        comp = cp.VibrationCompensator(kind, key=jax.random.key(4), window_s=2.0,
                                       axis=(0.0, 0.0, 1.0), feature_range=box)  # fmt: skip
        for dur in (20.0, 200.0):
            for i, f_hz in enumerate((10.0, 12.0, 10.0)):
                sch = vb.VibrationSchedule.constant(f_hz, 1.0, dur)
                rec = vb.simulate(imu, sch, fs=100.0, key=jax.random.key(i))
                counted(f"compensate, {kind}, {dur:g} s, {f_hz:g} Hz",
                        lambda c=comp, r=rec: cp.compensate(c, imu, r).gyro)  # fmt: skip


def fog_fits():
    from hrgjax.fog import compensation as cp
    from hrgjax.fog import vibration as vb

    imu = vb.default_imu()
    kw = dict(fs=50.0, window_s=2.0, lead_s=2.0, on_s=10.0, off_s=4.0)
    sets = [cp.training_set(imu, conds, key=jax.random.key(i), **kw)
            for i, conds in enumerate(([(10.0, 0.5), (20.0, 1.0)], [(12.0, 0.6), (18.0, 0.9)]))]  # fmt: skip
    for kind in cp.KINDS:
        for i, data in enumerate(sets):
            comp = cp.VibrationCompensator(kind, key=jax.random.key(10 + i))
            fit = dict(key=jax.random.key(20 + i), epochs=3, learning_rate=0.01 * (i + 1))
            counted(f"fit, {kind}, set {i}", lambda c=comp, d=data, f=fit: cp.fit(c, d, **f)[1])
        for i, data in enumerate(sets):
            comp = cp.VibrationCompensator(kind, key=jax.random.key(10 + i))
            fit = dict(key=jax.random.key(20 + i), epochs=3, learning_rate=0.01 * (i + 1))
            counted(f"fit_end_to_end, {kind}, set {i}",
                    lambda c=comp, d=data, f=fit: cp.fit_end_to_end(c, imu, d, **f)[1])  # fmt: skip


def diagnosis_calls():
    import jax.numpy as jnp

    from hrgjax.diagnosis import compare as cp
    from hrgjax.diagnosis import neural as nl
    from hrgjax.nn import train

    sc = cp.Scenario("short", t_fault=150.0, duration=200.0, specific_force=(1.0, 0.0, 0.0))
    kw = dict(n_faulty=3, n_healthy=1, n_train=2, n_windows=200,
              methods=("filter_bank", "filter_bank_rest", "filter_bank_full", "mlp_classifier"))  # fmt: skip
    for i in range(2):
        counted(
            f"compare, call {i + 1}", lambda i=i: cp.compare(sc, key=jax.random.key(3 + i), **kw)
        )
    k = jax.random.key(0)
    x = jax.random.normal(k, (300, 8))
    y = jax.random.randint(jax.random.fold_in(k, 1), (300,), 0, 4)
    for i in range(2):
        counted(f"MLPClassifier.fit, call {i + 1}",
                lambda i=i: nl.MLPClassifier.fit(x, y, 4, key=jax.random.key(6 + i), steps=50))  # fmt: skip
    import equinox as eqx

    # an eqx.Partial of a module-level loss with compile_once=True: compiled once; a
    # closure (the default path): traced on every call
    t = jnp.array([1.0, -2.0, 3.0])
    partial = eqx.Partial(_quartic, t=t)
    closure = lambda p: jnp.sum((p - t) ** 4)
    for name, loss, once in (("eqx.Partial", partial, True), ("closure", closure, False)):
        for i in range(2):
            counted(f"rprop, one {name} loss (compile_once={once}), call {i + 1}",
                    lambda loss=loss, once=once: train.rprop(loss, jnp.zeros(3), 30, 1e-2,
                                                             compile_once=once))  # fmt: skip


def type_calls():
    import equinox as eqx
    import jax.numpy as jnp

    from hrgjax import calibration as cal
    from hrgjax.fog import vibration as vb
    from hrgjax.ins import motion, platform, sensors

    res = hg.Resonator(omega=hg.TemperatureLaw(2 * np.pi * 40.0), tau=hg.TemperatureLaw(600.0))
    gyro, prof = hg.presets.ideal(res), hg.Profile.constant_rate(1.0, 1.0)
    counted(
        "simulate, tau a Python float",
        lambda: (
            hg.simulate(
                eqx.tree_at(lambda g: g.resonator.tau, gyro, 640.0), prof, dt_out=0.5
            ).wave_angle
        ),
    )
    counted(
        "simulate, tau jnp.asarray(650.0) (weak)",
        lambda: (
            hg.simulate(
                eqx.tree_at(lambda g: g.resonator.tau, gyro, jnp.asarray(650.0)), prof, dt_out=0.5
            ).wave_angle
        ),
    )
    noisy = hg.presets.tvg3_like()
    run = lambda **kw: hg.simulate(noisy, prof, key=jax.random.key(0), dt_out=0.5, **kw)  # noqa: E731
    counted("simulate with noise, key only", lambda: run().wave_angle)
    counted(
        "simulate with noise, bias_key given", lambda: run(bias_key=jax.random.key(3)).wave_angle
    )

    still = motion.Segment(1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 30.0)
    truth = motion.Motion(45.0, 30.0, 100.0, (0.0, 0.0, 0.0), 45.0, 0.0, 0.0, (still,))
    imu, truth = sensors.ImuModel(), truth.truth(rate_hz=20.0)
    for i in range(2):
        counted(f"ImuModel.apply, same arguments, call {i + 1}",
                lambda: imu.apply(jax.random.key(0), truth.dtheta, truth.dv, truth.dt))  # fmt: skip

    schedule = vb.VibrationSchedule.on_off([(10.0, 1.0)], on_s=4.0, off_s=2.0, lead_s=1.0)
    for lat in (45.0, 40.0):
        counted(
            f"fog.vibration.simulate, lat_deg={lat}",
            lambda lat=lat: (
                vb.simulate(
                    vb.default_imu(), schedule, fs=100.0, key=jax.random.key(0), lat_deg=lat
                ).gyro
            ),
        )

    ins = platform.PlatformINS(lat=0.785)
    for t_fault in (200.0, 200):
        counted(
            f"platform.simulate, t_fault={t_fault!r}",
            lambda t_fault=t_fault: platform.simulate(
                ins,
                dt=1.0,
                n_steps=300,
                key=jax.random.key(1),
                fault=platform.Fault.on("accel_y", 2e-7, t_fault),
            ),
        )

    y = np.random.default_rng(4).normal(size=333)
    for tau0 in (1.0, 1, np.float64(1.0)):
        counted(f"oadev, tau0={tau0!r}", lambda tau0=tau0: hg.allan.oadev(y, 2, tau0))
    for dt in (0.1, np.float64(0.1)):
        counted(f"allan_deviation, dt={dt!r}", lambda dt=dt: hg.allan_deviation(y, dt)[1])
    for n in (37, 38):
        dts = np.full(n, 0.5)
        counted(f"gauss_markov_bridge, {n} intervals",
                lambda dts=dts: hg.noise.gauss_markov_bridge(dts, 1.0, 50.0))  # fmt: skip

    def plan(n):
        seg = {"kind": "static", "temperature_c": 20.0, "wave_angle_deg": 0.0, "duration_s": 60.0}
        ramp = {"kind": "ramp", "temperature_start_c": 20.0, "temperature_end_c": 30.0,
                "wave_angle_deg": 0.0, "duration_s": 900.0}  # fmt: skip
        return cal.BenchPlan.from_segments([seg] * (n - 1) + [ramp])

    for n in (5, 6):
        counted(f"bench_time_h, a plan of {n} segments", lambda n=n: cal.bench_time_h(plan(n)))


def settings_calls():
    import equinox as eqx

    from hrgjax import calibration as cal
    from hrgjax.calibration import design
    from hrgjax.ins import ekf, flights, gnss, motion, sensors
    from hrgjax.nn import train

    seg = motion.Segment(3, (0.0, 0.0, 20.0), (0.0, 0.0, 0.0), 60.0)
    truth = motion.Motion(40.0, 10.0, 200.0, (20.0, 0.0, 0.0), 10.0, 0.0, 0.0, (seg,)).truth(10.0)
    for tau in (600.0, 60.0):
        imu = sensors.ImuModel(gyro_bias=1e-5, accel_bias=5e-4, arw=3e-6, vrw=1e-4,
                               gyro_bias_instability=1e-4, accel_bias_instability=5e-3,
                               gyro_correlation_time=tau, accel_correlation_time=tau)  # fmt: skip
        settings = ekf.LooselyCoupled(imu, gnss.Gnss(), gauss_markov=True)
        counted(f"flights.fly, τ = {tau:g} s",
                lambda imu=imu, s=settings: flights.fly(truth, imu, s, key=jax.random.key(0),
                                                        runs=8).nis)  # fmt: skip
    data = hg.presets.tvg3_like(noise=False)
    plan = cal.static_plan((0.0, 40.0), (-45.0, 0.0, 45.0), duration_s=30.0, dt_out=0.5)
    rot = cal.rotation_plan((0.0, 40.0), (-45.0, 0.0, 45.0), duration_s=30.0, dt_out=0.5)
    bench = hg.data.concat([cal.run_plan(data, plan),
                            cal.run_plan(data, rot, first_run=plan.size)])  # fmt: skip
    for rate in (1e-3, 3e-3):
        comp = cal.MLPCompensator(steps=40, learning_rate=rate)
        counted(
            f"MLPCompensator.fit, learning_rate {rate:g}",
            lambda c=comp: c.fit(bench, key=jax.random.key(0)).drift_dph([0.0], 20.0),
        )
    for tol in (25.0, 30.0):
        comp = cal.FourierCompensator(tolerance_c=tol)
        counted(
            f"FourierCompensator(tolerance_c={tol:g}).fit, drift_dph",
            lambda c=comp: c.fit(bench).drift_dph([0.0], 20.0),
        )
    loss = eqx.Partial(_quartic, t=jax.numpy.ones(4))
    for rate in (1e-2, 3e-2):
        counted(
            f"rprop(compile_once=True), learning_rate {rate:g}",
            lambda r=rate: train.rprop(loss, jax.numpy.zeros(4), 30, r, compile_once=True),
        )
    gyro = hg.presets.ideal(hg.Resonator(omega=2 * np.pi * 40.0, tau=50.0, k_e=0.554))
    prof = hg.Profile.constant_rate(10.0, 20.0)
    for kw in (dict(rtol=1e-8), dict(rtol=1e-6), dict(fixed_step=0.01), dict(fixed_step=0.02)):
        counted(f"simulate, {kw}", lambda kw=kw: hg.simulate(gyro, prof, dt_out=0.5, **kw))
    from hrgjax.ins import constants, strapdown, trajectory

    traj = trajectory.constant_velocity(30.0, duration_s=12 * 3600.0, dt=60.0,
                                        earth=constants.SPHERE)  # fmt: skip
    for rtol in (1e-10, 1e-9):
        counted(f"strapdown.propagate, rtol {rtol:g}",
                lambda r=rtol: strapdown.propagate(traj, jax.numpy.zeros(9).at[6].set(1e-4),
                                                   altitude_aided=True, rtol=r))  # fmt: skip
    import dataclasses

    from hrgjax.diagnosis import compare

    scenario = compare.Scenario("short", t_fault=300.0, duration=400.0)
    for onset in (300.0, 320.0):
        sc = dataclasses.replace(scenario, t_fault=onset)
        counted(f"diagnosis.compare, t_fault {onset:g} s",
                lambda sc=sc: compare.compare(sc, key=jax.random.key(3), n_faulty=3, n_healthy=1,
                                              n_train=2, methods=("filter_bank",),
                                              n_windows=600)["methods"][0]["detected"])  # fmt: skip
    for rate in (0.1, 0.05):
        counted(f"calibration.design, learning_rate {rate:g}",
                lambda r=rate: design.design(2.5, levels=(2,), statics=2, rotations=1, steps=40,
                                             learning_rate=r).value)  # fmt: skip
    from hrgjax.ins import platform

    for g in (9.80665, 9.7):
        ins = platform.PlatformINS(g=g, radius=6.3e6)
        counted(f"ins.platform.simulate, PlatformINS(g={g:g})",
                lambda i=ins: platform.simulate(i, dt=1.0, n_steps=600,
                                                key=jax.random.key(0))[1])  # fmt: skip
    if not _MATCH or any(m in "PhysicalCompensator" for m in _MATCH):
        temps, angles = (-40.0, 20.0, 60.0), tuple(range(-90, 90, 30))  # test_calibration's
        physical_bench = hg.data.concat([
            cal.run_plan(data, cal.static_plan(temps, angles, duration_s=60.0, dt_out=0.5)),
            cal.run_plan(data, cal.rotation_plan(temps, angles, duration_s=60.0, dt_out=0.5),
                         first_run=18),
        ])  # fmt: skip
        for k_e in (0.554, 0.56):
            counted(
                f"PhysicalCompensator(k_e={k_e:g}).fit",
                lambda k=k_e: cal.PhysicalCompensator(k_e=k).fit(physical_bench).values,
            )
    for settle in (1800.0, 1700.0):
        bench_model = design.BenchModel(settle_s=settle)
        counted(f"calibration.design, BenchModel(settle_s={settle:g})",
                lambda b=bench_model: design.design(2.5, levels=(2,), statics=2, rotations=1,
                                                    steps=40, bench=b).value)  # fmt: skip


def _quartic(p, *, t):
    return ((p - t) ** 4).sum()


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--no-full", action="store_true", help="only the sweeps (and --fog's)")
    ap.add_argument("--fog", action="store_true", help="only the FOG compensation and fit calls")
    ap.add_argument("--diagnosis", action="store_true", help="only diagnosis.compare and training")
    ap.add_argument("--types", action="store_true", help="only part 6: number types, options")
    ap.add_argument("--settings", action="store_true", help="only part 7: settings as values")
    ap.add_argument(
        "--match",
        action="append",
        default=[],
        help="only the calls whose label holds this text (repeatable)",
    )
    a = ap.parse_args()
    _MATCH.extend(a.match)
    jax.monitoring.register_event_duration_secs_listener(_listen)
    if a.types:
        type_calls()
        raise SystemExit
    if a.settings:
        settings_calls()
        raise SystemExit
    if a.diagnosis:
        diagnosis_calls()
        raise SystemExit
    if not a.fog:
        sweeps()
        if not a.no_full:
            full_runs()
    fog_calls()
    fog_fits()
