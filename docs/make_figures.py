"""Figures for the docs, written to docs/figures/ (git-ignored): `make docs` runs this first.

`python docs/make_figures.py [--jobs N] [--fresh] [NAME …]` makes all figures, or only the
named ones (function names below), N at a time in separate processes, printing each as it is
done. Each figure's files are kept in hrgjax's cache (`<cache>/figures/<key>/<name>/`),
keyed by the SHA-256 of this script, every source file of the package, the data file the
figures read and the versions of JAX and its libraries: while none of those change, the
figure is copied back instead of recomputed (`--fresh` or `HRGJAX_NO_CACHE=1` recompute). The
compile cache is on too, so a figure whose code changed recompiles only what changed."""

import os

from hrgjax._threads import widen_cpu_thread_pool

# Before JAX's CPU backend starts, here and in the figure processes (they inherit it): on two
# cores the navigation figure's batched LU (20 filters under `vmap`) wedged XLA's pool, every
# thread waiting in `ParallelBatchMap` (hrgjax/_threads.py).
widen_cpu_thread_pool()

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import hrgjax as hg  # noqa: E402

HERE = os.path.join(os.path.dirname(__file__), "figures")
PSINS = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "psins_lasergyro.imu")


def full_vs_averaged():
    res = hg.Resonator(
        omega=2 * np.pi * 40,
        tau=20.0,
        delta_inv_tau=0.02,
        theta_tau=0.3,
        delta_omega=0.05,
        theta_omega=-0.3,
    )
    gyro = hg.Gyro(res, readout=hg.Readout(gain_mismatch=0.005))
    prof = hg.Profile.constant_rate(1.0, 20.0, wave_angle0_deg=10.0)
    full = hg.simulate(gyro, prof, model="full", dt_out=0.05)
    avg = hg.simulate(gyro, prof, model="averaged", dt_out=0.05)
    fig, (a, b) = plt.subplots(2, 1, figsize=(7, 5), sharex=True, constrained_layout=True)
    ideal = np.deg2rad(10.0) - 0.554 * np.asarray(full.table_angle)
    a.plot(full.t, np.rad2deg(full.wave_angle - ideal), label="full (carrier resolved)")
    a.plot(avg.t, np.rad2deg(avg.wave_angle - ideal), "--", label="averaged")
    a.set_ylabel("wave angle − ideal [°]")
    a.legend()
    b.plot(full.t, np.rad2deg(full.wave_angle - avg.wave_angle) * 3600)
    b.set_ylabel("full − averaged [″]")
    b.set_xlabel("time [s]")
    fig.savefig(os.path.join(HERE, "full_vs_averaged.png"), dpi=110)
    plt.close(fig)


def allan():
    from hrgjax.plots import allan_figure

    gyro = hg.presets.tvg3_like(temperature_laws=False)
    rec = hg.simulate(gyro, hg.Profile.static(20000.0), key=jax.random.key(0), dt_out=1.0)
    rate = -np.diff(np.asarray(rec.wave_angle)) / 0.554 / hg.units.DEG_PER_H
    result = hg.allan.deviation(rate - rate.mean(), 1.0)
    fit = hg.allan.fit_noise(result)
    allan_figure(result, os.path.join(HERE, "allan.png"), fit=fit, unit="°/h",
                 title="default gyro at rest, 20 000 s at 1 Hz")  # fmt: skip


def allan_model():
    from hrgjax.plots import allan_figure

    gyro = hg.presets.tvg3_like(temperature_laws=False)
    rec = hg.simulate(gyro, hg.Profile.static(20000.0), key=jax.random.key(0), dt_out=1.0)
    rate = -np.diff(np.asarray(rec.wave_angle)) / 0.554 / hg.units.DEG_PER_H
    result = hg.allan.deviation(rate - rate.mean(), 1.0, unit="°/h")
    model = hg.allan.identify_noise(rate - rate.mean(), 1.0, unit="°/h")
    allan_figure(result, os.path.join(HERE, "allan_model.png"), fit=model, unit="°/h",
                 title="default gyro at rest: the identified noise model")  # fmt: skip


def bench_plan():
    from hrgjax.calibration import design
    from hrgjax.plots import plan_figure

    plan_figure(design.seed_bench_plan(), os.path.join(HERE, "seed_plan.png"),
                title="the seed's calibration plan as one bench session")  # fmt: skip


