"""Checks of the calibration's reduction and fits against closed-form data: the table rate a
window compares with, the standard errors under white and random-walk angle noise, and the
data the Fourier and virtual-precession fits refuse because they cannot determine them."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hrgjax as hg
from hrgjax import calibration as cal
from hrgjax.calibration.reduce import K_E_NOMINAL, window_slopes
from hrgjax.units import DEG

K = K_E_NOMINAL


def _moving_run(table_angle, rate, sf=1.002, drift_dph=1.5, duration=30.0, dt=0.1, columns=True):
    """A run whose wave angle is exactly θ = θ0 − k_e (SF·A(t) + D t) for a table angle A(t)
    [°] and rate Ω(t) [°/s] given as functions: the measured rate of any window is exactly
    SF × (the table angle's least-squares slope) + D."""
    t = np.arange(int(round(duration / dt)) + 1) * dt
    cols = {
        "time_s": t,
        "temperature_c": np.full(t.size, 20.0),
        "table_rate_dps": rate(t),
        "wave_angle_deg": 10.0 - K * (sf * table_angle(t) + drift_dph / 3600.0 * t),
    }
    if columns:
        cols["table_angle_deg"] = table_angle(t)
    return hg.MeasuredData(cols)


@pytest.mark.parametrize(
    "table",
    [
        # spin-up to 5 °/s in 2 s: A = 5 t²/4, then 5 (t − 1)
        (
            lambda t: np.where(t < 2, 1.25 * t**2, 5.0 * (t - 1.0)),
            lambda t: 5 * np.minimum(t / 2, 1),
        ),
        # an oscillating table, 20 sin(2πt/40) °/s
        (
            lambda t: 20 * 40 / (2 * np.pi) * (1 - np.cos(2 * np.pi * t / 40)),
            lambda t: 20 * np.sin(2 * np.pi * t / 40),
        ),
    ],
    ids=["spin-up", "oscillating"],
)
def test_window_table_rate_is_the_slope_of_the_table_angle(table):
    """(measured − drift) / table rate is the scale factor in every window, also where the
    table rate changes within it (the plain mean of the rate samples biased it: 1.0 % in the
    spin-up's first window, up to 0.2 % in the oscillation's)."""
    sf, drift = 1.002, 1.5
    w = cal.reduce(_moving_run(*table, sf=sf, drift_dph=drift))
    assert len(w) == 10 and not np.any(w.static)
    ratio = (w.rate_dps - drift / 3600.0) / w.table_rate_dps
    np.testing.assert_allclose(ratio, sf, rtol=1e-9)


def test_window_table_rate_without_a_table_angle_column_and_at_rest():
    """Without the column, the rate's integral: exact for a piecewise-linear rate; a window
    with the table at rest throughout keeps table rate 0 exactly (a static window)."""
    angle, rate = (lambda t: np.where(t < 2, 1.25 * t**2, 5.0 * (t - 1.0)),
                   lambda t: 5 * np.minimum(t / 2, 1))  # fmt: skip
    w = cal.reduce(_moving_run(angle, rate, columns=False))
    np.testing.assert_allclose((w.rate_dps - 1.5 / 3600.0) / w.table_rate_dps, 1.002, rtol=1e-9)
    stop = _moving_run(lambda t: 5 * np.maximum(t - 15, 0.0), lambda t: np.where(t >= 15, 5.0, 0.0))
    w = cal.reduce(stop)
    assert np.array_equal(w.static, np.arange(10) < 5)
    assert np.all(w.table_rate_dps[:5] == 0.0)
    np.testing.assert_allclose(w.drift_dph[:5], 1.5, rtol=1e-9)


@pytest.mark.parametrize(
    ("white", "walk"), [(1.0 / 3600, 0.0), (0.0, 1e-4 / np.sqrt(0.5))], ids=["white", "walk"]
)
def test_standard_errors_against_the_slopes_scatter(white, walk):
    """Monte Carlo on 300 windows of 241 samples (60 s at 0.5 s): the batch-means standard
    error is the scatter of the slopes within 15 % for an angle random walk, and never below
    it for white angle noise, which it counts ≈ batches times too large (reduce's docstring)."""
    rng = np.random.default_rng(0)
    n, dt, reps = 241, 0.5, 300
    t = np.tile(np.arange(n) * dt, reps)
    y = white * rng.standard_normal((reps, n))
    y = y + walk * np.sqrt(dt) * np.cumsum(rng.standard_normal((reps, n)), axis=1)
    slope, _, _, err = window_slopes(jnp.asarray(t), jnp.asarray(y.ravel()), reps, 5)
    scatter = np.std(np.asarray(slope))
    # the exact scatter of a least-squares slope under each (pattern_noise.slope_variance)
    exact = np.sqrt(hg.pattern_noise.slope_variance(white, walk, n, dt))
    np.testing.assert_allclose(scatter, exact, rtol=0.1)
    ratio = np.mean(np.asarray(err)) / scatter
    assert (0.85 < ratio < 1.15) if walk else (3.0 < ratio < 5.0), ratio


def _windows(static_angles, moving_angles, temps=(20.0,)):
    """Exact reduced windows: drift D = 0.3 + 1.2 cos 2θ − 0.5 sin 4θ [°/h] on static windows,
    a 5 °/s rotation with SF = 1 + 0.002 cos 2θ on moving ones."""

    def law(angles):
        tt, aa = np.meshgrid(np.asarray(temps), np.asarray(angles, float), indexing="ij")
        return tt.ravel(), aa.ravel()

    ts, as_ = law(static_angles)
    tm, am = law(moving_angles)
    drift = lambda a: (0.3 + 1.2 * np.cos(2 * a * DEG) - 0.5 * np.sin(4 * a * DEG)) / 3600.0  # noqa: E731
    sf = 1 + 0.002 * np.cos(2 * am * DEG)
    n = ts.size + tm.size
    return cal.RateWindows(
        run=np.arange(n), start=np.zeros(n, int), stop=np.full(n, 10),
        t_mid=np.full(n, 5.0), duration=np.zeros(n),  # point values: no arc to average over
        temperature_c=np.r_[ts, tm], table_rate_dps=np.r_[np.zeros(ts.size), np.full(tm.size, 5.0)],
        wave_angle_deg=np.r_[as_, am], rate_dps=np.r_[drift(as_), sf * 5.0 + drift(am)],
        stderr_dps=np.full(n, 1e-6), k_e=K,
    )  # fmt: skip


def test_fourier_fit_refuses_wave_angles_that_do_not_determine_the_harmonics():
    """Static runs at two wave angles (a hair apart, as measured angles are) cannot determine
    five coefficients: one line naming the angles and what to add, not a drift of 10⁹ °/h."""
    grid = np.arange(-90.0, 90.0, 20.0)
    good = cal.FourierCompensator().fit(_windows([-60.0, -20.0, 0.0, 30.0, 70.0], grid))
    th = np.array([-45.0, 10.0, 80.0])
    truth = 0.3 + 1.2 * np.cos(2 * th * DEG) - 0.5 * np.sin(4 * th * DEG)
    np.testing.assert_allclose(good.drift_dph(th, np.full(3, 20.0)), truth, rtol=1e-9)
    few = _windows([0.0, 0.0001, 0.0002, 45.0, 45.0001, 45.0002], grid)
    with pytest.raises(ValueError, match=r"^drift \(static runs\): .* at \+20\.0 °C 2 distinct "
                       r"wave angles \(0, 45°\).*needs ≥ 5 .*add runs at other wave angles"):  # fmt: skip
        cal.FourierCompensator().fit(few)
    with pytest.raises(ValueError, match=r"^scale factor \(rotation runs\): .* 1 distinct"):
        cal.FourierCompensator(harmonics=1).fit(_windows(grid, [30.0, 30.0001, 210.0]))
    with pytest.raises(ValueError, match=r"at -40\.0 °C 2 distinct .* at \+60\.0 °C 2 distinct"):
        cal.FourierCompensator(temperature_degree=1).fit(
            _windows([0.0, 1e-4, 2e-4, 3e-4, 45.0, 45.0001], grid, temps=(-40.0, 60.0))
        )


def _sweeps(arc_deg, drift_dph=2.0, rho_dps=1.0, dt=1.0):
    """Two sweeps ±ρ at rest over `arc_deg` (electrical), gain S = 1 and a constant drift:
    θ = θ0 ± ρt − k_e D t exactly."""
    t = np.arange(int(round(arc_deg / rho_dps / dt)) + 1) * dt
    pattern = -K * drift_dph / 3600.0
    up = -arc_deg / 2 + (rho_dps + pattern) * t
    down = arc_deg / 2 + (-rho_dps + pattern) * t
    n = t.size
    return hg.MeasuredData({
        "time_s": np.r_[t, t + t[-1] + 10.0], "run": np.repeat([0, 1], n),
        "temperature_c": np.full(2 * n, 20.0), "table_rate_dps": np.zeros(2 * n),
        "wave_angle_deg": np.r_[up, down], "precession_dps": np.repeat([rho_dps, -rho_dps], n),
    })  # fmt: skip


def test_precession_fit_refuses_sweeps_that_cover_too_little_angle():
    """Sweeps over 30° of the 180° period put the drift 100× off (auditor's case); they are
    refused in one line; sweeps over 180° give the drift exactly."""
    comp = cal.PrecessionCompensator(settle_s=0.0)
    good = comp.fit(_sweeps(180.0))
    np.testing.assert_allclose(good.drift_dph(np.array([-60.0, 0.0, 45.0]), 20.0), 2.0, rtol=1e-6)
    with pytest.raises(ValueError, match=r"^at 20 °C the sweeps turning \+ρ cover 30° of the 180° "
                       r"\(electrical\).*sweep over a half turn"):  # fmt: skip
        comp.fit(_sweeps(30.0))


def test_precession_sweeps_with_table_readback_jitter_are_at_rest():
    """A rate table's readback jitter (1e-5 °/s) on sweeps taken at rest was refused as "the
    table turns"; within `STILL_RATE_DPS` it is rest, as everywhere else in the package, and
    the fit is the jitter-free one. A table that turns is still refused, in one line."""
    comp = cal.PrecessionCompensator(settle_s=0.0)
    data = _sweeps(180.0)
    cols = dict(data.columns)
    cols["table_rate_dps"] = 1e-5 * np.random.default_rng(1).normal(size=len(data))
    still = comp.fit(data)
    jitter = comp.fit(hg.MeasuredData(cols))
    np.testing.assert_array_equal(np.asarray(jitter.drift_coef), np.asarray(still.drift_coef))
    cols["table_rate_dps"] = np.full(len(data), 0.01)
    with pytest.raises(ValueError, match=r"^run 0: the table turns \(\|table_rate_dps\| up to "
                       r"0\.01 °/s, varying by 0\); virtual-precession sweeps are taken with the "
                       r"case at rest \(\|table_rate_dps\| ≤ STILL_RATE_DPS = 0\.001 °/s, or "
                       r"constant and no larger than Earth's 0\.004178 °/s\)$"):  # fmt: skip
        comp.fit(hg.MeasuredData(cols))


@pytest.mark.parametrize(
    ("cls", "settings", "match"),
    [
        ("MLPCompensator", {"learning_rate": -1.0}, "learning_rate must be a finite number > 0"),
        ("MLPCompensator", {"learning_rate": float("nan")}, "learning_rate must be a finite"),
        ("MLPCompensator", {"bin_deg": 0.0}, r"bin_deg must be a finite number > 0 \[°"),
        ("MLPCompensator", {"bin_deg": -5.0}, "bin_deg must be a finite number > 0"),
        ("MLPCompensator", {"e2e_steps": 0, "mode": "end_to_end"},
         "e2e_steps must be a whole number ≥ 1 with mode='end_to_end'; got 0"),
        ("MLPCompensator", {"e2e_steps": -1}, "e2e_steps must be a whole number ≥ 0"),
        ("MLPCompensator", {"steps": 0}, "steps must be a whole number ≥ 1"),
        ("MLPCompensator", {"steps": 2.5}, "steps must be a whole number ≥ 1"),
        ("MLPCompensator", {"sf_width": 0}, "sf_width must be a whole number ≥ 1"),
        ("MLPCompensator", {"st_width": -1}, "st_width must be a whole number ≥ 0"),
        ("MLPCompensator", {"window_s": float("inf")}, "window_s must be None or a finite"),
        ("FourierCompensator", {"window_s": float("inf")}, "window_s must be None or a finite"),
        ("FourierCompensator", {"window_s": 0.0}, "window_s must be None or a finite"),
        ("FourierCompensator", {"tolerance_c": -1.0}, r"tolerance_c must be a finite number ≥ 0"),
        ("FourierCompensator", {"tolerance_c": float("nan")}, "tolerance_c must be a finite"),
        ("FourierCompensator", {"fit_temperature_c": float("nan")},
         r"fit_temperature_c must be a finite number \[°C\]"),
        ("FourierCompensator", {"harmonics": 1.5}, "harmonics must be a whole number ≥ 1"),
        ("FourierCompensator", {"harmonics": True}, "harmonics must be a whole number ≥ 1"),
        ("FourierCompensator", {"temperature_degree": 1.5},
         "temperature_degree must be a whole number ≥ 0 or None"),
        ("FourierCompensator", {"temperature_degree": -1}, "temperature_degree must be a whole"),
    ],
)  # fmt: skip
def test_compensator_settings_are_refused_at_construction(cls, settings, match):
    """Audit: learning_rate=-1 trained to a wrong fit, bin_deg=0 failed after training
    (ZeroDivisionError), e2e_steps=0 end to end with 'need at least one array', window_s=inf
    with an OverflowError. Each is now one line naming the class and the field, before any fit."""
    with pytest.raises(ValueError, match=f"^{cls}: {match}") as err:
        getattr(cal, cls)(**settings)
    assert "\n" not in str(err.value)


def test_good_settings_and_old_files_pass_the_checks(tmp_path):
    """The checks take every documented value (None windows, e2e_steps=0 when not end to end,
    tolerance 0), and a compensator file written before `window_s` and `mode` were saved loads
    with the class defaults."""
    import json

    from hrgjax.calibration.export import checksum

    cal.MLPCompensator(e2e_steps=0, window_s=None, learning_rate=1, bin_deg=180.0)
    cal.FourierCompensator(tolerance_c=0.0, window_s=None, temperature_degree=0)
    comps = (
        cal.FourierCompensator(window_s=5.0, drift_coef=jnp.zeros((1, 5)), sf_coef=jnp.ones((1, 5))),
        cal.MLPCompensator(drift_width=2, sf_width=2, window_s=5.0, mode="end_to_end",
                           e2e_steps=3).init(jax.random.key(0)),
    )  # fmt: skip
    for comp in comps:
        path = cal.save_compensator(comp, tmp_path / "model.eqx")
        with open(path, "rb") as fh:
            header, payload = json.loads(fh.readline()), fh.read()
        for old in ("window_s", "mode"):
            header["hyper"].pop(old, None)
        header["sha256"] = checksum(header, payload)
        with open(path, "wb") as fh:
            fh.write((json.dumps(header) + "\n").encode() + payload)
        loaded = cal.load_compensator(path)
        assert loaded.window_s == type(comp)().window_s
        assert getattr(loaded, "mode", "reduced") == "reduced"


def test_known_plant_keeps_the_forcers_and_refuses_force_to_rebalance(tmp_path):
    """Audit: `known_plant` rebuilt the loops without `forcer_gain` and `forcer_angle` (which
    whole-angle mode reads: the grey box then modelled other loops than the plant's) and took a
    force-to-rebalance plant, or one with a loop open. Both forcer errors are now kept (and
    saved); FTR and open loops are refused."""
    import dataclasses

    import equinox as eqx

    from hrgjax.calibration.physical import known_plant, plant_from_json, plant_to_json

    gyro = hg.presets.tvg3_like()
    law = hg.TemperatureLaw(0.01, 1e-4)
    control = dataclasses.replace(gyro.control, forcer_gain=law, forcer_angle=0.002)
    plant = known_plant(eqx.tree_at(lambda g: g.control, gyro, control))
    assert float(plant.control.forcer_gain.p0) == 0.01
    assert float(plant.control.forcer_gain.p1) == 1e-4
    assert float(plant.control.forcer_angle) == 0.002
    d = plant_to_json(plant)
    assert d["control"]["forcer_gain"][:2] == [0.01, 1e-4]
    assert d["control"]["forcer_angle"] == 0.002
    back = plant_from_json(d)
    assert float(back.control.forcer_gain(40.0)) == pytest.approx(0.01 + 20 * 1e-4)
    assert float(back.control.forcer_angle) == 0.002
    old = {"resonator": d["resonator"], "control": {
        k: v for k, v in d["control"].items() if k not in ("forcer_gain", "forcer_angle")}}  # fmt: skip
    assert float(plant_from_json(old).control.forcer_gain) == 0.0  # files from before load
    with pytest.raises(ValueError, match=r"^plant.control.mode must be 'wa' .*got 'ftr'"):
        cal.PhysicalCompensator(plant=gyro.in_mode("ftr"))
    # audit: a plant with a loop open (bandwidth 0) passed and reached `reduced_rate`: NaN
    open_q = dataclasses.replace(gyro.control, quadrature_bandwidth=0.0)
    with pytest.raises(ValueError, match=r"^plant.control.quadrature_bandwidth = 0 rad/s opens"):
        known_plant(eqx.tree_at(lambda g: g.control, gyro, open_q))


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"window_s": float("inf")}, r"window_s must be a finite number > 0 of seconds"),
        ({"window_s": -1.0}, r"window_s must be a finite number > 0"),
        ({"window_s": None}, r"window_s must be a finite number > 0"),
        ({"max_steps": 0}, r"max_steps must be a whole number ≥ 1"),
        ({"max_steps": 2.5}, r"max_steps must be a whole number ≥ 1"),
        ({"sf_rate": float("nan")}, r"sf_rate must be a finite number \[rad/s\]"),
    ],
)
def test_physical_compensator_settings_are_refused_at_construction(kw, match):
    from hrgjax.calibration import PhysicalCompensator

    with pytest.raises(ValueError, match=match):
        PhysicalCompensator(**kw)
    PhysicalCompensator(window_s=10.0, max_steps=8, sf_rate=0.1)  # good ones pass


