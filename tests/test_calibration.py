"""Calibration study (issue 3): reduction, compensators, correction, export, bad input.

Oracles: exact harmonic laws on synthetic windows, analytic LSQ-slope variance of a random
walk, exact integration of a known drift, finite differences, Monte-Carlo coverage of the
physical fit's covariance.
"""

import dataclasses
import json
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter, closed_form_session, noisy_model_gyro

import hrgjax as hg
from hrgjax.calibration import (
    FourierCompensator,
    MLPCompensator,
    NoCompensation,
    PhysicalCompensator,
    RateWindows,
    export_json,
    load_compensator,
    load_json,
    physical,
    reduce,
    run_plan,
    save_compensator,
    static_plan,
)
from hrgjax.calibration import mlp as mlp_module
from hrgjax.calibration.reduce import K_E_NOMINAL, window_slopes
from hrgjax.units import DEG, DEG_PER_H

K = K_E_NOMINAL
TEMPS = np.array([-40.0, -10.0, 20.0, 40.0, 60.0])
ANGLES = np.arange(-90.0, 90.0, 10.0)


def true_drift(theta, temp):
    """A smooth 180°-periodic drift law [rad/s]: amplitude, phase and offset vary with T."""
    amp = 1.5 * DEG_PER_H * np.exp(-0.016 * (temp - 20.0))
    phase = (25.0 + 0.16 * (temp - 20.0)) * DEG
    return 0.3 * DEG_PER_H + 0.005 * DEG_PER_H * (temp - 20) - amp * np.sin(2 * (theta - phase))


def true_sf(theta, temp):
    g = 0.0046 - 9.6e-5 * (temp - 20.0)
    return 1.0 - 2 * g * np.cos(2 * theta)


def synthetic_windows(noise_dph=0.0, seed=0):
    """Exact reduced targets on a (T, θ) grid: static drift and 5 °/s rotation windows, point
    values (windows of no duration: no arc for the fits to average over)."""
    rng = np.random.default_rng(seed)
    tt, aa = np.meshgrid(TEMPS, ANGLES, indexing="ij")
    tt, aa = tt.ravel(), aa.ravel()
    n = tt.size
    th = aa * DEG
    drift = true_drift(th, tt) + noise_dph * DEG_PER_H * rng.standard_normal(n)
    rot = 5.0 * DEG
    moving = true_sf(th, tt) * rot + true_drift(th, tt)

    def windows(rate, table):
        return dict(
            temperature_c=tt,
            table_rate_dps=np.full(n, table),
            wave_angle_deg=aa,
            rate_dps=rate / DEG,
            stderr_dps=np.full(n, 1e-6),
        )

    s, m = windows(drift, 0.0), windows(moving, 5.0)
    cols = {k: np.concatenate([s[k], m[k]]) for k in s}
    idx = np.arange(2 * n)
    return RateWindows(
        run=idx,
        start=np.zeros(2 * n, int),
        stop=np.full(2 * n, 10),
        t_mid=np.full(2 * n, 5.0),
        duration=np.zeros(2 * n),
        **cols,
        k_e=K,
    )


@pytest.fixture(scope="module")
def exact_windows():
    return synthetic_windows()


# --- reduction -------------------------------------------------------------------------


def test_window_slopes_exact_on_lines():
    t = jnp.linspace(0.0, 9.9, 100)
    y = jnp.concatenate([2.0 * t[:50] + 1.0, -3.0 * t[50:]])
    slope, tm, ym = window_slopes(t, y, 2)
    np.testing.assert_allclose(slope, [2.0, -3.0], rtol=1e-12)
    np.testing.assert_allclose(tm, [np.mean(t[:50]), np.mean(t[50:])])


def test_batch_means_error_matches_random_walk_scatter():
    """Angle random walk: the reported error must match the real scatter of the slope, which
    the white-noise LSQ formula underestimates several times."""
    rng = np.random.default_rng(1)
    n, dt, reps = 600, 0.5, 400
    t = np.arange(n) * dt
    walk = np.cumsum(rng.standard_normal((reps, n)), axis=1) * np.sqrt(dt)
    slopes, errs, naive = [], [], []
    for y in walk:
        s, _, _, e = window_slopes(jnp.asarray(t), jnp.asarray(y), 1, 6)
        slopes.append(float(s[0]))
        errs.append(float(e[0]))
        resid = y - np.polyval(np.polyfit(t, y, 1), t)
        naive.append(np.sqrt(np.sum(resid**2) / (n - 2) / np.sum((t - t.mean()) ** 2)))
    scatter = np.std(slopes)
    # LSQ slope of a unit random walk over T: variance 6/(5T) (continuous limit).
    np.testing.assert_allclose(scatter, np.sqrt(6 / (5 * n * dt)), rtol=0.1)
    assert 0.75 < np.sqrt(np.mean(np.square(errs))) / scatter < 1.35
    assert np.mean(naive) < scatter / 3


def test_reduce_static_run_slope_and_units():
    t = np.arange(0.0, 60.0, 1.0)
    drift_dph = 2.0
    theta = 10.0 - K * drift_dph / 3600.0 * t
    data = hg.MeasuredData(
        dict(
            time_s=t,
            temperature_c=np.full(t.size, 20.0),
            table_rate_dps=np.zeros(t.size),
            wave_angle_deg=theta,
        )
    )
    w = reduce(data)
    assert len(w) == 1 and w.static[0]
    np.testing.assert_allclose(w.drift_dph, [drift_dph], rtol=1e-9)
    np.testing.assert_allclose(w.wave_angle_deg, [np.mean(theta)])


def test_static_drift_reports_the_student_t_degrees_of_freedom_of_its_error():
    """Seeded Monte Carlo, 400 static runs of a pure angle random walk (truth: drift 0): the
    batch-means error read as a normal 1σ under-covers (t₃: 61 %, z-RMS √3), so its degrees
    of freedom are reported and the t interval they give covers at its nominal rate."""
    from scipy import stats

    rng = np.random.default_rng(7)
    runs, n = 400, 100
    walk = np.cumsum(rng.standard_normal((runs, n)), axis=1) * 1e-3
    data = hg.MeasuredData(dict(
        time_s=np.tile(np.arange(n) * 0.1, runs), temperature_c=np.full(runs * n, 20.0),
        table_rate_dps=np.zeros(runs * n), wave_angle_deg=walk.ravel(),
        run=np.repeat(np.arange(runs), n)))  # fmt: skip
    for batches, normal_1s in ((5, (0.55, 0.66)), (10, (0.59, 0.71))):
        d = hg.calibration.static_drift(data, batches=batches)
        np.testing.assert_array_equal(d["dof"], batches - 2)
        z = np.abs(d["drift_dph"] / d["stderr_dph"])
        assert normal_1s[0] < np.mean(z < 1) < normal_1s[1], np.mean(z < 1)  # t's, not 68 %
        for p, lo, hi in ((0.6827, 0.63, 0.74), (0.9545, 0.93, 0.98)):
            q = stats.t.ppf(0.5 + p / 2, batches - 2)
            assert lo < np.mean(z < q) < hi, (batches, p, np.mean(z < q))
    short = reduce(hg.MeasuredData({k: v[:8] for k, v in data.columns.items()}))
    np.testing.assert_array_equal(short.dof, [2])  # 8 samples: 4 batches, 2 dof


def test_reduce_rejects_bad_arguments():
    data = hg.MeasuredData(
        dict(
            time_s=np.arange(3.0),
            temperature_c=np.zeros(3),
            table_rate_dps=np.zeros(3),
            wave_angle_deg=np.zeros(3),
        )
    )
    with pytest.raises(ValueError, match="at least 4"):
        reduce(data)
    with pytest.raises(ValueError, match="k_e"):
        reduce(data, k_e=-1.0)
    with pytest.raises(ValueError, match=r"^k_e must be .* in \(0, 1\].*got 55\.4 \(a gain in "):
        reduce(data, k_e=55.4)


