"""Entry points under `jit`, `vmap`, `grad` and `hg.sweep` (trace audit of 2ec03ab).

1. `fog.heading.heading_limit_deg` ended in `float(...)`: jit, vmap over latitude and the
   sensitivity ∂δψ/∂ε all crashed (ConcretizationTypeError). It returns a 0-d array now, and
   holds a traced latitude / drift / bias to its eager rules at run time.
2. `ins.sensors.ImuModel` skipped every value check on traced fields: a bias in °/h typed as
   rad/s, a scale in ppm typed as a fraction, NaN or a negative density swept silently.
   `apply` holds them now (one `eqx.branched_error_if`), compiled once.
3. `fog.spectrum`'s "accel in g" refusal was eager only: under jit a record in g gave
   features 9.81× too small. It has a run-time twin now.
4. `imu.ferraris` blamed a traced (valid) latitude as out of its domain.
5. `allan.composite.gm_white_level` read any sampling but "interval" as "point", and its
   point branch (math.tanh) could not be traced.

Review of 4216a16: a unit drawn by `random_unit` inside jit/vmap (`ins.fly`'s runs) was held
to the `imu_*` ranges, so a valid grade failed at random (a Gaussian draw past a bound);
the jitted g-rule sorted the record (`jnp.median`: 10× slower), now counts. Session 30:
the rule is the record's |mean f| (gravity) instead; `psd` takes a traced fs.
"""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter

import hrgjax as hg
from hrgjax.allan.composite import gm_white_level
from hrgjax.fog import compensation as cp
from hrgjax.fog import spectrum as sp
from hrgjax.ins.sensors import ImuModel, random_unit
from hrgjax.units import DEG_PER_H

OMEGA = 7.292115e-5  # WGS84's Earth rate [rad/s]
LATS = np.radians([10.0, 45.0, 80.0])
EPS_E = 0.01 * DEG_PER_H


# 1. heading_limit_deg


def _limit(eps_e, lat):
    return cp.heading_limit_deg(jnp.stack([0.0, eps_e, 0.0]), np.zeros(3), np.eye(3), lat)


@pytest.fixture(scope="module")
def limit_fns():
    return jax.jit(jax.grad(_limit)), jax.jit(jax.vmap(_limit, in_axes=(None, 0))), jax.jit(_limit)


def test_heading_limit_grad_and_vmap_against_the_analytic_sensitivity(limit_fns):
    grad, over_lat, _ = limit_fns
    # level IMU, east drift only: δψ = −atan2(ε_E, Ω cos φ) [°], so
    # ∂δψ/∂ε_E = −(180/π) Ω cos φ / (Ω² cos² φ + ε_E²)
    for lat in LATS:
        w = OMEGA * np.cos(lat)
        want = -np.degrees(w / (w * w + EPS_E * EPS_E))
        assert float(grad(EPS_E, lat)) == pytest.approx(want, rel=1e-9), lat
    eager = [_limit(EPS_E, lat) for lat in LATS]
    np.testing.assert_allclose(over_lat(EPS_E, jnp.asarray(LATS)), eager, rtol=1e-12)
    np.testing.assert_allclose(eager, -np.degrees(np.arctan2(EPS_E, OMEGA * np.cos(LATS))),
                               rtol=1e-9)  # fmt: skip
    # eagerly a float, as before (JSON, pytest.approx, f-strings)
    assert all(isinstance(r, float) for r in eager) and f"{eager[1]:+.4f}" == "-0.0539"


@pytest.mark.parametrize("eps_e, lat, match", [
    (EPS_E, 45.0, r"lat must be the latitude in radians, finite and \|lat\| ≤ π/2"),
    (EPS_E, np.nan, r"lat must be the latitude in radians"),
    (EPS_E, np.radians(89.5), r"lat must be within ±89° \(MAX_LAT_DEG\)"),
    (0.36, 0.5, r"eps_body must be a bias in rad/s.*°/h\?"),
])  # fmt: skip
def test_heading_limit_traced_values_are_checked_at_run_time(limit_fns, eps_e, lat, match):
    jitted = limit_fns[2]
    assert np.isfinite(jitted(EPS_E, 0.5))
    with pytest.raises(Exception, match=match):
        jax.block_until_ready(jitted(eps_e, lat))


# 2. ImuModel


N, DT = 50, 0.01
FIELDS = ("gyro_bias", "gyro_scale", "arw", "gyro_misalignment")


@pytest.fixture(scope="module")
def imu_fn():
    """Σ measured Δθ over N intervals of a still IMU, every field traced: one program."""
    th, dv = jnp.full((N, 3), 1e-3), jnp.zeros((N, 3))

    def f(kw):
        return ImuModel(**kw).apply(jax.random.key(0), th, dv, DT)[0].sum(axis=0)

    return jax.jit(f)