def test_a_rate_tables_readback_jitter_and_a_thermometers_noise_leave_a_static_run_static():
    """A static run whose table-rate column carries 1e-5 °/s of readback jitter and whose
    temperature 5 mK of noise is the same static run: one window, static, the same drift
    (the jitter split it into 3-s "moving" windows, and with `ramp_window_s` the noise made
    it a ramp), in the reduction, the run stack and the accuracy table alike."""
    rng = np.random.default_rng(5)
    t = np.arange(601) * 0.1
    clean = {
        "time_s": t,
        "temperature_c": np.full(t.size, 20.0),
        "table_rate_dps": np.zeros(t.size),
        "table_angle_deg": np.zeros(t.size),
        "wave_angle_deg": 10.0 - K * 1.5 / 3600.0 * t,
    }
    noisy = dict(clean, table_rate_dps=1e-5 * rng.standard_normal(t.size),
                 temperature_c=20.0 + 5e-3 * rng.standard_normal(t.size))  # fmt: skip
    for kw in ({}, {"ramp_window_s": 10.0}):
        a, b = (cal.reduce(hg.MeasuredData(c), **kw) for c in (clean, noisy))
        assert len(b) == len(a) == 1 and bool(b.static[0])
        np.testing.assert_allclose(b.drift_dph, a.drift_dph, rtol=1e-12)
    assert bool(hg.MeasuredData(noisy).stacked()[0].static[0])
    for cols in (clean, noisy):  # the accuracy table: a static run, its drift error
        done = hg.MeasuredData(dict(cols, angle_corrected_deg=1.5 / 3600.0 * t))
        table = cal.corrected_run_errors(done)
        assert list(table["static"]) == [True]
        np.testing.assert_allclose(table["drift_error_dph"], 1.5, rtol=1e-9)
    # the physical fit's grouping: the noisy static run is static, not a ramp
    from hrgjax.calibration._physical_groups import fit_groups

    (group,) = fit_groups(hg.MeasuredData(noisy), 10.0, K)
    assert group.static_idx == (0,) and group.ramp_idx == ()
    # an FTR gyro's record with its loop off throughout (rebalance_on 0) is whole-angle
    # data: correct and reduce read it; with the loop on somewhere they refuse it
    free = dict(clean, rebalance_rate_dps=np.zeros(t.size), rebalance_on=np.zeros(t.size))
    cal.reduce(hg.MeasuredData(free))
    with pytest.raises(ValueError, match="force-to-rebalance output"):
        cal.reduce(hg.MeasuredData(dict(free, rebalance_on=np.r_[np.zeros(300), np.ones(301)])))
    # the turned table (0.3° over the minute: 5e-3 °/s) is a moving run
    turning = dict(clean, table_rate_dps=np.full(t.size, 5e-3), table_angle_deg=5e-3 * t)
    assert not bool(hg.MeasuredData(turning).stacked()[0].static[0])