def design_budgets():
    """Predicted compensated drift error vs bench time: plans designed within 3–36 h and the
    seed's plans (the criterion `design` minimises: ARW, readout and Gauss–Markov noise)."""
    import matplotlib.pyplot as plt

    from hrgjax.calibration import design

    budgets = (3.0, 6.0, 12.0, 24.0, 36.0)
    designed = [design.design(b, criterion="drift") for b in budgets]
    seeds = [design.seed_bench_plan(quick=True), design.seed_bench_plan()]
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    ax.loglog([r.bench_time_h for r in designed], [r.value for r in designed], "o-",
              color="C2", label="designed (gradient search)")  # fmt: skip
    ax.loglog([float(design.bench_time_h(p)) for p in seeds],
              [float(design.criterion(p, "drift")) for p in seeds], "s", color="C3", ms=8,
              label="seed plans (3 and 11 temperatures)")  # fmt: skip
    ax.set_xlabel("bench time, transitions included [h]")
    ax.set_ylabel("predicted compensated drift error [°/h]")
    ax.set_title("accuracy vs bench time (prediction: ideal-loop grey box)",
                 fontsize=10)  # fmt: skip
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=9)
    fig.savefig(os.path.join(HERE, "design_budgets.png"), dpi=110)
    plt.close(fig)


def imu():
    from hrgjax.plots import imu_session_figure

    rng = np.random.default_rng(1)
    truth = hg.imu.ImuCalibration.known(
        accel_matrix=np.eye(3) + rng.normal(0, 0.01, (3, 3)),
        accel_bias=[0.1, -0.05, 0.2],
        gyro_matrix=np.eye(3) + rng.normal(0, 0.01, (3, 3)),
        gyro_bias=np.deg2rad([0.5, -0.3, 0.1]),
        gyro_g_sensitivity=rng.normal(0, 1e-4, (3, 3)),
    )
    data, _ = hg.imu.ferraris_session(truth, jax.random.key(0))
    cal = hg.imu.ferraris(data)
    imu_session_figure(data, hg.imu.detect_sections(data), os.path.join(HERE, "imu.png"),
                       calibration=cal)  # fmt: skip


def presets():
    from hrgjax.calibration import scale_factor_vs_angle, seed_plan, static_drift
    from hrgjax.plots import drift_and_scale_factor

    gyro = hg.presets.tvg3_like()
    static, rotation = seed_plan()
    key = jax.random.key(0)
    d = hg.calibration.run_plan(gyro, static, key=key)
    r = hg.calibration.run_plan(gyro, rotation, key=jax.random.fold_in(key, 1))
    drift_and_scale_factor(
        static_drift(d),
        scale_factor_vs_angle(r),
        os.path.join(HERE, "tvg3_drift_sf.png"),
        "tvg3_like()",
    )


def calibration():
    from hrgjax.calibration import compare, run_study, test_plan
    from hrgjax.calibration.evaluate import SEED_TABLE
    from hrgjax.calibration.study import bench_session
    from hrgjax.plots import compensation_residuals, error_vs_temperature

    study = run_study(key=jax.random.key(0), quick=True, ins=False)  # the figures need no flights
    compensation_residuals(
        study.windows, study.compensators, os.path.join(HERE, "calibration_residuals.png")
    )
    error_vs_temperature(study.table, os.path.join(HERE, "calibration_errors.png"), SEED_TABLE)
    # the test grid again in another switch-on: its offset apart from what is left
    second = bench_session(hg.presets.tvg3_like(), test_plan(True), key=jax.random.key(43),
                           bias_key=jax.random.key(42))  # fmt: skip
    compare(
        study.compensators, second, name="the test grid in another switch-on", warn=False
    ).plot(  # the +20 °C baseline outside its range: drawn hollow
        os.path.join(HERE, "calibration_second_session.png")
    )


def discovery():
    from hrgjax.discovery import discover
    from hrgjax.discovery.generate import continuous_dataset, hidden_effect_dataset

    data = hidden_effect_dataset("damping_anisotropy_temperature", -0.04, key=jax.random.key(0))
    discover(data).plot(os.path.join(HERE, "discovery_dwell.png"))
    data = continuous_dataset("thermal_lag", 0.01, key=jax.random.key(0))
    discover(data).plot(os.path.join(HERE, "discovery_continuous.png"))