def _bench_run(run, temp, sf, rate, n=6000, dt=0.01, jitter=0.0, drift_dps=1e-3):
    """Columns of one run: the table at `rate` [°/s] (an array, or a number), the wave angle
    −k_e·(sf·(table angle) + drift·t); readback `jitter` [°/s] on the rate."""
    t = np.arange(n) * dt
    w = np.broadcast_to(np.asarray(rate, float), (n,))
    table = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t))])
    w = w + jitter * np.random.default_rng(run).standard_normal(n)
    theta = 10.0 - K * (sf * table + drift_dps * t)
    return dict(time_s=t, wave_angle_deg=theta, temperature_c=np.full(n, temp),
                table_rate_dps=w, table_angle_deg=table, run=np.full(n, run))  # fmt: skip


def _bench(*runs):
    return hg.MeasuredData({k: np.concatenate([r[k] for r in runs]) for k in runs[0]})


def test_scale_factor_vs_angle_is_relative_to_the_nominal_gain():
    """Two rotation runs with scale factors 1.002 (−40 °C) and 0.998 (+60 °C) keep their
    levels (the figure's "scale factor − 1"), not each ≈ 1 relative to its own mean."""
    from hrgjax.calibration import scale_factor_vs_angle

    data = _bench(_bench_run(0, -40.0, 1.002, 5.0), _bench_run(1, 60.0, 0.998, 5.0),
                  _bench_run(2, 20.0, 1.0, 0.0))  # fmt: skip
    out = scale_factor_vs_angle(data)
    np.testing.assert_array_equal(out["temperature_c"], [-40.0, 60.0])
    assert out["scale_factor"].shape == (2, 18)
    for row, truth in zip(out["scale_factor"], [1.002, 0.998], strict=True):
        assert np.sum(np.isfinite(row)) >= 10
        # the drift, 10⁻³ °/s, is not removed: 2·10⁻⁴ of the 5 °/s table rate
        np.testing.assert_allclose(row[np.isfinite(row)], truth + 1e-3 / 5.0, rtol=1e-9)


def test_scale_factor_vs_angle_uses_only_where_the_table_turns():
    """A spin-up after 1 s at rest, a stop 1 s before the end, a sign change and a static run
    with readback jitter: only intervals where the table turns throughout count (no
    division by a zero rate, no row for the static run), from increments, not instantaneous
    rates."""
    from hrgjax.calibration import scale_factor_vs_angle

    t = np.arange(6000) * 0.01
    rates = [np.where(t < 1.0, 0.0, 5.0), np.where(t > 59.0, 0.0, 5.0),
             np.where(t < 30.0, 5.0, -5.0), np.clip(t, 0.0, 5.0)]  # fmt: skip
    runs = [_bench_run(i, 20.0, 1.001, w, drift_dps=0.0) for i, w in enumerate(rates)]
    runs.append(_bench_run(4, 30.0, 1.0, 0.0, jitter=1e-5))
    out = scale_factor_vs_angle(_bench(*runs))
    np.testing.assert_array_equal(out["temperature_c"], [20.0])
    row = out["scale_factor"][0]
    assert np.sum(np.isfinite(row)) >= 10
    np.testing.assert_allclose(row[np.isfinite(row)], 1.001, rtol=1e-9)
    static = scale_factor_vs_angle(_bench(runs[-1]))
    assert static["scale_factor"].shape == (0, 18) and static["temperature_c"].size == 0


# --- compensators on exact targets -------------------------------------------------------


def test_fourier_base_recovers_pure_harmonic_at_fit_temperature(exact_windows):
    comp = FourierCompensator().fit(exact_windows)
    th = np.linspace(-90, 90, 37)
    np.testing.assert_allclose(
        comp.drift_dph(th, 20.0), true_drift(th * DEG, 20.0) / DEG_PER_H, atol=1e-9
    )
    np.testing.assert_allclose(comp.scale_factor_at(th, 20.0), true_sf(th * DEG, 20.0), atol=1e-9)
    # No temperature dependence: at −40 °C it still predicts the +20 °C curve.
    np.testing.assert_allclose(comp.drift_dph(th, -40.0, warn=False), comp.drift_dph(th, 20.0))
    # a NaN/inf angle or temperature, or non-numbers: one line naming the argument (the
    # compiled program would otherwise stop on its non-finite output, naming no input)
    with pytest.raises(ValueError, match=r"FourierCompensator.drift_dph: theta_deg must be "
                       r"finite; it has nan at index \(1,\)"):  # fmt: skip
        comp.drift_dph([0.0, np.nan], 20.0)
    with pytest.raises(ValueError, match="scale_factor_at: temperature_c must be finite"):
        comp.scale_factor_at(th, np.full(th.shape, np.inf))
    with pytest.raises(TypeError, match="theta_deg must be real numbers"):
        comp.drift_dph(["a"], 20.0)


def test_fourier_leaves_only_noise_on_periodic_drift():
    noisy = synthetic_windows(noise_dph=0.01, seed=3)
    comp = FourierCompensator(temperature_degree=4).fit(noisy)
    st = noisy.select(noisy.static)
    resid = st.drift_dph - comp.drift_dph(st.wave_angle_deg, st.temperature_c)
    dof = resid.size - 5 * 5
    chi2 = np.sum((resid / 0.01) ** 2) / dof
    assert 0.7 < chi2 < 1.4  # residual is the injected noise, nothing systematic


def test_mlp_fits_smooth_laws(exact_windows):
    comp = MLPCompensator(steps=3000).fit(exact_windows, key=jax.random.key(0))
    th = np.linspace(-90, 90, 73)
    for temp in (-40.0, 20.0, 60.0):
        truth = true_drift(th * DEG, temp) / DEG_PER_H
        err = comp.drift_dph(th, temp) - truth
        assert np.sqrt(np.mean(err**2)) < 0.01 * 3.9  # < 1 % of the −40 °C peak-to-peak
        sf_err = comp.scale_factor_at(th, temp) - true_sf(th * DEG, temp)
        assert np.max(np.abs(sf_err)) < 5e-4


def test_mlp_periodic_encoding_is_exactly_periodic(exact_windows):
    """Also compile once: a fit with another learning rate (Rprop's step, a value; a
    `TRAINING_FIELDS` entry, reset in the evaluating programs) compiles nothing; it was 3
    programs."""
    from helpers import CompileCounter

    comp = MLPCompensator(steps=50).fit(exact_windows, key=jax.random.key(1))
    np.testing.assert_allclose(comp.drift_dph([-90.0], 0.0), comp.drift_dph([90.0], 0.0))
    with CompileCounter() as c:
        other = MLPCompensator(steps=50, learning_rate=3e-3, e2e_steps=100)
        other.fit(exact_windows, key=jax.random.key(1)).drift_dph([-90.0], 0.0)
    assert c.compiles == 0, c.names
    seed_style = MLPCompensator(steps=50, encoding="angle").fit(
        exact_windows, key=jax.random.key(1)
    )
    assert seed_style.in_size == 2


def test_physical_drift_and_sf_match_reduced_laws():
    """D and SF of the physical compensator equal PHYSICS.md §4.1/§4.7 for a known gyro."""
    v = dict(zip(physical.NAMES, np.zeros(len(physical.NAMES)), strict=True))
    v.update(
        k_e0=K * 1.001,
        bias0=0.3 * DEG_PER_H,
        delta_inv_tau0=4e-6,
        theta_tau0=0.4,
        gain_mismatch0=2e-3,
    )
    values = jnp.asarray([v[n] for n in physical.NAMES])
    comp = PhysicalCompensator(values=values, covariance=jnp.eye(values.size))
    th_true = np.linspace(-1.5, 1.5, 13)
    th_meas = th_true - 2e-3 * np.sin(2 * th_true)  # readout, first order (PHYSICS §4.7)
    d = np.asarray(jax.vmap(lambda a: comp.drift(a, 20.0))(jnp.asarray(th_meas)))
    sf = np.asarray(jax.vmap(lambda a: comp.scale_factor(a, 20.0))(jnp.asarray(th_meas)))
    slope = 1 - 2 * 2e-3 * np.cos(2 * th_true)
    pattern_rate = -v["k_e0"] * v["bias0"] + 0.5 * 4e-6 * np.sin(2 * (th_true - 0.4))
    np.testing.assert_allclose(d, -slope * pattern_rate / K, rtol=2e-5, atol=1e-12)
    np.testing.assert_allclose(sf, slope * v["k_e0"] / K, rtol=1e-5)


# --- correction ----------------------------------------------------------------------------