def test_a_numpy_table_rate_is_stored_as_a_plain_number():
    """`sf_rate` is a static field: a NumPy scalar there warned "A JAX array is being set as
    static!" (the suite's warnings are errors) and made `sf_rate != 0` a NumPy bool."""
    comp = cal.PhysicalCompensator(sf_rate=np.float64(np.deg2rad(10.0)))
    assert type(comp.sf_rate) is float and comp.sf_rate == pytest.approx(np.deg2rad(10.0))


def _bad(call, match, exc=(ValueError, TypeError)):
    with pytest.raises(exc, match=match) as err:
        call()
    assert "\n" not in str(err.value)


def test_reduction_and_evaluation_refuse_what_makes_no_sense_in_one_line():
    """Audit (calib): a dict for the data, batches=3.5, window_s=inf, bin_deg=0, a 2-D
    residual table, offset_dph="1", a list of compensators… reached NumPy, Python or JAX
    (AttributeError, slice indices, OverflowError, ZeroDivisionError) or passed silently
    (window_s ≤ 0 read as one sample, a 2-D table flattened, None read as no runs, inf
    residuals dropped, "1" taken as 1 °/h). Each is now one line naming the argument."""
    d = _moving_run(lambda t: 5 * t, lambda t: 5 + 0 * t)
    w = _windows([-60.0, -20.0, 0.0, 30.0, 70.0], np.arange(-90.0, 90.0, 20.0))
    nc = cal.NoCompensation()
    for call, match in (
        (lambda: cal.reduce(d.columns), r"^reduce: data must be hrgjax.MeasuredData"),
        (lambda: cal.reduce(d, batches=3.5), r"^batches must be a whole number ≥ 3"),
        (lambda: cal.reduce(d, window_s=float("inf")), r"^reduce: window_s must be None or a"),
        (lambda: cal.reduce(d, window_s="10"), r"^reduce: window_s must be None or a finite"),
        (lambda: cal.static_drift(d, batches=4.5), r"^batches must be a whole number ≥ 3"),
        (lambda: cal.scale_factor_vs_angle(d, window_s=-2.0),
         r"^scale_factor_vs_angle: window_s must be a finite number > 0 \[s\]"),
        (lambda: cal.scale_factor_vs_angle(d, bin_deg=0.0),
         r"^scale_factor_vs_angle: bin_deg must be a number in \(0, 180\]"),
        (lambda: w.select([True]), r"^RateWindows.select: mask must be \d+ bools"),
        (lambda: cal.RateWindows(**{k: np.zeros(3) for k in ("run", "stop", "t_mid", "duration",
         "temperature_c", "table_rate_dps", "wave_angle_deg", "rate_dps", "stderr_dps")},
         start=np.zeros(2), k_e=K), r"^RateWindows.start must have one value per window"),
        (lambda: window_slopes(jnp.arange(10.0), jnp.arange(12.0), 2),
         r"^window_slopes: theta must have the shape of t"),
        (lambda: nc.correct(d.columns), r"^NoCompensation.correct: data must be hrgjax.Measured"),
        (lambda: cal.run_errors(nc, d, offset_dph="1"), r"^run_errors: offset_dph must be a num"),
        (lambda: cal.run_errors("fourier", d), r"^run_errors: comp must be a fitted compensator"),
        (lambda: cal.corrected_run_errors(d.columns), r"^corrected_run_errors: corrected must"),
        (lambda: cal.accuracy_table([nc], d), r"^accuracy_table: compensators must be a dict"),
        (lambda: cal.accuracy_table({}, d), r"^accuracy_table: give at least one compensator"),
        (lambda: cal.accuracy_table({"r": nc}, d, temperatures_c=[[20.0]]),
         r"^accuracy_table: temperatures_c must be 1-D"),
        (lambda: cal.compare([nc], d), r"^compare: compensators must be a dict"),
        (lambda: cal.compare({"a": 3}, d), r"^compare: compensators\['a'\] must be a fitted"),
        (lambda: cal.compare_corrected([d]), r"^compare_corrected: corrected must be a dict"),
        (lambda: cal.compare({"a": nc}, d, temperature_bin_c="1"),
         r"^temperature_bin_c must be a number > 0; got '1'"),
        (lambda: cal.paired_difference(np.ones((2, 3)), np.zeros((2, 3))),
         r"^residual_a must be 1-D, one value per run"),
        (lambda: cal.paired_difference([1.0, np.inf], [0.0, 0.0]), r"^residual_a must be finite"),
        (lambda: cal.paired_difference(None, None), r"^residual_a must be one value per run"),
        (lambda: cal.paired_difference([1.0, 2.0], [0.0, 1.0], level="0.9"),
         r"^level must be in \(0, 1\); got '0.9'"),
        (lambda: cal.session_offset({"static": [True, True], "drift_error_dph": [np.inf, 1.0],
                                     "duration_s": [60.0, 60.0]}),
         r"^session_offset: every static run needs a drift_error_dph that is not infinite"),
    ):  # fmt: skip
        _bad(call, match)
    fitted = cal.FourierCompensator(drift_coef=jnp.zeros((1, 5)), sf_coef=jnp.ones((1, 5)))
    assert fitted.drift_dph([], 20.0).shape == (0,)  # was NumPy's "can't extend empty axis"
    _bad(lambda: cal.FourierCompensator(drift_coef=jnp.zeros((1, 3)), sf_coef=jnp.ones((1, 5))),
         r"^FourierCompensator: drift_coef must have shape .* = \(1, 5\)")  # fmt: skip