def _kw(**over):
    return {name: jnp.asarray(over.get(name, 0.0)) for name in FIELDS}


@pytest.mark.parametrize("field, value, match", [
    ("gyro_bias", 10.0, r"ImuModel.gyro_bias \[rad/s\] is outside the plausible range -0.75 … "
                        r"0.75 rad/s.*°/h → ×hrgjax.units.DEG_PER_H"),
    ("gyro_bias", 0.75, r"ImuModel.gyro_bias \[rad/s\] is outside the plausible range -0.75 … "
                        r"0.75 rad/s at one or more points, its bounds excluded — °/h → "),
    ("gyro_scale", 50.0, r"ImuModel.gyro_scale .*plausible range -0.1 … 0.1.*ppm → ×1e-6"),
    ("arw", -1e-3, r"ImuModel.arw is a density or a 1σ: it must be >= 0"),
    ("gyro_bias", np.nan, r"ImuModel.gyro_bias must be finite"),
    ("gyro_misalignment", 5.0, r"ImuModel.gyro_misalignment \[rad\] is outside .*° → "),
])  # fmt: skip
def test_imu_model_traced_fields_are_checked_in_apply(imu_fn, field, value, match):
    with pytest.raises(Exception, match=match):
        jax.block_until_ready(imu_fn(_kw(**{field: value})))


@pytest.mark.parametrize("value", [10.0, -0.75])
def test_imu_model_traced_message_is_the_eager_one_without_the_value(imu_fn, value):
    with pytest.raises(ValueError) as eager:
        ImuModel(gyro_bias=value)
    with pytest.raises(Exception) as traced:
        jax.block_until_ready(imu_fn(_kw(gyro_bias=value)))
    want = str(eager.value).replace(f" = {value:g} at index 0", "")
    want = want.replace("0.75 rad/s", "0.75 rad/s at one or more points")
    assert ("its bounds excluded" in want) is (value == -0.75)  # on a bound only, both ways
    assert want in str(traced.value)


def test_imu_model_checks_compile_once(imu_fn):
    imu_fn(_kw())
    with CompileCounter() as c:  # valid and refused models through the same program
        for b, s in ((2e-5, 1e-4), (-3e-4, 5e-3), (0.7, -0.09)):
            got = imu_fn(_kw(gyro_bias=b, gyro_scale=s))
            # Σ Δθ = N (Δθ (1 + s) + b Δt): still, no noise, exactly
            np.testing.assert_allclose(got, N * (1e-3 * (1 + s) + b * DT), rtol=1e-12)
        with pytest.raises(Exception, match=r"ImuModel.gyro_scale .*ppm → ×1e-6"):
            jax.block_until_ready(imu_fn(_kw(gyro_scale=100.0)))
    assert (c.traces, c.compiles) == (0, 0)


def test_imu_model_checks_hold_under_sweep_and_eager_grad():
    th, dv = jnp.zeros((N, 3)), jnp.zeros((N, 3))

    def rate(gyro_bias):
        return ImuModel(gyro_bias=gyro_bias).apply(jax.random.key(0), th, dv, DT)[0][0, 0] / DT

    with pytest.raises(RuntimeError, match=r"^sweep: at one or more grid points, "
                       r"ImuModel.gyro_bias \[rad/s\] is outside the plausible range"):  # fmt: skip
        hg.sweep(rate, gyro_bias=jnp.array([1e-6, 10.0]))
    # eager grad carries the value: the eager check sees it (the old one skipped the tracer)
    with pytest.raises(ValueError, match=r"ImuModel.gyro_bias \[rad/s\] = 10 at index 0"):
        jax.grad(rate)(10.0)
    assert float(jax.grad(rate)(1e-5)) == pytest.approx(1.0, rel=1e-12)


def test_imu_model_apply_takes_a_traced_dt():
    """jit or vmap over the interval: `math.sqrt(dt)` of the white and random-walk noise
    raised a ConcretizationTypeError (audit of session 29); the eager values."""
    th, dv = jnp.full((N, 3), 1e-3), jnp.zeros((N, 3))
    imu = ImuModel(arw=1e-6, vrw=1e-5, gyro_rate_random_walk=1e-8,
                   gyro_bias_instability=1e-7, gyro_correlation_time=100.0)  # fmt: skip

    def run(dt):
        return imu.apply(jax.random.key(2), th, dv, dt)

    got = jax.jit(jax.vmap(run))(jnp.asarray([DT, 2 * DT]))
    for i, dt in enumerate((DT, 2 * DT)):
        for traced, eager in zip(got, run(dt), strict=True):
            np.testing.assert_allclose(traced[i], eager, rtol=1e-12, atol=0)