def _run(rate_dps, drift_dph, n=101, dt=0.5, theta0=20.0, run=0):
    t = np.arange(n) * dt
    theta = theta0 - K * (rate_dps + drift_dph / 3600.0) * t
    return dict(
        time_s=t,
        run=np.full(n, run),
        temperature_c=np.full(n, 20.0),
        table_rate_dps=np.full(n, rate_dps),
        wave_angle_deg=theta,
    )


def test_correct_removes_a_known_constant_drift():
    parts = [_run(0.0, 1.5, run=0), _run(5.0, 1.5, run=1)]
    data = hg.MeasuredData({k: np.concatenate([p[k] for p in parts]) for k in parts[0]})
    comp = FourierCompensator(harmonics=1)
    coef = jnp.zeros((1, 3))
    comp = eqx.tree_at(
        lambda c: (c.drift_coef, c.sf_coef),
        comp,
        (coef.at[0, 0].set(1.5 * DEG_PER_H), coef.at[0, 0].set(1.0)),
        is_leaf=lambda x: x is None,
    )
    out = comp.correct(data)
    np.testing.assert_allclose(out["angle_corrected_deg"], data.table_angle_deg, atol=1e-9)
    np.testing.assert_allclose(out["rate_corrected_dps"], data["table_rate_dps"], atol=1e-9)
    raw = NoCompensation().correct(data)
    assert abs(raw["angle_corrected_deg"][100] - 1.5 / 3600 * 50) < 1e-9
    assert out.names[: len(data.names)] == data.names  # input columns kept unchanged
    with pytest.raises(ValueError, match="already has"):
        comp.correct(out)


def _exact_session_compensator():
    """The closed-form session's laws at +20 °C as a Fourier compensator (one 2θ harmonic,
    no law in T): exact there, so `correct`'s error is its integration's alone."""
    phase = 25.0 * DEG
    drift = [0.3, 1.5 * np.sin(2 * phase), -1.5 * np.cos(2 * phase)]
    return eqx.tree_at(
        lambda c: (c.drift_coef, c.sf_coef),
        FourierCompensator(harmonics=1),
        (jnp.asarray([drift]) * DEG_PER_H, jnp.asarray([[1.0, -2 * 0.0046, 0.0]])),
        is_leaf=lambda x: x is None,
    )


def _end_errors(comp, data):
    """Per run: `correct`'s case angle at the run's end minus the table's [°]."""
    angle = comp.correct(data)["angle_corrected_deg"]
    return np.array([angle[ix[-1]] - data.table_angle_deg[ix[-1]] for ix in data.run_indices()])


def test_correct_integrates_each_sample_interval_over_its_arc(monkeypatch):
    """Logged at 1 Hz at 50 °/s a sample spans 27.7° of electrical arc: evaluated at the
    interval's middle the compensated rate left 3.4e-2° after 60 s with the exact laws (the
    midpoint rule's Δθ³·(1/SF)'' per interval does not average out); integrated over the arc
    (Gauss–Legendre, 4 nodes a ≤ 22.5° piece) 6.8e-6°, what the drift term's uniform motion
    leaves — and 8× finer pieces change it by < 1e-10° (4 nodes are enough)."""
    from hrgjax.calibration import _correction

    comp = _exact_session_compensator()
    data = closed_form_session(temps=(20.0,), rate_dps=50.0, dt=1.0, duration_s=60.0)
    err = _end_errors(comp, data)
    static = data["table_rate_dps"][[ix[0] for ix in data.run_indices()]] == 0
    assert np.max(np.abs(err[static])) < 1e-10
    assert np.max(np.abs(err[~static])) < 2e-5  # before: 3.4e-2 (RMS 2.0e-2 for a fitted T²)
    monkeypatch.setattr(_correction, "ARC_RAD", _correction.ARC_RAD / 8)
    np.testing.assert_allclose(_end_errors(comp, data), err, rtol=0, atol=1e-10)


@pytest.mark.parametrize("rate_dps", [5.0, 50.0])
def test_a_gap_in_a_run_is_integrated_over_its_arc_without_a_warning(rate_dps):
    """20 s of samples lost mid-run (55° of electrical arc at 5 °/s, 554° at 50 °/s): the arc
    is known at both ends, so `correct` integrates the gap like any interval (its scale-factor
    term depends on the end angles only) and says nothing; at 5 °/s the end error was −0.13°
    with the midpoint rule, 0.0000° without the gap."""
    comp = _exact_session_compensator()
    data = closed_form_session(temps=(20.0,), rate_dps=rate_dps, dt=0.5, duration_s=60.0)
    cols = dict(data.columns)
    keep = ~((cols["time_s"] > 20.0) & (cols["time_s"] < 40.0))
    gap = hg.MeasuredData({k: v[keep] for k, v in cols.items()})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        err = _end_errors(comp, gap)
    np.testing.assert_allclose(err, _end_errors(comp, data), rtol=0, atol=5e-5)
    assert np.max(np.abs(err)) < 5e-5


# --- end-to-end training -------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_runs():
    parts = [_run(0.0, 2.0, n=41, run=0), _run(5.0, 2.0, n=41, run=1, theta0=-30.0)]
    data = hg.MeasuredData({k: np.concatenate([p[k] for p in parts]) for k in parts[0]})
    return data, mlp_module.run_groups(data, window_s=5.0)


def test_integrate_compensated_is_exact_for_linear_data(small_runs):
    data, groups = small_runs
    comp = NoCompensation()
    g = groups[0]
    psi = mlp_module.integrate_compensated(comp, g.t[0], g.theta[0], g.temperature_c[0], g.t[0])
    expected = -(g.theta[0] - g.theta[0][0]) / K
    np.testing.assert_allclose(psi, expected, rtol=1e-10, atol=1e-14)


def test_correct_is_the_integral_along_the_record_and_the_midpoint_sum_is_close(
    small_runs, exact_windows
):
    """Two methods, one answer: adaptive Gauss–Kronrod (`scipy.integrate.quad_vec`, to 1e-15
    rad/s) of the compensated rate over every sample interval at once, θ and T linear between
    samples, through the NumPy API (`drift_dph`, `scale_factor_at`), against `correct`'s
    Gauss–Legendre quadrature over each interval's arc — for a compensator whose D and SF
    vary with the wave angle, on a temperature ramp; the training's sum
    (`integrate_compensated`, the same rule) equals it to round-off (its midpoint rule
    before: within 2e-6, its O(Δθ²) error at 1.4° electrical a sample)."""
    from scipy.integrate import quad_vec

    data, _ = small_runs
    comp = FourierCompensator(temperature_degree=1).fit(exact_windows)
    idx = data.run_indices()[1]  # the 5 °/s run
    cols = dict(data.columns)
    cols["temperature_c"] = cols["temperature_c"] + 0.05 * cols["time_s"]  # a ramp too
    ramp = hg.MeasuredData(cols)
    angle = comp.correct(ramp)["angle_corrected_deg"][idx]
    t, th, tc = (ramp[c][idx] for c in ("time_s", "wave_angle_deg", "temperature_c"))
    dt, dth, dtc = np.diff(t), np.diff(th), np.diff(tc)

    def rate(s):  # [°/s] at the fraction s of every interval
        a, b = th[:-1] + s * dth, tc[:-1] + s * dtc
        drift = comp.drift_dph(a, b) / 3600
        return (-dth / dt / K - drift) / comp.scale_factor_at(a, b)

    mean, _ = quad_vec(rate, 0.0, 1.0, epsabs=1e-15 / DEG, epsrel=0.0)
    expected = np.concatenate([[0.0], np.cumsum(mean * dt)])
    assert np.max(np.abs(angle)) > 50.0  # a real signal: 100° of case rotation
    # the rule takes the fewest nodes that meet 4 nodes' bound on a 22.5° piece (5e-6 of a
    # 4θ harmonic, `node_count`): here 1.1e-11° on 2.5°, 4 nodes gave round-off
    np.testing.assert_allclose(angle, expected, rtol=1e-10, atol=1e-12)
    psi = mlp_module.integrate_compensated(comp, t, th * DEG, tc, t) / DEG
    np.testing.assert_allclose(psi, angle, rtol=1e-13, atol=1e-12)