def ins():
    import jax.numpy as jnp

    from hrgjax.ins import alignment, strapdown, trajectory
    from hrgjax.ins.constants import SPHERE
    from hrgjax.plots import alignment_figure, schuler_figure

    traj = trajectory.stationary(45.0, duration_s=4 * 3600.0, dt=30.0, earth=SPHERE)
    runs = {
        "initial tilt 0.1 mrad about east → north error": (
            jnp.zeros(9).at[7].set(1e-4),
            None,
            None,
        ),
        "accelerometer bias 0.1 mg north → north error": (None, None, jnp.array([9.8e-4, 0, 0])),
        "gyro bias 0.01 °/h about north → east error": (None, jnp.array([4.85e-8, 0, 0]), None),
    }
    pos = {}
    for label, (dx0, g, a) in runs.items():
        dx = strapdown.propagate(traj, dx0, g, a, altitude_aided=True)
        axis = 1 if "east error" in label else 0
        pos[label] = strapdown.position_metres(traj, dx)[:, axis]
    schuler_figure(traj.t, pos, os.path.join(HERE, "ins_schuler.png"))
    if os.path.isfile(PSINS):
        log = alignment.load_psins(PSINS)
        alignment_figure(alignment.align(log), os.path.join(HERE, "ins_alignment.png"),
                         log.header_attitude_deg)  # fmt: skip


def diagnosis():
    from hrgjax.diagnosis.compare import compare
    from hrgjax.plots import diagnosis_figure

    # less training than the default (1 500 windows, 200 predictor samples, 10 LM steps):
    # every method still names the right INS within 3 s on this run, in 2/3 of the time
    res = compare("stationary", key=jax.random.key(0), n_faulty=3, n_healthy=1, traces=True,
                  n_windows=1500, n_predictor=200, predictor_steps=10)  # fmt: skip
    diagnosis_figure(res["traces"], os.path.join(HERE, "diagnosis_stationary.png"), "stationary")


def vibration():
    from hrgjax.fog.study import run
    from hrgjax.plots import vibration_figure

    res = run("on_off", key=jax.random.key(0))
    vibration_figure(res["_figures"], os.path.join(HERE, "fog_vibration.png"))


def adjoint_memory():
    """Peak memory (XLA's account of the compiled program) of the forward run and of its
    gradient against run length; the full table is benchmarks/adjoint_memory.py's."""
    import diffrax
    import equinox as eqx

    gyro = hg.presets.tvg3_like(noise=False)
    params, static = eqx.partition(gyro.resonator, eqx.is_inexact_array)

    from hrgjax._compiled import callback_free

    def peak(fn, *args):
        # traced as hrgjax's own programs are (checks in NaN form, no host callback), so the
        # compile cache keeps them and a second `make docs` loads instead of compiling
        with callback_free():
            m = jax.jit(fn).lower(params, *args).compile().memory_analysis()
        return (m.temp_size_in_bytes + m.argument_size_in_bytes + m.output_size_in_bytes) / 1e3

    def final_loss(p, prof):
        # the profile (its length included) is an argument: the gradient of the final angle is
        # one program for every length, so its memory is measured once
        g = eqx.tree_at(lambda g: g.resonator, gyro, eqx.combine(p, static))
        ts = jnp.stack([prof.t[0], prof.t[-1]])
        return jnp.mean(hg.simulate(g, prof, ts=ts).wave_angle ** 2)

    lengths = np.array([225.0, 900.0, 3600.0])
    final = peak(jax.grad(final_loss), hg.Profile.piecewise([0.0, 1.0], [5.0, 5.0], [-40.0, 20.0]))
    rows = []
    for length in lengths:
        prof = hg.Profile.piecewise([0.0, length], [5.0, 5.0], [-40.0, 20.0])

        def loss(p, adjoint=None, prof=prof):
            g = eqx.tree_at(lambda g: g.resonator, gyro, eqx.combine(p, static))
            return jnp.mean(hg.simulate(g, prof, adjoint=adjoint, dt_out=1.0).wave_angle ** 2)

        store_all = diffrax.RecursiveCheckpointAdjoint(int(5.2 * length))  # ≥ steps (5.13/s)
        rows.append([
            peak(loss),
            peak(jax.grad(loss)),
            peak(jax.grad(lambda p, a=store_all, loss=loss: loss(p, a))),
            final,
        ])  # fmt: skip
    rows = np.array(rows)
    fig, ax = plt.subplots(figsize=(6.5, 4), constrained_layout=True)
    h = lengths / 3600
    ax.loglog(h, rows[:, 0], "o-", label="forward, 1-s outputs")
    ax.loglog(h, rows[:, 1], "s-", label="gradient, 256 checkpoints (default)")
    ax.loglog(h, rows[:, 2], "^--", label="gradient, a checkpoint per step")
    ax.loglog(h, rows[:, 3], "d:", label="gradient, final-angle loss")
    ax.set_xlabel("run length [h]")
    ax.set_ylabel("peak memory [kB]")
    ax.set_title("averaged model, warm-up run: memory against length")
    ax.legend(fontsize=8)
    fig.savefig(os.path.join(HERE, "adjoint_memory.png"), dpi=120)
    plt.close(fig)