def test_drawn_units_are_not_range_checked_but_their_grade_is():
    th, dv = jnp.full((N, 3), 1e-3), jnp.zeros((N, 3))
    keys = jax.random.split(jax.random.key(0), 16)

    @jax.jit
    def units(scale):  # a user's Monte Carlo: the grade traced, each unit drawn and applied
        grade = ImuModel(gyro_scale=scale)

        def one(k):
            unit = random_unit(grade, k)
            return unit.gyro_scale, unit.apply(jax.random.key(1), th, dv, DT)[0].sum(axis=0)

        return jax.vmap(one)(keys)

    drawn, got = units(0.06)  # σ 0.06: P(|draw| ≥ 0.1) = 2Φ(−5/3) = 9.6 % per axis
    assert np.sum(np.any(np.abs(drawn) >= 0.1, axis=1)) >= 2  # were refused: 4216a16
    np.testing.assert_allclose(got, N * 1e-3 * (1.0 + drawn), rtol=1e-12)  # Σ Δθ, exactly
    # the grade's own values are held, traced (here, at run time) and eager (where built)
    with pytest.raises(Exception, match=r"ImuModel.gyro_scale .*plausible range -0.1 … 0.1"):
        jax.block_until_ready(units(0.5))
    with pytest.raises(ValueError, match=r"ImuModel.gyro_scale \[-\] = 0.5 at index 0"):
        ImuModel(gyro_scale=0.5)
    eager = random_unit(ImuModel(gyro_scale=0.06), keys[int(np.argmax(np.abs(drawn).max(1)))])
    assert eager.drawn and np.max(np.abs(eager.gyro_scale)) >= 0.1
    np.testing.assert_allclose(eager.apply(jax.random.key(1), th, dv, DT)[0].sum(axis=0),
                               N * 1e-3 * (1.0 + eager.gyro_scale), rtol=1e-12)  # fmt: skip


# 3. vibration features of a record in g


FS = 200.0


def _record(amp_g, unit):
    t = np.arange(0.0, 4.0, 1.0 / FS)
    a = np.zeros((t.size, 3))
    a[:, 2] = -unit
    a[:, 0] = amp_g * unit * np.sin(2 * np.pi * 20.0 * t)
    return a


def test_vibration_features_refuse_g_under_jit_and_vmap():
    features = jax.jit(lambda a: sp.vibration_features(a, FS))
    in_ms2, in_g = _record(0.5, 9.80665), _record(0.5, 1.0)
    got = np.asarray(features(in_ms2))
    np.testing.assert_allclose(got[:, 0], 20.0, rtol=1e-9)  # the tone: 20 Hz, 0.5 g
    np.testing.assert_allclose(got[:, 1], 0.5, rtol=1e-6)
    match = r"accel must be specific force in m/s²: its mean over the record .*in g\?"
    with pytest.raises(Exception, match=match):  # was 0.051 g: 0.5 g / 9.80665
        jax.block_until_ready(features(in_g))
    with pytest.raises(Exception, match=match):
        jax.vmap(lambda a: sp.vibration_features(a, FS))(jnp.stack([in_ms2, in_g]))


def test_vibration_unit_rule_traced_decides_as_eagerly():
    """(Session 30.) The rule is the record's |mean f| now (gravity; the vibration averages
    out), not the median |f| (which a 3-g vibration in g lifted past 2: read as m/s²). The
    run-time twin decides as the eager rule on each side of each bound, with and without
    `ac_coupled`: m/s² (≥ 3.13), in g (0.3 … 3.13), no gravity (< 0.3), beyond 20 g."""
    t = np.arange(0.0, 2.0, 1.0 / FS)
    vib = 3.0 * np.sin(2 * np.pi * 20.0 * t)  # a 3-g-like tone in any unit: averages out
    cases = {0.0: 1, 0.29: 1, 0.31: 0, 1.0: 0, 3.1: 0, 3.2: None, 9.8: None, 196.0: None,
             197.0: 2}  # |mean f| → index of the broken rule (None: passes)  # fmt: skip
    for ac in (False, True):
        features = jax.jit(lambda a, ac=ac: sp.vibration_features(a, FS, ac_coupled=ac))
        for mean, rule in cases.items():
            a = np.zeros((t.size, 3))
            a[:, 0], a[:, 2] = vib, -mean
            broken = None if (rule == 1 and ac) else rule
            if broken is None:
                assert np.isfinite(np.asarray(features(a))).all(), (ac, mean)
                assert np.isfinite(np.asarray(sp.vibration_features(a, FS, ac_coupled=ac))).all()
                continue
            before, after = (  # each rule's message about the value (eager: " = value")
                ("accel must be specific force in m/s²: its mean over the record (gravity: ≈ "
                 "9.8 m/s² where DC-coupled; vibration averages out) has |mean f|", " within"),
                ("accel carries no gravity: its mean over the record has |mean f|", " below"),
                ("accel must be specific force in m/s²: its mean over the record has |mean f|",
                 " beyond 196.1 m/s² (20 g;"),
            )[broken]  # fmt: skip
            with pytest.raises(Exception, match=re.escape(before + after)):
                jax.block_until_ready(features(a))
            eager = "^" + re.escape(before) + r" = [-+0-9.e]+" + re.escape(after)
            with pytest.raises(ValueError, match=eager):
                sp.vibration_features(a, FS, ac_coupled=ac)