def test_plans_and_self_calibration_refuse_bad_arguments_before_simulating():
    """Audit (calib): a 2-D grid of temperatures was flattened, rate_dps="5" or NaN built a
    plan, dt_out > duration_s made runs of one sample, lists in `Plan` failed with
    AttributeError, first_run=1.5 was truncated, key=0 reached JAX (run_plan, MLPCompensator), quick="no" was read as
    True, a string of methods was split into letters, and mode reversal took a negative
    settling time (holds starting inside the slew) or mismatched arrays (JAX's broadcast
    error). Each is now one line before anything runs."""
    gyro = hg.presets.tvg3_like()
    sp = cal.static_plan([20.0], [0.0], duration_s=2.0, dt_out=1.0)
    prof = hg.Profile.held_angles((0.0, 90.0), 30.0)
    for call, match in (
        (lambda: cal.static_plan([[20.0, 30.0]], [0.0]), r"^plan temperatures_c must be 1-D"),
        (lambda: cal.rotation_plan([20.0], [0.0], rate_dps="5"), r"^plan rate_dps must be a"),
        (lambda: cal.rotation_plan([20.0], [0.0], rate_dps=np.nan), r"^plan rate_dps must be fin"),
        (lambda: cal.static_plan([20.0], [0.0], duration_s=10, dt_out=20),
         r"^Plan.dt_out must be ≤ Plan.duration_s"),
        (lambda: cal.Plan(temperature_c=[20.0], wave_angle0_deg=[0.0], rate_dps=[0.0],
                          duration_s=10.0), r"^Plan.temperature_c must be an array"),
        (lambda: cal.seed_plan(quick="no"), r"^seed_plan: quick must be True or False"),
        (lambda: cal.run_plan(gyro, sp, first_run=1.5), r"^run_plan: first_run must be a whole"),
        (lambda: cal.run_plan(gyro, sp, key=0), r"^run_plan: key \(or None\) must be one JAX PRNG key"),
        (lambda: cal.run_plan(None, sp), r"^run_plan: gyro must be an hrgjax.Gyro"),
        (lambda: cal.precession_plan([[20.0, 30.0]]), r"^precession_plan: temperatures_c must"),
        (lambda: cal.precession_plan(precession_dps="0.5"), r"^precession_plan: precession_dps"),
        (lambda: cal.mode_reversal(np.arange(10.0), np.zeros(7), prof),
         r"^mode_reversal: rebalance_rate must have one value per sample of t"),
        (lambda: cal.mode_reversal(np.arange(80.0), np.zeros(80), prof, settle_s=-5.0),
         r"^Profile.hold_windows: settle_s must be >= 0"),
        (lambda: cal.mode_reversal_data(_moving_run(lambda t: 0 * t, lambda t: 0 * t),
                                        settle_s=-5), r"^mode_reversal_data: settle_s must be >="),
        (lambda: cal.run_study(key=jax.random.key(0), methods="fourier"),
         r"^run_study: methods must be a list"),
        (lambda: cal.run_study(key=jax.random.key(0), quick="no"), r"^run_study: quick must be"),
        (lambda: cal.MLPCompensator().init(0), r"^MLPCompensator.init: key must be one JAX PRNG"),
        (lambda: cal.MLPCompensator().fit(None, key=jax.random.split(jax.random.key(0))),
         r"^MLPCompensator.fit: key= .* got a key array of shape \(2,\)"),
    ):  # fmt: skip
        _bad(call, match)