def test_integrate_compensated_equals_a_diffrax_solve(small_runs, exact_windows):
    """The vectorised arc quadrature (Gauss–Legendre, `correct`'s rule) against diffrax's
    8th-order Dopri8 stepping 4× finer than the sample grid (a second method), for a
    compensator with angle- and temperature-dependent terms. (With the midpoint rule it
    used before, the two were 4.2e-7 rad apart here, 2.8e-7 of the angle.)"""
    import diffrax

    _, groups = small_runs
    comp = FourierCompensator(temperature_degree=1).fit(exact_windows)
    g = groups[0]
    t, th, tc = g.t[1], g.theta[1], g.temperature_c[1] + 0.05 * g.t[1]  # a ramp too
    path = diffrax.LinearInterpolation(ts=t, ys=jnp.stack([th, tc], axis=-1))

    def field(s, psi, args):
        (a, b), (da, db) = path.evaluate(s), path.derivative(s)
        return comp.corrected_rate(a, da, b, db)

    ts = t[::7]
    sub = t[:-1, None] + jnp.diff(t)[:, None] * jnp.arange(4.0)[None] / 4  # 4 steps an interval
    steps = jnp.concatenate([sub.ravel(), t[-1:]])
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field), diffrax.Dopri8(), t0=t[0], t1=t[-1], dt0=None,
        y0=jnp.zeros(()), saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.StepTo(ts=steps), max_steps=steps.shape[0],
    )  # fmt: skip
    psi = mlp_module.integrate_compensated(comp, t, th, tc, ts)
    assert float(jnp.max(jnp.abs(sol.ys))) > 1e-3  # a real signal, not zeros
    np.testing.assert_allclose(psi, sol.ys, rtol=1e-10, atol=1e-15)  # node_count: 4e-12 here


def test_end_to_end_gradient_matches_finite_differences(small_runs):
    _, groups = small_runs
    comp = MLPCompensator(drift_width=4, sf_width=3).init(jax.random.key(2))
    comp = eqx.tree_at(lambda c: (c.drift_scale, c.sf_scale), comp, (1e-5, 1e-3))

    def loss(shift):
        c = eqx.tree_at(lambda c: c.drift_offset, comp, comp.drift_offset + shift)
        c = eqx.tree_at(lambda c: c.sf_net.layers[0].bias, c, c.sf_net.layers[0].bias + shift)
        return sum(mlp_module.end_to_end_loss(c, g) for g in groups)

    grad = jax.jit(jax.grad(loss))(0.0)
    loss = jax.jit(loss)
    h = 1e-7
    fd = (loss(h) - loss(-h)) / (2 * h)
    assert np.isfinite(grad)
    np.testing.assert_allclose(grad, fd, rtol=1e-5)


# --- physical fit: coverage of the reported uncertainties ---------------------------------


def _injected_truth() -> dict:
    """Physical parameters injected into the simulated bench sessions (`_injected_session`)."""
    truth = dict(zip(physical.NAMES, np.zeros(len(physical.NAMES)), strict=True))
    truth.update(
        k_e0=K,
        bias0=0.2 * DEG_PER_H,
        delta_inv_tau0=3e-6,
        delta_inv_tau_lam=-0.015,
        theta_tau0=0.45,
        theta_tau1=0.003,
        gain_mismatch0=3e-3,
        gain_mismatch1=-6e-5,
    )
    return truth


def _injected_session(gyro, seed: int):
    """A bench session of `gyro`: 3 temperatures × 6 angles, 60-s static and 5 °/s runs at
    0.5 s (36 runs of 121 samples, one compiled fit group)."""
    temps, angles = (-40.0, 20.0, 60.0), tuple(range(-90, 90, 30))
    static = static_plan(temps, angles, duration_s=60.0, dt_out=0.5)
    rotation = hg.calibration.rotation_plan(temps, angles, duration_s=60.0, dt_out=0.5)
    key = jax.random.key(100 + seed)
    d1 = run_plan(gyro, static, key=key, bias_key=key)
    d2 = run_plan(gyro, rotation, key=jax.random.fold_in(key, 1), first_run=static.size)
    return hg.data.concat([d1, d2])


@pytest.mark.slow(
    "~40 s: 20 noisy benches fitted; fast tier: the physical fit's values on one bench "
    "(test_calibration); benchmarks/coverage.py --only-physical measures the σ's coverage "
    "at scale"
)
def test_physical_fit_recovers_injected_damping_within_uncertainty():
    truth = _injected_truth()
    gyro = noisy_model_gyro(jnp.asarray([truth[n] for n in physical.NAMES]))
    hits = {"delta_inv_tau0": 0, "theta_tau0": 0}
    seeds = 20
    for seed in range(seeds):
        fit = PhysicalCompensator().fit(_injected_session(gyro, seed))
        params = fit.parameters()
        for name in hits:
            value, err = params[name]
            hits[name] += abs(value - truth[name]) < 2 * err
    # 2σ covers 95 % of seeds when the errors are right; require ≥ 90 %.
    assert hits["delta_inv_tau0"] >= 0.9 * seeds, hits
    assert hits["theta_tau0"] >= 0.9 * seeds, hits


def test_physical_fit_of_jittered_time_stamps_compiles_one_group_and_fits_as_clean():
    """Logged time stamps jitter: runs apart only by that share one compiled group (were one
    group per run: 36 runs, 34–36 groups, a fit of > 15 min instead of seconds), and each run
    keeps its own stamps — with 1 µs jitter on 0.5 s samples (2 ppm of a 10-s window's 20
    samples at 5 °/s: ≈ 0.005 °/h) the fit is the clean-stamp fit to 0.05 σ."""
    truth = _injected_truth()
    data = _injected_session(noisy_model_gyro(jnp.asarray([truth[n] for n in physical.NAMES])), 0)
    clean = PhysicalCompensator().fit(data)
    cols = {k: np.array(v) for k, v in data.columns.items()}
    cols["time_s"] = cols["time_s"] + np.random.default_rng(3).normal(0, 1e-6, data.run.size)
    jittered = hg.MeasuredData(cols)
    assert len(jittered.stacked()) == len(data.stacked()) == 1
    assert len(physical.fit_groups(jittered, PhysicalCompensator().window_s, K)) == 1
    for stack in jittered.stacked():  # each run's own stamps, not a resampled grid
        np.testing.assert_array_equal(stack.t, cols["time_s"][stack.rows])
    fit = PhysicalCompensator().fit(jittered)
    z = (np.asarray(fit.values) - np.asarray(clean.values)) / np.sqrt(np.diag(clean.covariance))
    assert np.max(np.abs(z)) < 0.05, dict(zip(physical.NAMES, z.round(3), strict=True))
    # the statistics `hrgjax calibrate` prints (test_cli stands a fake fit in): at-rest and
    # rotation windows' scatter [°/h], χ²/dof 1 by construction
    stats = fit.fit_stats
    assert stats["chi2_per_dof"] == pytest.approx(1.0, abs=1e-6)
    assert 0 < stats["static_rms_dph"] < stats["moving_rms_dph"] < 1.0  # 0.006, 0.14 °/h
    # each kind's σ rests on its windows less their leverages (Σ = 12 parameters): the 18
    # static runs carry the bias and damping laws (ν ≈ 11), so every σ is widened as a t's
    assert stats["rest_dof"] + stats["moving_dof"] == pytest.approx(126 - 12, abs=1e-6)
    assert 9 < stats["rest_dof"] < 13, stats
    # the nominal gain k_e divides the measured and the simulated rates alike: another value
    # fits the same parameters, and compiles nothing (it was a constant of the fit's program)
    with CompileCounter() as c:
        other = PhysicalCompensator(k_e=1.02 * K).fit(data)
    assert c.compiles == 0, c.names
    z = (np.asarray(other.values) - np.asarray(clean.values)) / np.sqrt(np.diag(clean.covariance))
    assert np.max(np.abs(z)) < 1e-3, dict(zip(physical.NAMES, z.round(5), strict=True))
    with pytest.raises(RuntimeError, match=r"not converge in max_steps = 2 steps; give Phys"):
        PhysicalCompensator(max_steps=2).fit(data)  # the knob named, not optimistix's words