def ftr_run():
    """A force-to-rebalance run of the default gyro: held at 70°, switched to 160° (mode
    reversal) while the case turns at 0.01 °/s."""
    gyro = hg.presets.tvg3_like(temperature_laws=False).in_mode("ftr")
    prof = hg.Profile.held_angles([70.0, 160.0], dwell_s=300.0, slew_s=20.0, rate_dps=0.01)
    rec = hg.simulate(gyro, prof, key=jax.random.key(0), dt_out=1.0)
    t = np.asarray(rec.t)
    fig, (a0, a1) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    a0.plot(t, np.asarray(rec.wave_angle) / hg.units.DEG, lw=1)
    a0.set_ylabel("wave angle [° el.]")
    a0.set_title("force-to-rebalance: the wave held at 70°, then at 160°")
    rate = np.asarray(rec.rebalance_rate) / hg.units.DEG_PER_H
    a1.plot(t, rate, lw=0.6, color="0.6", label="FTR output (1-s samples)")
    k = 30
    a1.plot(t[k // 2 : -k // 2 + 1], np.convolve(rate, np.ones(k) / k, "valid"), lw=1.5,
            label="30-s mean")  # fmt: skip
    a1.axhline(36.0, ls="--", color="k", lw=0.8, label="input 0.01 °/s = 36 °/h")
    a1.set_ylim(30, 42)
    a1.set_ylabel("rate [°/h]")
    a1.set_xlabel("time [s]")
    a1.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, "ftr_run.png"), dpi=120)
    plt.close(fig)


def virtual_precession():
    """The drift the sweeps identify at rest against the gyro's own static drift."""
    from hrgjax.calibration import self_calibration as sc

    gyro = hg.presets.tvg3_like()
    key, bias = jax.random.split(jax.random.key(0))
    temps = (-40.0, 20.0, 60.0)
    data = sc.run_precession_plan(gyro, sc.precession_plan(temps), key=key, bias_key=bias)
    comp = sc.PrecessionCompensator().fit(data)
    switch_on = float(hg.noise.draw_run_bias(bias, gyro.noise))  # the session's own bias
    angles = np.arange(-90.0, 91.0, 15.0)
    fig, ax = plt.subplots(figsize=(7, 4))
    fine = np.linspace(-90.0, 90.0, 181)
    for temp, color in zip(temps, ("C0", "C1", "C3"), strict=True):
        clean = gyro.without_noise()
        base = hg.Profile.static(60.0, temp)

        def one(a, base=base, clean=clean):
            p = eqx.tree_at(lambda q: q.wave_angle0, base, a)
            return hg.simulate(clean, p, dt_out=1.0).wave_angle

        wave = jax.vmap(one)(jnp.asarray(angles * hg.units.DEG))
        wave = np.asarray(wave)
        truth = -(wave[:, 50] - wave[:, 20]) / 30.0 / comp.k_e + switch_on
        truth = truth / hg.units.DEG_PER_H
        ax.plot(fine, comp.drift_dph(fine, temp), color=color, label=f"self-calibration {temp:+.0f} °C")
        ax.plot(angles, truth, "o", color=color, ms=4)
    ax.plot([], [], "o", color="k", ms=4, label="static runs without noise (+ the session's switch-on bias)")
    ax.set_xlabel("measured wave angle [° electrical]")
    ax.set_ylabel("drift at rest [°/h]")
    ax.set_title("virtual precession at rest: the identified drift law")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, "virtual_precession.png"), dpi=120)
    plt.close(fig)


def navigation():
    """The example flight: 20 tactical-grade Monte Carlo runs with a 60-s GNSS outage."""
    from hrgjax.ins import ekf, flights, gnss, motion, sensors

    truth = motion.example().truth(20.0)
    imu = sensors.preset("tactical")
    settings = ekf.LooselyCoupled(imu, gnss.Gnss(outages=((1400.0, 1460.0),)))
    runs = flights.fly(truth, imu, settings, key=jax.random.key(0), runs=20)
    from hrgjax.plots import navigation_figure

    navigation_figure(truth, runs, os.path.join(HERE, "navigation.png"))