def test_raw_must_be_the_windows_session_and_is_given_once():
    """Audit: `PhysicalCompensator().fit(A, raw=B)` fitted B and dropped A; the end-to-end MLP
    given windows of A and `raw=B` trained stage one on A and end to end on B. `raw` beside
    samples is refused (pass them once), and beside windows unless it is their session —
    by every compensator, before any fit."""
    data = _moving_run(lambda t: 5 * t, lambda t: 5 + 0 * t)
    other = _moving_run(lambda t: 5 * t, lambda t: 5 + 0 * t, drift_dph=2.5)  # same times
    w, key = cal.reduce(data), jax.random.key(0)
    e2e = cal.MLPCompensator(steps=1, e2e_steps=1, mode="end_to_end")
    once = r": data are the samples \(MeasuredData\) and raw= gives samples too; pass "
    for comp in (cal.PhysicalCompensator(), e2e, cal.FourierCompensator(), cal.NoCompensation()):
        who = f"^{type(comp).__name__}.fit"
        _bad(lambda c=comp: c.fit(data, key=key, raw=data), who + once + r"the samples once")
        _bad(lambda c=comp: c.fit(w, key=key, raw=other), who + r": raw is not the session the "
             r"windows were reduced from \(run 0's window over samples \[0, 30\) has mean wave "
             r"angle .*, raw's samples there .*\); pass the samples behind them")  # fmt: skip
        _bad(lambda c=comp: c.fit(w, key=key, raw=data.columns), who + r": raw must be hrgjax")
    _bad(
        lambda: cal.PrecessionCompensator().fit(data, raw=data),
        "^PrecessionCompensator.fit" + once + r"the samples once: fit\(data\)$",
    )
    nc = cal.NoCompensation()  # the windows' own session passes, any window length or subset
    for windows in (w, cal.reduce(data, window_s=None), w.select(np.arange(len(w)) % 2 == 0)):
        assert nc.fit(windows, raw=data) is nc
    two = hg.MeasuredData({k: np.r_[v, v] for k, v in data.columns.items()}
                          | {"run": np.repeat([0, 1], len(data))})  # fmt: skip
    _bad(lambda: nc.fit(w, raw=two), r"\(raw has run 1, which has no window\)")
    _bad(lambda: nc.fit(cal.reduce(two), raw=data), r"\(the windows have run 1, which raw has")