def test_residual_scatter_counts_each_kinds_degrees_of_freedom():
    """Linear least squares: σ² = RSS/(n − p) is unbiased. With the parameters all carried by
    one kind the per-kind estimate is exactly that; with two kinds sharing them it is
    unbiased for each kind (Monte Carlo), where the plain RMS of the few at-rest rows is not."""
    rng = np.random.default_rng(7)
    n_rest, n_moving, p = 18, 60, 8
    weights = {True: np.r_[np.ones(n_rest), 0.0, 0.0], False: np.ones(n_moving)}  # 2 padded
    # (a) every parameter in the at-rest rows: classic RSS/(n − p), the other kind its RMS
    j_rest = np.r_[rng.standard_normal((n_rest, p)), np.zeros((2, p))]
    r_rest = np.r_[rng.standard_normal(n_rest), 0.0, 0.0]
    r_rest = r_rest - j_rest @ np.linalg.lstsq(j_rest, r_rest, rcond=None)[0]  # a residual
    r_moving = 3.0 * rng.standard_normal(n_moving)
    jac = {True: j_rest, False: np.zeros((n_moving, p))}
    sigma = physical.scatter_per_dof({True: r_rest, False: r_moving}, jac, weights)
    assert sigma[True] == pytest.approx(np.sqrt(r_rest @ r_rest / (n_rest - p)), rel=1e-12)
    assert sigma[False] == pytest.approx(np.sqrt(np.mean(r_moving**2)), rel=1e-12)
    # (b) shared parameters, σ = 1 at rest and 5 moving: the per-kind σ² average to the truth
    j_rest = np.r_[rng.standard_normal((n_rest, p)), np.zeros((2, p))]
    j_moving = 0.3 * rng.standard_normal((n_moving, p))
    jac = {True: j_rest, False: j_moving}
    true_sigma = {True: 1.0, False: 5.0}
    w = np.r_[j_rest[:n_rest] / 1.0, j_moving / 5.0]
    est, rms = {True: [], False: []}, []
    for _ in range(400):
        e = {True: rng.standard_normal(n_rest), False: 5.0 * rng.standard_normal(n_moving)}
        y = np.r_[e[True] / 1.0, e[False] / 5.0]
        fit = np.r_[j_rest[:n_rest], j_moving] @ np.linalg.lstsq(w, y, rcond=None)[0]
        res = {True: np.r_[e[True] - fit[:n_rest], 0.0, 0.0], False: e[False] - fit[n_rest:]}
        s = physical.scatter_per_dof(res, jac, weights)
        for k in est:
            est[k].append(s[k] ** 2 / true_sigma[k] ** 2)
        rms.append(np.mean(res[True][:n_rest] ** 2))
    assert np.mean(est[True]) == pytest.approx(1.0, abs=0.06)  # 400 draws: ±0.03 (1 s.e.)
    assert np.mean(est[False]) == pytest.approx(1.0, abs=0.03)
    assert np.mean(rms) < 0.8  # the plain RMS at rest: (n − p_rest)/n ≈ 0.6 of σ²


def test_parameter_sigmas_from_few_windows_are_widened_to_cover_as_normal_ones():
    """Linear least squares, two kinds of windows each with its σ estimated from its own
    residuals (18 at-rest rows carrying 8 parameters, ν ≈ 10): a parameter's error over its
    σ is a Student t, z-RMS √(ν/(ν − 2)) ≈ 1.12, ±2σ covering ≈ 92 %. `t_factors` widens
    each σ by that factor (Satterthwaite's ν of the kinds it rests on): z-RMS 1, ±2σ ≈ 95 %
    (the grey box's 3 × 6 static runs covered 93 % before, 95 % after:
    benchmarks/coverage_physical.py)."""
    rng = np.random.default_rng(11)
    n_rest, n_moving, p, draws = 18, 60, 8, 600
    weights = {True: np.r_[np.ones(n_rest), 0.0, 0.0], False: np.ones(n_moving)}  # 2 padded
    j = {True: np.r_[rng.standard_normal((n_rest, p)), np.zeros((2, p))],
         False: 0.3 * rng.standard_normal((n_moving, p))}  # fmt: skip
    truth_sigma = {True: 1.0, False: 5.0}
    raw, wide = [], []
    for _ in range(draws):
        e = {k: truth_sigma[k] * rng.standard_normal(j[k].shape[0]) * (weights[k] > 0)
             for k in j}  # fmt: skip
        w = np.r_[j[True] / truth_sigma[True], j[False] / truth_sigma[False]]
        x = np.linalg.lstsq(w, np.r_[e[True], e[False] / 5.0], rcond=None)[0]
        res = {k: e[k] - j[k] @ x * (weights[k] > 0) for k in j}  # truth: x = 0
        sigma = physical.scatter_per_dof(res, j, weights)
        jw = np.r_[j[True] / sigma[True], j[False] / sigma[False]]
        err = np.sqrt(np.diag(np.linalg.inv(jw.T @ jw)))
        factors, nu = physical.t_factors(jw, weights, sigma)
        raw.append(x / err)
        wide.append(x / (err * factors))
    assert 8 < nu[True] < 12 and nu[False] > 55, nu  # n − leverages of each kind
    raw, wide = np.asarray(raw), np.asarray(wide)
    assert 1.07 < np.sqrt(np.mean(raw**2)) < 1.2  # a t with ν ≈ 10 read as a normal
    assert np.sqrt(np.mean(wide**2)) == pytest.approx(1.0, abs=0.04)
    assert np.mean(np.abs(raw) < 2) < 0.935 < np.mean(np.abs(wide) < 2)


# --- export ---------------------------------------------------------------------------------


def test_export_round_trips(tmp_path, exact_windows):
    th = np.linspace(-90, 90, 7)
    comps = [
        FourierCompensator(temperature_degree=2).fit(exact_windows),
        MLPCompensator(steps=20).fit(exact_windows, key=jax.random.key(3)),
        PhysicalCompensator(
            values=jnp.asarray(physical.initial_values(exact_windows)),
            covariance=jnp.eye(len(physical.NAMES)),
        ),
    ]
    for i, comp in enumerate(comps):
        ref = (comp.drift_dph(th, -10.0), comp.scale_factor_at(th, -10.0))
        back = load_compensator(save_compensator(comp, tmp_path / f"m{i}.eqx"))
        js = export_json(comp, tmp_path / f"m{i}.json")
        with open(js) as fh:
            doc = json.load(fh)
        assert doc["class"] == type(comp).__name__
        if isinstance(comp, PhysicalCompensator):  # each parameter's unit beside it (added)
            units = doc["parameter_units"]
            assert list(units) == list(doc["parameters"]) == list(physical.NAMES)
            assert (units["k_e0"], units["bias0"], units["bias2"], units["theta_tau1"],
                    units["delta_inv_tau0"]) == ("1", "rad/s", "rad/s/degC^2", "rad/degC",
                                                 "1/s")  # fmt: skip
        for other in (back, load_json(js)):
            assert type(other) is type(comp)
            np.testing.assert_array_equal(other.drift_dph(th, -10.0), ref[0])
            np.testing.assert_array_equal(other.scale_factor_at(th, -10.0), ref[1])
    (tmp_path / "bad.eqx").write_text("not a model")
    with pytest.raises(ValueError, match="not an hrgjax compensator"):
        load_compensator(tmp_path / "bad.eqx")


# --- bad input ------------------------------------------------------------------------------


def test_bad_plans_are_refused():
    with pytest.raises(ValueError, match="temperatures_c is empty"):
        static_plan([], [0.0])
    with pytest.raises(ValueError, match="duplicates"):
        static_plan([20.0, 20.0], [0.0, 10.0])
    with pytest.raises(ValueError, match="angles_deg is empty"):
        hg.calibration.rotation_plan([20.0], [])


def test_missing_rotation_runs_for_scale_factor(exact_windows):
    static_only = exact_windows.select(exact_windows.static)
    for comp in (FourierCompensator(), MLPCompensator(steps=5)):
        with pytest.raises(ValueError, match="no rotation runs"):
            comp.fit(static_only, key=jax.random.key(0))  # one call for every compensator
    moving_only = exact_windows.select(~exact_windows.static)
    with pytest.raises(ValueError, match="no static runs"):
        FourierCompensator().fit(moving_only)