FIGURES = (  # longest first (cold, 2 cores), so that the workers finish together
    diagnosis,
    vibration,
    discovery,
    adjoint_memory,
    calibration,
    presets,
    ins,
    full_vs_averaged,
    allan,
    allan_model,
    virtual_precession,
    navigation,
    ftr_run,
    imu,
    bench_plan,
    design_budgets,
)


def _key() -> str:
    """SHA-256 of what the figures depend on: this script, the package's sources, the data
    file `ins` reads (its size and time: it is large) and the library versions."""
    import hashlib
    import importlib.metadata as md
    from pathlib import Path

    h = hashlib.sha256()
    root = Path(__file__).resolve().parent.parent
    files = [Path(__file__).resolve()] + sorted((root / "hrgjax").rglob("*.py"))
    for f in files:
        h.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes() + b"\0")
    if os.path.isfile(PSINS):
        st = os.stat(PSINS)
        h.update(f"psins {st.st_size} {st.st_mtime_ns}".encode())
    for lib in ("jax", "jaxlib", "equinox", "diffrax", "optax", "optimistix", "matplotlib"):
        h.update(f"{lib}={md.version(lib)};".encode())
    return h.hexdigest()[:24]


def _stored(key: str, name: str):
    """The cached folder of figure `name` under `key` (None when the cache is off)."""
    from hrgjax._cache import cache_dir, cache_disabled

    return None if cache_disabled() else cache_dir() / "figures" / key / name


def _make(name: str, key: str, fresh: bool) -> tuple[float, bool]:
    """Make one figure (in a worker process), or copy it from the cache: (wall time [s],
    whether it came from the cache)."""
    import shutil
    import tempfile
    import time

    global HERE
    out = HERE
    os.makedirs(out, exist_ok=True)
    t0 = time.perf_counter()
    stored = _stored(key, name)
    if stored is not None and not fresh and (stored / "done").is_file():
        for f in stored.iterdir():
            if f.name != "done":
                shutil.copy2(f, os.path.join(out, f.name))
        return time.perf_counter() - t0, True
    hg.enable_cache()  # shared by the workers; a second `make docs` loads what the first compiled
    with tempfile.TemporaryDirectory() as tmp:
        HERE = tmp  # the figure functions write to HERE: collect this figure's files alone
        try:
            globals()[name]()
        finally:
            HERE = out
        made = sorted(os.listdir(tmp))
        for f in made:
            shutil.copy2(os.path.join(tmp, f), os.path.join(out, f))
        if stored is not None:
            try:
                part = stored.with_name(f"{name}.{os.getpid()}.part")
                shutil.rmtree(part, ignore_errors=True)
                part.mkdir(parents=True)
                for f in made:
                    shutil.copy2(os.path.join(tmp, f), part / f)
                (part / "done").write_text("\n".join(made))
                shutil.rmtree(stored, ignore_errors=True)
                os.replace(part, stored)
            except OSError as err:  # a read-only or full cache costs the next run time only
                print(f"could not cache {name}: {err}", flush=True)
    return time.perf_counter() - t0, False


if __name__ == "__main__":
    import argparse
    import multiprocessing
    import time
    from concurrent.futures import ProcessPoolExecutor, as_completed

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="figures to make (default: all)")
    parser.add_argument(
        "--jobs", type=int, default=min(os.cpu_count() or 1, 4),
        help="figures made at once, each in its own process (default: cores, at most 4)",
    )  # fmt: skip
    parser.add_argument("--fresh", action="store_true",
                        help="recompute every figure (ignore the figure cache)")  # fmt: skip
    args = parser.parse_args()
    known = [f.__name__ for f in FIGURES]
    unknown = sorted(set(args.names) - set(known))
    if unknown:
        parser.error(f"unknown figure(s) {unknown}; choose from {known}")
    todo = [n for n in known if not args.names or n in args.names]
    start = time.perf_counter()
    key = _key()
    print(f"making {len(todo)} figures, {args.jobs} at a time (figure cache key {key})",
          flush=True)  # fmt: skip
    # Each figure in a fresh process (spawned: JAX does not survive a fork), longest first.
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=max(args.jobs, 1), mp_context=context) as pool:
        jobs = {pool.submit(_make, name, key, args.fresh): name for name in todo}
        for done, job in enumerate(as_completed(jobs), 1):
            wall, cached = job.result()
            how = "from the cache" if cached else "made"
            print(f"[{done}/{len(todo)}] {jobs[job]}: {how}, {wall:.1f} s", flush=True)
    print(f"wrote figures to {HERE} in {time.perf_counter() - start:.0f} s")