def test_psd_takes_a_traced_fs_and_the_features_say_theirs_must_be_concrete():
    """(Session 30.) A traced fs was refused as "fs must be a finite number > 0 Hz; got
    jax.Array…", blaming a valid value. psd's fs only scales the result: it runs traced.
    The features' fs and window_s set the window length: refused as traced, saying so."""
    x = jnp.asarray(np.sin(2 * np.pi * 10.0 * np.arange(2000) / 100.0))
    peaks = jax.vmap(lambda f: sp.psd(x, f, 200)[1].max())(jnp.array([100.0, 200.0]))
    np.testing.assert_allclose(peaks, [sp.psd(x, f, 200)[1].max() for f in (100.0, 200.0)],
                               rtol=1e-12)  # fmt: skip
    f, _ = jax.jit(lambda fs: sp.psd(x, fs, 200))(100.0)
    np.testing.assert_allclose(f[:3], [0.0, 0.5, 1.0])
    with pytest.raises(Exception, match=r"fs must be a finite number > 0 Hz"):
        jax.block_until_ready(jax.jit(lambda fs: sp.psd(x, fs, 200))(-1.0))
    a = _record(0.5, 9.80665)
    for name, call in (("fs", lambda v: sp.vibration_features(a, v, 1.0)),
                       ("window_s", lambda v: sp.vibration_features(a, FS, v))):  # fmt: skip
        with pytest.raises(ValueError, match=rf"^{name} must be a concrete number \[.*\] \(not "
                           r"traced by jit/vmap/grad\): with the other it sets the window "
                           r"length in samples"):  # fmt: skip
            jax.jit(call)(1.0)


# 4. ferraris with a traced latitude or Earth rate


def test_ferraris_names_a_traced_latitude_as_traced_not_as_out_of_range():
    truth = hg.imu.ImuCalibration.known(gyro_bias=np.array([0.01, -0.02, 0.005]))
    key = jax.random.key(0)
    data, sections = hg.imu.ferraris_session(truth, key, rate_hz=20.0, static_s=3.0)
    match = (r"^{} must be a concrete number: the Ferraris calibration and session run on the "
             r"host \(NumPy\), not inside jit, vmap or grad; got a traced value")  # fmt: skip
    with pytest.raises(ValueError, match=match.format("lat_deg")):
        jax.grad(lambda lat: hg.imu.ferraris(data, sections, lat_deg=lat).gyro_bias[0])(45.0)
    with pytest.raises(ValueError, match=match.format("earth_rate")):
        jax.grad(lambda r: hg.imu.ferraris(data, sections, earth_rate=r).gyro_bias[0])(7.29e-5)
    with pytest.raises(ValueError, match=match.format("lat_deg")):
        jax.jit(lambda lat: hg.imu.ferraris_session(truth, key, rate_hz=20.0, static_s=3.0,
                                                    lat_deg=lat)[0].gyro)(45.0)  # fmt: skip


# 5. gm_white_level


def test_gm_white_level_checks_sampling_and_traces_both():
    sigma, dt, ts = 1e-3, 0.01, np.array([0.0025, 0.005, 0.04])
    with pytest.raises(ValueError, match=r"sampling must be one of \['interval', 'point'\]; "
                       r"got 'points'"):  # fmt: skip
        gm_white_level(sigma, 0.005, dt, "points")
    x = dt / (2 * ts)  # point samples: σ²Δt coth(Δt/2T), ∂/∂T = σ²Δt²/(2T²) csch²(Δt/2T)
    want = {"point": (sigma**2 * dt / np.tanh(x), sigma**2 * dt**2 / (2 * ts**2) / np.sinh(x) ** 2),
            "interval": (2 * sigma**2 * ts, np.full(3, 2 * sigma**2))}  # fmt: skip
    for sampling, (level, slope) in want.items():
        f = lambda t, s=sampling: gm_white_level(sigma, t, dt, s)  # noqa: E731
        np.testing.assert_allclose(jax.vmap(f)(jnp.asarray(ts)), level, rtol=1e-12)
        np.testing.assert_allclose(jax.vmap(jax.grad(f))(jnp.asarray(ts)), slope, rtol=1e-12)
        assert isinstance(f(0.005), float)  # a number in, a number out (JSON, YAML)