def test_one_fit_call_for_every_compensator_and_the_old_keywords_still_work():
    """Issue 45: `fit(data, key=…, raw=…)` is every compensator's call (settings are fields);
    the per-call keywords of earlier versions (`window_s`, `mode`, `initial`) give the same
    fit."""
    data = closed_form_session(duration_s=30.0)
    windows, key = reduce(data, window_s=5.0), jax.random.key(2)
    th = np.linspace(-90.0, 90.0, 7)
    same = lambda a, b: np.testing.assert_array_equal(a.drift_dph(th, 0.0), b.drift_dph(th, 0.0))
    fourier = FourierCompensator(temperature_degree=2, window_s=5.0)
    new = fourier.fit(windows, key=key, raw=data)  # raw: the windows' session (checked)
    for old in (FourierCompensator(temperature_degree=2).fit(data, window_s=5.0),
                FourierCompensator(temperature_degree=2).fit(data, 5.0), fourier.fit(data)):  # fmt: skip
        same(new, old)
    mlp = MLPCompensator(steps=20, e2e_steps=2, mode="end_to_end", window_s=5.0)
    new = mlp.fit(windows, key=key, raw=data)
    old = MLPCompensator(steps=20, e2e_steps=2).fit(windows, key=key, mode="end_to_end",
                                                    window_s=5.0, raw=data)  # fmt: skip
    same(new, old)
    assert (new.mode, new.window_s) == (old.mode, old.window_s) == ("end_to_end", 5.0)
    with CompileCounter() as c:  # another learning rate, end to end too: nothing compiled
        faster = dataclasses.replace(mlp, learning_rate=3e-3).fit(windows, key=key, raw=data)
    assert c.compiles == 0, c.names
    assert faster.learning_rate == 3e-3 and faster.mode == "end_to_end"
    with pytest.raises(TypeError, match="key="):
        MLPCompensator().fit(windows)
    with pytest.raises(ValueError, match="mode must be one of"):
        MLPCompensator(mode="joint")
    raw_gyro = NoCompensation()
    assert raw_gyro.fit(windows, key=key, raw=data) is raw_gyro
    with pytest.raises(TypeError, match="raw samples"):
        PhysicalCompensator().fit(windows, key=key)
    x0 = jnp.asarray(physical.initial_values(windows))
    assert PhysicalCompensator(initial=x0).initial is x0


def test_fourier_base_needs_points_at_fit_temperature(exact_windows):
    with pytest.raises(ValueError, match="within 1.0 °C of the fit temperature 25"):
        FourierCompensator(fit_temperature_c=25.0).fit(exact_windows)


def test_mlp_bins_targets_by_temperature_level_not_by_sensor_noise():
    """Windows of one level whose temperatures carry 0.005 °C of sensor noise share cells:
    120 windows over 0–178° in 5° cells are 36 cells, not one each."""
    theta = np.linspace(0.0, 178.0, 120) * DEG
    noisy = 20.0 + 0.005 * np.random.default_rng(5).standard_normal(theta.size)
    th, tc, value = mlp_module.bin_targets(theta, noisy, np.ones_like(theta), 5.0)
    assert th.size == 36
    np.testing.assert_allclose(tc, 20.0, atol=0.02)
    np.testing.assert_allclose(value, 1.0)
    two = mlp_module.bin_targets(np.r_[theta, theta], np.r_[noisy, noisy + 40.0],
                                 np.ones(2 * theta.size), 5.0)  # fmt: skip
    assert two[0].size == 72


def test_fourier_refusal_names_temperatures_too_close_for_the_polynomial():
    """temperature_degree=3 on four levels 0.6 °C apart (wave angles fine): the refusal
    blames the temperatures, not the wave angles."""
    temps, angles = np.array([59.0, 59.6, 60.2, 60.8]), np.arange(-90.0, 90.0, 15.0)
    tt, aa = (x.ravel() for x in np.meshgrid(temps, angles, indexing="ij"))
    n = tt.size
    table = np.r_[np.zeros(n), np.full(n, 5.0)]
    w = RateWindows(
        run=np.arange(2 * n), start=np.zeros(2 * n, int), stop=np.full(2 * n, 10),
        t_mid=np.full(2 * n, 5.0), duration=np.zeros(2 * n),  # point values: no arc
        temperature_c=np.r_[tt, tt], table_rate_dps=table, wave_angle_deg=np.r_[aa, aa],
        rate_dps=table + 1e-4 * np.cos(2 * np.r_[aa, aa] * DEG), stderr_dps=np.full(2 * n, 1e-6),
        k_e=K,
    )  # fmt: skip
    with pytest.raises(ValueError) as err:
        FourierCompensator(temperature_degree=3).fit(w)
    msg = str(err.value)
    assert msg.startswith("drift (static runs): the windows' temperatures do not determine")
    assert "+59.0, +59.6, +60.2, +60.8 °C" in msg and "lower temperature_degree" in msg
    assert "wave angles" not in msg
    FourierCompensator(temperature_degree=1).fit(w)  # a line in T: these levels do for it


def test_laws_in_temperature_need_enough_distinct_temperatures(exact_windows, monkeypatch):
    """Audit items 1 and 3: a temperature polynomial fitted to fewer temperatures than it has
    coefficients was a made-up law (SF 0.55 at +20 °C from −40 and +60 °C; flat in T from
    one), the grey box at one temperature a bare 'Singular matrix', at two σ of 6.6e4."""
    w = exact_windows
    two = w.select(np.isin(w.temperature_c, [-40.0, 60.0]))
    with pytest.raises(ValueError, match=r"^temperature_degree 2 needs at least 3 distinct "
                       r"temperatures in the calibration data's static runs; got 2 \(-40\.0, "
                       r"\+60\.0 °C.*lower temperature_degree \(CLI --temperature-degree\)"):  # fmt: skip
        FourierCompensator(temperature_degree=2).fit(two)
    # one level whose windows scatter by 0.3 °C is one temperature
    one = w.select(w.temperature_c == 20.0)
    one = eqx.tree_at(lambda x: x.temperature_c, one, 20.0 + 0.3 * (np.arange(len(one)) % 2))
    with pytest.raises(ValueError, match=r"^temperature_degree 1 needs at least 2 .* got 1 "):
        FourierCompensator(temperature_degree=1).fit(one)
    rotations_at_two = w.select(w.static | np.isin(w.temperature_c, [-40.0, 60.0]))
    with pytest.raises(ValueError, match=r"^temperature_degree 3 .* rotation runs; got 2 "):
        FourierCompensator(temperature_degree=3).fit(rotations_at_two)
    FourierCompensator(temperature_degree=1).fit(rotations_at_two)  # enough: fitted
    FourierCompensator(temperature_degree=0).fit(one)
    # the grey box: refused before any simulation
    for temps, got in (((20.0,), r"got 1 \(\+20\.0 °C"), ((-40.0, 60.0), r"got 2 \(-40\.0, ")):
        data = closed_form_session(temps=temps, duration_s=20.0)
        with pytest.raises(ValueError, match=r"^the physical model's rate bias law \(quadratic "
                           r"in T\) needs at least 3 distinct temperatures in the calibration "
                           rf"data; {got}"):  # fmt: skip
            PhysicalCompensator().fit(data)
    data = closed_form_session(duration_s=20.0)  # −40, +20, +60 °C
    keep = (data["table_rate_dps"] == 0) | (data["temperature_c"] == 20.0)
    at_one = hg.MeasuredData({k: v[keep] for k, v in data.columns.items()})
    with pytest.raises(ValueError, match=r"^the physical model's k_e\(T\) \(linear in T\) "
                       r"needs at least 2 distinct temperatures in the calibration data's "
                       r"rotation runs; got 1 \(\+20\.0 °C"):  # fmt: skip
        PhysicalCompensator().fit(at_one)
    # a ramp's 300-s windows are temperatures of their own: −40 and +60 °C and a ramp 50 → 70 °C
    data = closed_form_session(temps=(-40.0, 60.0), duration_s=20.0)
    t = np.arange(0.0, 1200.0, 0.5)
    ramp = {"time_s": t, "run": np.full(t.size, data["run"].max() + 1),
            "temperature_c": 50.0 + t / 60.0, "table_rate_dps": np.zeros(t.size),
            "wave_angle_deg": 10.0 - 1e-5 * t}  # fmt: skip
    with_ramp = hg.MeasuredData({k: np.r_[v, ramp[k]] for k, v in data.columns.items()})

    def past_the_checks(*args):
        raise RuntimeError("past the checks")

    monkeypatch.setattr(physical, "fit_groups", past_the_checks)
    with pytest.raises(RuntimeError, match="past the checks"):
        PhysicalCompensator().fit(with_ramp)
    # a normal matrix that is singular names the parameters it leaves free, never LinAlgError
    jac = np.random.default_rng(0).standard_normal((40, len(physical.NAMES)))
    jac[:, physical.NAMES.index("bias2")] = 0.0
    with pytest.raises(ValueError, match=r"^PhysicalCompensator.fit: the calibration data do not "
                       r"identify bias2 \(the fit's normal matrix JᵀJ is singular\)"):  # fmt: skip
        physical._covariance(jac, 1.0)
    jac[:, 4] = 2.0 * jac[:, 3]  # bias2 moves as bias1 does
    with pytest.raises(ValueError, match=r"do not identify bias1, bias2 \("):
        physical._covariance(jac, 1.0)