def test_physical_starting_values_are_checked_when_built():
    """Audit: `PhysicalCompensator(initial=…)` took 5 values, NaN or a 2-D array, refused (or
    fitted from NaN) only inside `fit`. One line naming `initial`, the count and the order."""
    from hrgjax.calibration import design

    x0 = np.asarray(design.nominal_values())
    form = (r"^PhysicalCompensator: initial must be None or 12 finite real numbers, 1-D, in the "
            r"order of PARAMETERS \(k_e0, k_e_tc, .*, cross_talk\) \[SI\]; got ")  # fmt: skip
    for bad, got in ((x0[:5], r"ndarray of shape \(5,\)"), (x0[None], r"ndarray of shape \(1, "),
                     (np.r_[x0[:3], np.nan, x0[4:]], r"nan at index 3 \(bias1\)"),
                     ("x0", "str")):  # fmt: skip
        _bad(lambda b=bad: cal.PhysicalCompensator(initial=b), form + got)
    _bad(lambda: cal.PhysicalCompensator().fit(_moving_run(np.sin, np.cos), initial=x0[:5]),
         r"^PhysicalCompensator.fit: initial must be None or 12")  # fmt: skip
    assert cal.PhysicalCompensator(initial=list(x0)).initial == list(x0)


def test_numpy_and_jax_scalars_are_settings_as_the_numbers_they_hold():
    """Audit: `MLPCompensator(learning_rate=jnp.float64(0.01))` and `FourierCompensator(
    window_s=jnp.array(10.0))` were refused ("must be a finite number > 0; got Array(0.01)")
    after equinox's "JAX array is being set as static" warning (an error here), and NumPy
    scalars were kept as arrays in static fields. They are stored as Python numbers; a
    traced setting is refused in one line."""
    cases = (
        (cal.MLPCompensator, "learning_rate", jnp.float64(0.01), 0.01),
        (cal.MLPCompensator, "steps", np.int64(7), 7),
        (cal.FourierCompensator, "window_s", jnp.array(10.0), 10.0),
        (cal.FourierCompensator, "harmonics", np.array(3), 3),
        (cal.PhysicalCompensator, "max_steps", jnp.array(8), 8),
        (cal.PhysicalCompensator, "window_s", np.float32(5.0), 5.0),
        (cal.PrecessionCompensator, "settle_s", np.float32(12.5), 12.5),
        (cal.NoCompensation, "k_e", jnp.array(0.5), 0.5),
    )
    for cls, name, value, number in cases:
        got = getattr(cls(**{name: value}), name)
        assert got == number and type(got) is type(number), (cls, name, got)
    for cls, name, value, _ in cases:
        traced = rf"^{cls.__name__}: {name} must be a number fixed when the compensator is built"
        with pytest.raises(ValueError, match=traced + "; got a traced value") as err:
            jax.jit(lambda v, c=cls, n=name: getattr(c(**{n: v}), n))(value)
        assert "\n" not in str(err.value)