def test_k_e_is_the_electrical_gain_in_zero_one():
    """Audit item 7: k_e = 55.4 (a percentage) was taken by every compensator."""
    from hrgjax.calibration.self_calibration import PrecessionCompensator

    for cls in (FourierCompensator, MLPCompensator, PhysicalCompensator, NoCompensation,
                PrecessionCompensator):  # fmt: skip
        with pytest.raises(ValueError, match=r"^k_e must be the electrical angular gain k_e = "
                           r"2K, a number in \(0, 1\].*got 55\.4 \(a gain in percent\?"):  # fmt: skip
            cls(k_e=55.4)
        with pytest.raises(ValueError, match=r"^k_e must be .*got 0$"):
            cls(k_e=0.0)
        with pytest.raises(TypeError, match=r"^k_e must be a number"):
            cls(k_e="0.554")
        assert cls(k_e=0.6).k_e == 0.6


def test_unfitted_compensators_say_so(tmp_path):
    """Evaluating, saving or exporting an unfitted compensator is refused in one line (saving
    one wrote a file its loader then blamed on a hand-edited header; exporting an MLP raised
    AttributeError), and no file is left behind."""
    from hrgjax.calibration import export_json, save_compensator

    with pytest.raises(ValueError, match="not fitted"):
        FourierCompensator().drift_dph([0.0], 20.0)
    with pytest.raises(ValueError, match="not fitted"):
        MLPCompensator().drift_dph([0.0], 20.0)
    for comp in (FourierCompensator(), MLPCompensator(), PhysicalCompensator()):
        name = type(comp).__name__
        for write, path in ((save_compensator, tmp_path / "c.eqx"),
                            (export_json, tmp_path / "c.json")):  # fmt: skip
            with pytest.raises(ValueError, match=f"^this {name} is not fitted; fit it before"):
                write(comp, path)
            assert not path.exists()


# --- INS impact (minimal Schuler model) ------------------------------------------------------


@pytest.mark.parametrize(
    ("fields", "error", "match"),
    [
        ({"dt_out": -1.0}, ValueError, r"^Flight\.dt_out must be > 0 s and divide duration_s = "
         r"3600 s into whole steps; got -1\.0$"),
        ({"dt_out": 0.7, "duration_s": 120.0}, ValueError, r"^Flight\.dt_out must be > 0 s and "
         r"divide duration_s = 120 s into whole steps; got 0\.7 \(171\.429 steps\)$"),
        ({"warmup_s": 0.0}, ValueError, r"^Flight\.warmup_s must be > 0 s \(the time constant "
         r"t_w of the warm-up T\(t\)\); got 0\.0$"),
        ({"heading_deg": "north"}, TypeError, r"^Flight\.heading_deg must be a number \[°, "
         r"clockwise from north\]; got str$"),
        ({"speed_mps": np.nan}, ValueError, r"^Flight\.speed_mps must be finite \[m/s\]; got nan$"),
        ({"speed_mps": -200.0}, ValueError, r"^Flight\.speed_mps = -200 is outside the plausible "
         r"range 0 … 10000 m/s"),
        ({"duration_s": -10.0}, ValueError, r"^Flight\.duration_s must be > 0 s; got -10\.0$"),
        ({"temperature_start_c": 233.15}, ValueError, r"^Flight\.temperature_start_c = 233\.15 "
         r"is outside the plausible range .* kelvin"),
        ({"wave_angle_y_deg": None}, TypeError, r"^Flight\.wave_angle_y_deg must be a number "
         r"\[° electrical\]; got NoneType$"),
        ({"lat_deg": 95.0}, ValueError, r"^Flight\.lat_deg must be in \[-89, 89\] °; got 95\.0$"),
    ],
)  # fmt: skip
def test_flight_refuses_each_bad_field_naming_it(fields, error, match):
    """Each field of a `Flight` is checked when built, in one line naming it, the expected
    form and unit (`dt_out=-1` failed later without naming it, `warmup_s=0` raised a bare
    ZeroDivisionError from `temperature_rate`, `heading_deg="north"` built)."""
    from hrgjax.calibration.ins_impact import FLIGHTS, Flight

    with pytest.raises(error, match=match) as info:
        Flight(**fields)
    assert "\n" not in str(info.value)
    for flight in FLIGHTS:  # the study's flights still build
        assert Flight(**{f.name: getattr(flight, f.name) for f in dataclasses.fields(flight)})


def test_schuler_channel_matches_closed_form():
    """PHYSICS.md §12: a constant level gyro bias ε gives δp = Rε(t − sin(ω_s t)/ω_s) and
    δv = Rε(1 − cos ω_s t)."""
    from hrgjax.calibration.ins_impact import EARTH_RADIUS, GRAVITY, schuler_errors

    t = jnp.linspace(0.0, 3600.0, 361)
    eps = 1e-7
    dv, dp = schuler_errors(t, jnp.full(t.shape, eps), jnp.zeros(t.shape))
    ws = np.sqrt(GRAVITY / EARTH_RADIUS)
    tn = np.asarray(t)
    np.testing.assert_allclose(
        dp[:, 0], EARTH_RADIUS * eps * (tn - np.sin(ws * tn) / ws), rtol=1e-6, atol=1e-6
    )
    np.testing.assert_allclose(
        dv[:, 0], EARTH_RADIUS * eps * (1 - np.cos(ws * tn)), rtol=1e-6, atol=1e-9
    )
    np.testing.assert_allclose(dp[:, 1], 0.0, atol=1e-12)
    # the same solve from NumPy arrays (the drive above was a weakly typed `full`) compiles
    # nothing new; times that run backwards, a drive of another length or a NaN: one line
    with CompileCounter() as c:
        _, again = schuler_errors(tn, np.full(tn.shape, eps), np.zeros(tn.shape))
    assert "jit(_schuler)" not in c.names, c.names
    np.testing.assert_allclose(again, dp, rtol=1e-12, atol=1e-9)
    zero = np.zeros(tn.shape)
    bad = [((tn[::-1], zero, zero), "^t must be finite times .s., strictly increasing"),
           ((tn, zero[1:], zero), "^eps_north must be a 1-D array of one gyro error"),
           ((tn, zero, np.where(tn > 60.0, np.nan, 0.0)), "^eps_east must be finite")]  # fmt: skip
    for args, match in bad:
        with pytest.raises(ValueError, match=match):
            schuler_errors(*args)


def test_schuler_channels_are_signed_as_the_strapdown_error_model():
    """Each channel against `hrgjax.ins.strapdown.propagate` (a stationary, level vehicle on
    a sphere that does not turn): a north gyro error moves the vehicle east, an east gyro
    error moves it *south* (the north channel read +2195 m for −2195 m)."""
    from hrgjax.calibration.ins_impact import EARTH_RADIUS, GRAVITY, schuler_errors
    from hrgjax.ins import constants, strapdown, trajectory

    earth = constants.Earth(radius=EARTH_RADIUS, g=GRAVITY, rate=0.0)
    traj = trajectory.stationary(10.0, duration_s=3000.0, dt=10.0, earth=earth)
    eps, t = 1e-7, traj.t
    zero, full = jnp.zeros(t.shape), jnp.full(t.shape, eps)
    for axis, drive in ((0, (full, zero)), (1, (zero, full))):  # north, then east gyro error
        dx = strapdown.propagate(traj, gyro_error=eps * jnp.eye(3)[axis], altitude_aided=True)
        north_east = np.asarray(strapdown.position_metres(traj, dx))[:, :2]
        _, dp = schuler_errors(t, *drive)
        np.testing.assert_allclose(np.asarray(dp)[:, ::-1], north_east, rtol=1e-4, atol=1e-3)