def test_a_settling_longer_than_the_sweeps_is_named_as_such():
    """Audit: `self-calibrate --settle` longer than the sweeps said they "turn one way only"
    (no sample left in either direction); now the samples left after settle_s are named."""
    with pytest.raises(ValueError, match=r"^at 20 °C a sweep of 180 s keeps 0 samples after "
                       r"settle_s = 1000 s, fewer than 20: give a settle_s shorter"):  # fmt: skip
        cal.PrecessionCompensator(settle_s=1000.0).fit(_sweeps(180.0))
    with pytest.raises(ValueError, match=r"^at 20 °C a sweep of 180 s keeps 11 samples after "):
        cal.PrecessionCompensator(settle_s=170.0).fit(_sweeps(180.0))


def test_evaluation_refuses_a_temperature_in_kelvin():
    """Audit: `FourierCompensator.drift_dph([0.], 293.15)` extrapolated to 293 °C without a
    word. `drift_dph` and `scale_factor_at` refuse temperatures beyond the plausible range,
    kelvin named."""
    comp = cal.FourierCompensator(drift_coef=jnp.zeros((1, 5)), sf_coef=jnp.ones((1, 5)))
    for method in ("drift_dph", "scale_factor_at"):
        _bad(lambda m=method: getattr(comp, m)([0.0, 10.0], [293.15, 300.0]),
             rf"^FourierCompensator.{method}: temperature_c = 293.15 at index 0 is outside "
             r"the plausible range -100 … 150 °C — these look like kelvin .*subtract")  # fmt: skip