def test_physical_compensates_the_apparent_rate_of_a_temperature_ramp():
    """A readout mismatch that changes with temperature moves the measured angle while the
    temperature changes (rate ∝ Ṫ, PHYSICS.md §4.7 with g(T)); knowing the readout, the
    physical compensator removes it; a compensator fitted at constant temperatures cannot."""
    v = dict(zip(physical.NAMES, np.zeros(len(physical.NAMES)), strict=True))
    v.update(k_e0=K, gain_mismatch0=4e-3, gain_mismatch1=-1e-4, delta_inv_tau0=2e-6)
    values = jnp.asarray([v[n] for n in physical.NAMES])
    comp = PhysicalCompensator(values=values, covariance=jnp.eye(values.size))
    prof = hg.Profile.piecewise([0.0, 300.0], 0.0, [-40.0, -10.0], wave_angle0_deg=30.0)
    rec = hg.simulate(physical.model_gyro(values), prof, dt_out=1.0)
    data = rec.to_data()
    out = comp.correct(data)
    ramp = 0.1 * (-1e-4) * np.sin(np.radians(60.0)) / K / DEG * 3600  # (dg/dT)Ṫ sin2θ/k_e
    raw = NoCompensation().correct(data)["rate_corrected_dps"] * 3600
    drift_only = -0.5 * 2e-6 * np.sin(2 * np.asarray(rec.true_wave_angle)) / K / DEG * 3600
    assert abs(np.mean(raw - drift_only) - ramp) < 0.1 * abs(ramp)  # the effect is there
    np.testing.assert_allclose(out["rate_corrected_dps"] * 3600, 0.0, atol=2e-4)


def test_run_plan_sorts_points_by_rate_and_returns_the_plans_order():
    """A plan mixing 0.1 and 200 °/s points runs them sorted by |rate| (chunks of similar
    cost) and gives the same data as in the plan's order, to round-off (XLA:CPU may round a
    point by an ulp differently at another place in a chunk) — noise keys and run numbers
    follow each point."""
    from hrgjax.calibration import Plan

    gyro = hg.presets.tvg3_like(temperature_laws=False)
    n = 40  # more than one chunk of 32
    rates = np.where(np.arange(n) % 3 == 0, 200.0, 0.1) * np.where(np.arange(n) % 2, 1, -1)
    plan = Plan(jnp.linspace(-40.0, 60.0, n), jnp.linspace(-90.0, 90.0, n), jnp.asarray(rates),
                duration_s=2.0, dt_out=1.0)  # fmt: skip
    key = jax.random.key(5)
    ordered = run_plan(gyro, plan, key=key)
    plain = run_plan(gyro, plan, key=key, order_by_cost=False)
    assert set(ordered.names) == set(plain.names)
    for k in plain.names:
        np.testing.assert_allclose(ordered[k], plain[k], rtol=1e-12, atol=1e-11, err_msg=k)
    first = ordered.columns["table_rate_dps"][ordered.run == 0]
    np.testing.assert_allclose(first, rates[0])


def _restart_moves(fit_a, fit_b) -> dict:
    """How far a fit restarted from `fit_a`'s values moved (`fit_b`), in `fit_a`'s σ's."""
    pa, pb = fit_a.parameters(), fit_b.parameters()
    return {n: (pb[n][0] - pa[n][0]) / pa[n][1] for n in pa}


def test_physical_fit_weighs_each_kind_by_its_scatter_at_the_solution(monkeypatch):
    """`fit_values` on a linear stand-in for the simulator (host arrays, no simulator to
    compile): the start fits the moving windows 30× worse than their noise (as the harmonic
    start does on a plan with ramps), the at-rest ones to their noise. The fit must end at
    the weighted least squares whose weights (each kind's scatter at the solution) and σ's
    it reports — the same as a fit restarted from its result, to 0.05 of each σ — not at the
    optimum of the starting weights (Levenberg–Marquardt alone: 1.1 σ away)."""
    from hrgjax.calibration import _physical_fit as pf

    rng = np.random.default_rng(3)
    p = len(physical.NAMES)
    sig = {True: 1e-7, False: 1e-6}  # each kind's noise [rad/s]
    a_rest = rng.standard_normal((30, p)) * sig[True] / np.sqrt(30)
    a_rest[:, p // 2 :] = 0.0  # the at-rest windows see the first half of the parameters only
    a_mov = rng.standard_normal((60, p)) * sig[False] / np.sqrt(60)
    x_true = np.where(np.arange(p) < p // 2, 0.0, 30.0)  # far in what only moving windows see
    y = {True: a_rest @ x_true + sig[True] * rng.standard_normal(30),
         False: a_mov @ x_true + sig[False] * rng.standard_normal(60)}  # fmt: skip
    scale = np.asarray(physical.SCALE)

    def residuals_jacobian(groups, values, k_e):
        x = np.asarray(values) / scale
        return ({True: y[True] - a_rest @ x, False: y[False] - a_mov @ x},
                {True: -a_rest, False: -a_mov})  # fmt: skip

    monkeypatch.setattr(pf, "residuals_jacobian", residuals_jacobian)
    monkeypatch.setattr(pf, "window_weights", lambda g: {True: np.ones(30), False: np.ones(60)})
    values, _, r, sigma, jac = pf.fit_values(None, np.zeros(p), K, 200)
    again, _, _, _, _ = pf.fit_values(None, values, K, 200)
    err = np.sqrt(np.diag(np.linalg.inv(jac.T @ jac)))
    assert np.max(np.abs(again - values) / err) < 0.05
    # the weighted least squares with the reported weights, solved directly
    w = np.concatenate([np.full(30, 1 / sigma[True]), np.full(60, 1 / sigma[False])])
    a = np.concatenate([a_rest, a_mov]) * w[:, None]
    best = np.linalg.lstsq(a, np.concatenate([y[True], y[False]]) * w, rcond=None)[0] * scale
    assert np.max(np.abs(values - best) / err) < 0.05
    np.testing.assert_allclose(r[True], y[True] - a_rest @ (values / scale), atol=1e-12)


@pytest.mark.slow(
    "~25 s (compiling the fit's simulator); fast tier: "
    "test_physical_fit_weighs_each_kind_by_its_scatter_at_the_solution (a linear stand-in)"
)
def test_physical_fit_restarted_from_its_result_stays_on_a_plan_with_ramps():
    """The audit's case made small (3 levels, 2 static and 2 rotation minutes each, two 10-min
    ramps between them): the harmonic start fits the moving windows ~10× worse than their
    noise, so Levenberg–Marquardt alone, weighing them by that, stopped 1.3 σ (bias1: 1.2 σ)
    from where a fit restarted from its result goes. Now the restart moves no parameter by
    more than 0.05 of its σ."""
    from hrgjax.calibration import design

    segs = []
    levels = (-40.0, 10.0, 60.0)
    for k, temp in enumerate(levels):
        segs += [{"kind": "static", "temperature_c": temp, "wave_angle_deg": a,
                  "duration_s": 60.0} for a in (-60.0, 30.0)]  # fmt: skip
        segs += [{"kind": "rotation", "temperature_c": temp, "wave_angle_deg": a,
                  "rate_dps": 5.0, "duration_s": 60.0} for a in (0.0, 45.0)]  # fmt: skip
        if k < 2:
            segs.append({"kind": "ramp", "temperature_start_c": temp, "wave_angle_deg": 30.0,
                         "temperature_end_c": levels[k + 1], "duration_s": 600.0})  # fmt: skip
    plan = design.BenchPlan.from_segments(segs)
    data = design.simulate_plan(hg.presets.tvg3_like(), plan, key=jax.random.key(102),
                                bias_key=jax.random.key(999))  # fmt: skip
    fit = PhysicalCompensator().fit(data)
    again = PhysicalCompensator(initial=fit.values).fit(data)
    moves = _restart_moves(fit, again)
    assert max(abs(m) for m in moves.values()) < 0.05, moves
