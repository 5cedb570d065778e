"""The FOG vibration pipeline past its domain (audit 2026-11).

1. `heading_limit_deg` was the linear δψ = −ε_E/(ω_ie cos φ) + (∇_E/g) tan φ everywhere:
   5 °/h east at 45° gave −26.94° (exact −25.18°), at 80° −109.7° (exact −62.4°), at the
   pole −6.1e14°. Now the exact stationary equilibrium (the TRIAD of the biased means), with
   latitudes beyond ±89° refused.
2. `compensate` took features along the trained axis only: 10 Hz 1 g along x read (0, 0) =
   rest along z, all windows in range, the error passed untouched. Now a window vibrating
   more than 8° off that axis is out of range, with a warning naming both directions.
3. `vibration_features` near DC or Nyquist: 0.5 Hz at a 1-s window read 1.12 Hz 0.36 g,
   in range, silently. Now NaN (out of range) with an `EdgeToneWarning`."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hrgjax.fog import compensation as cp
from hrgjax.fog import vibration as vb
from hrgjax.fog.spectrum import vibration_features
from hrgjax.ins.constants import OMEGA_IE, WGS84
from hrgjax.units import DEG_PER_H

G0 = 9.80665


def _dcm(roll, pitch, heading):
    """Body-to-NED matrix from (roll, pitch, heading) [°], ZYX (NumPy, written here)."""
    r, p, h = np.radians([roll, pitch, heading])
    cz, sz, cy, sy, cx, sx = np.cos(h), np.sin(h), np.cos(p), np.sin(p), np.cos(r), np.sin(r)
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    return rz @ ry @ rx


def _triad_heading_error(eps_b, nab_b, c_bn, lat):
    """Independent TRIAD: down = −f̃/|f̃|, east ∥ down × ω̃, north = east × down (NED);
    heading atan2(C[1,0], C[0,0]) of the estimate minus the truth [°], wrapped."""
    g = float(WGS84.gravity(jnp.asarray(lat), jnp.asarray(0.0)))
    f = c_bn.T @ np.array([0.0, 0.0, -g]) + nab_b
    w = c_bn.T @ (OMEGA_IE * np.array([np.cos(lat), 0.0, -np.sin(lat)])) + eps_b
    d = -f / np.linalg.norm(f)
    e = np.cross(d, w)
    e /= np.linalg.norm(e)
    c_hat = np.stack([np.cross(e, d), e, d])  # rows: N, E, D in body axes
    dpsi = np.degrees(np.arctan2(c_hat[1, 0], c_hat[0, 0]) - np.arctan2(c_bn[1, 0], c_bn[0, 0]))
    return (dpsi + 180.0) % 360.0 - 180.0


def test_heading_limit_is_the_exact_stationary_equilibrium():
    level = _dcm(0.0, 0.0, 30.0)
    for eps_dph, lat_deg, exact in ((5.0, 45.0, -25.1790), (5.0, 80.0, -62.4187)):
        eps = level.T @ np.array([0.0, eps_dph * DEG_PER_H, 0.0])
        lat = np.radians(lat_deg)
        got = cp.heading_limit_deg(eps, np.zeros(3), level, lat)
        truth = -np.degrees(np.arctan2(eps_dph * DEG_PER_H, OMEGA_IE * np.cos(lat)))
        assert truth == pytest.approx(exact, abs=1e-4)
        assert got == pytest.approx(truth, abs=1e-9), (eps_dph, lat_deg)
    # tilted, every bias component, against the TRIAD written above
    c = _dcm(5.0, -10.0, 30.0)
    eps = np.array([0.5, 2.0, -1.0]) * DEG_PER_H
    nab = np.array([1e-3, -2e-3, 5e-4])
    lat = np.radians(60.0)
    want = _triad_heading_error(eps, nab, c, lat)
    assert abs(want) > 10.0
    assert cp.heading_limit_deg(eps, nab, c, lat) == pytest.approx(want, abs=1e-9)
    # small errors: PHYSICS.md §12's linear form, to δψ²/3 (δψ = 1.94° here: 0.04 %)
    eps = level.T @ np.array([0.0, 0.36 * DEG_PER_H, 0.0])
    nab = level.T @ np.array([0.0, 1e-3, 0.0])
    lat = np.radians(45.0)
    g = float(WGS84.gravity(jnp.asarray(lat), jnp.asarray(0.0)))
    linear = np.degrees(-0.36 * DEG_PER_H / (OMEGA_IE * np.cos(lat)) + 1e-3 / g * np.tan(lat))
    got = cp.heading_limit_deg(eps, nab, level, lat)
    assert got == pytest.approx(linear, rel=np.radians(linear) ** 2 / 3 + 1e-5)
    # no north near a pole: refused as `align` refuses it
    for lat in (np.radians(89.5), np.pi / 2, -np.pi / 2):
        with pytest.raises(ValueError, match=r"^lat must be within ±89° \(MAX_LAT_DEG\)"):
            cp.heading_limit_deg(eps, nab, level, lat)
    assert np.isfinite(cp.heading_limit_deg(eps, nab, level, np.radians(89.0)))


@pytest.fixture(scope="module")
def imu():
    return vb.default_imu()


def _comp(window_s, f_range=(5.0, 40.0)):
    """An untrained z-axis compensator as `fit` leaves it (only the range rules matter)."""
    return cp.VibrationCompensator("elman", key=jax.random.key(4), window_s=window_s,
                                   axis=(0, 0, 1), feature_range=(f_range, (0.25, 1.5)))  # fmt: skip


def _record(imu, freq, axis, fs=100.0, duration=20.0):
    sch = vb.VibrationSchedule.constant(freq, 1.0, duration, axis=axis)
    return vb.simulate(imu, sch, fs=fs, key=jax.random.key(6))


def test_vibration_off_the_trained_axis_is_out_of_range_and_named(imu):
    comp = _comp(2.0)
    for axis, off in (((0, 0, 1), False), ((0, 0.1, 1), False), ((1, 0, 0), True),
                      ((1, 1, 0), True), ((0, 0.3, 1), True)):  # fmt: skip
        rec = _record(imu, 10.0, axis)
        if off:  # 90°, 90°, 16.7° from z
            with pytest.warns(UserWarning, match=r"10 of 10 windows vibrate off the trained "
                              r"axis \(0, 0, 1\) — window 0 along"):  # fmt: skip
                out = cp.compensate(comp, imu, rec)
        else:  # 0°, 5.7°
            out = cp.compensate(comp, imu, rec)
        assert out.n_out_of_range == (10 if off else 0), axis
        assert np.all(np.asarray(out.prediction)[~np.asarray(out.in_range)] == 0.0)
    # the direction found is the table's, whatever the analysis axis
    from hrgjax.fog.spectrum import vibration_direction

    d = np.asarray(vibration_direction(vb.to_body(imu.accel, rec.accel), rec.fs, 2.0))
    u = np.array([0.0, 0.3, 1.0]) / np.hypot(0.3, 1.0)
    np.testing.assert_allclose(d, np.broadcast_to(u, d.shape), atol=1e-3)


def _tone(freq, fs=100.0, n=400, amp_g=1.0):
    t = np.arange(n) / fs
    a = np.zeros((n, 3))
    a[:, 2] = -G0 + amp_g * G0 * np.sin(2 * np.pi * freq * t + 0.3)
    return a


def test_a_tone_at_the_spectrum_edges_is_not_measured_and_is_counted(imu):
    # 1-s windows at 100 Hz: resolution 1 Hz, Nyquist bin 50; measurable peak bins 3..48
    for freq, ok in ((0.5, False), (1.7, False), (3.0, True), (48.0, True), (49.0, False),
                     (49.9, False)):  # fmt: skip
        if ok:
            f = np.asarray(vibration_features(_tone(freq), 100.0, 1.0, (0, 0, 1.0)))
            np.testing.assert_allclose(f, np.broadcast_to([freq, 1.0], f.shape), rtol=3e-3)
            continue
        with pytest.warns(UserWarning, match=r"4 of 4 tone\(s\) peak within 2 bins \(resolution "
                          r"1/window_s = 1 Hz\) of DC or 1 of Nyquist \(50 Hz\).*longer window"):  # fmt: skip
            f = np.asarray(vibration_features(_tone(freq), 100.0, 1.0, (0, 0, 1.0)))
        assert np.isnan(f).all(), (freq, f)  # was 1.12 Hz 0.36 g at 0.5 Hz, silently
    # rest stays rest (its noise peak may lie anywhere)
    noise = np.random.default_rng(0).normal(size=(4000, 3)) * 0.02  # 2e-3 g
    rest = np.asarray(vibration_features(_tone(10.0, n=4000, amp_g=0.0) + noise, 100.0, 1.0))
    assert rest.shape == (40, 2) and np.all(rest == 0.0)
    # compensate counts them out of range, with extrapolate too; the output stays finite
    comp, rec = _comp(1.0, (0.1, 40.0)), _record(imu, 0.5, (0, 0, 1), duration=10.0)
    for extrapolate in (False, True):
        with pytest.warns(UserWarning, match="of DC or 1 of Nyquist"):
            out = cp.compensate(comp, imu, rec, extrapolate=extrapolate)
        assert out.n_out_of_range == 10 and np.isfinite(np.asarray(out.gyro)).all()
    with pytest.raises(ValueError, match=r"^conditions: \(0.5 Hz, 1 g\) peaks within 2 bins"):
        cp.training_set(imu, [(0.5, 1.0)], key=jax.random.key(1), fs=50.0, window_s=1.0,
                        lead_s=2.0, on_s=4.0, off_s=2.0)  # fmt: skip


# Review of the commit above (2026-12): five more holes, each test failing on its code.


def test_a_weak_low_tone_at_an_edge_reads_not_measurable_not_rest(imu):
    # 0.13 g at 0.5 Hz in 1-s windows peaks at bin 1, where the lobe without DC read 0.043 g
    # < min_amp_g 0.05: rest in every window, silently. The lobe with its DC bin (the
    # window's whole AC power for a tone) reads ≥ 0.414·0.13 = 0.054 g over all phases.
    from hrgjax.fog.spectrum import EdgeToneWarning, vibration_direction

    a = _tone(0.5, amp_g=0.13)
    with pytest.warns(EdgeToneWarning, match=r"4 of 4 tone\(s\)") as caught:
        f = np.asarray(vibration_features(a, 100.0, 1.0, (0, 0, 1.0)))
    assert np.isnan(f).all(), f
    assert caught[0].filename == __file__  # the user's line
    d = np.asarray(vibration_direction(a, 100.0, 1.0))
    np.testing.assert_allclose(np.abs(d), np.broadcast_to([0, 0, 1.0], d.shape), atol=1e-9)
    # raised inside compensate it points at the user's call too (it named compensation.py)
    comp, rec = _comp(1.0, (0.1, 40.0)), _record(imu, 0.5, (0, 0, 1), duration=10.0)
    with pytest.warns(EdgeToneWarning) as caught:
        out = cp.compensate(comp, imu, rec)
    assert [w.filename for w in caught] == [__file__] and out.n_out_of_range == 10


def test_broadband_rest_has_no_direction_and_is_not_off_axis(imu):
    # isotropic noise of 0.08–0.1 g per axis summed over three axes crossed min_amp_g in the
    # direction test while the features along z read rest: windows counted off the trained
    # axis, warned, prediction forced to zero. Noise has no direction (λ₁/trace 0.5–0.76);
    # a tone is rank one (λ₁/trace ≈ 1).
    from hrgjax.fog.spectrum import vibration_direction

    comp = _comp(2.0)
    rest = vb.simulate(imu, vb.VibrationSchedule.constant(0.0, 0.0, 20.0), fs=100.0,
                       key=jax.random.key(6))  # fmt: skip
    rng = np.random.default_rng(0)
    for sigma in (0.08, 0.1):
        noisy = eqx.tree_at(lambda r: r.accel, rest, rest.accel + rng.normal(size=(2000, 3))
                            * sigma * G0)  # fmt: skip
        body = vb.to_body(imu.accel, noisy.accel)
        assert np.all(np.asarray(vibration_direction(body, 100.0, 2.0)) == 0.0), sigma
        out = cp.compensate(comp, imu, noisy)  # no off-axis warning (an error here)
        feats = vibration_features(body, 100.0, 2.0, (0, 0, 1.0))
        assert out.n_out_of_range == int(np.sum(~np.asarray(comp.in_range(feats)))), sigma
    # a weak tone along x in the same noise floor keeps its direction: off, 90° from z
    from hrgjax.fog.spectrum import off_axis

    t = np.arange(2000) / 100.0
    x = rest.accel + rng.normal(size=(2000, 3)) * 0.01 * G0
    x = x.at[:, 0].add(0.06 * G0 * np.sin(2 * np.pi * 10.0 * t))
    off, d, angle = off_axis(vb.to_body(imu.accel, x), 100.0, (0, 0, 1.0), 2.0)
    assert np.asarray(off).all() and np.allclose(np.asarray(angle), 90.0, atol=5.0)


def test_windows_too_short_to_measure_anything_are_refused():
    # 8 or 9 samples leave no bin between the 2 at DC and the 1 at Nyquist: every tone NaN,
    # the warning "measurable from 31.25 to 31.25 Hz". 10 leave bin 3.
    from hrgjax.fog.spectrum import EdgeToneWarning, tone

    for m in (8, 9):
        with pytest.raises(ValueError, match=rf"^window_s·fs must be >= 10 samples \(a shorter "
                           rf"window leaves no bin .*; got {m} \("):  # fmt: skip
            vibration_features(_tone(30.0, n=10 * m), 100.0, m / 100.0, (0, 0, 1.0))
        with pytest.raises(ValueError, match=r"^nperseg must be >= 10 samples"):
            tone(np.sin(np.arange(4 * m)), 100.0, nperseg=m)
    f = np.asarray(vibration_features(_tone(30.0, n=100), 100.0, 0.1, (0, 0, 1.0)))
    np.testing.assert_allclose(f, np.broadcast_to([30.0, 1.0], f.shape), rtol=1e-2)
    # an odd window has no Nyquist bin: 11 samples measure bins 2.5–3.5 = 22.7–31.8 Hz (it
    # said up to fs/2 − 1.5 df = 36.4 Hz)
    with pytest.warns(EdgeToneWarning, match=r"Measurable from about 22.73 to 31.82 Hz"):
        vibration_features(_tone(45.0, n=110), 100.0, 0.11, (0, 0, 1.0))
    # a NaN or zero axis, or min_amp_g NaN, read every window (0, 0), at rest; a negative
    # min_amp_g read noise as vibration; window_s NaN, fs inf or text raised raw errors
    rec = _tone(30.0, n=100)
    for axis in ((np.nan, 0.0, 1.0), (0.0, 0.0, 0.0)):
        with pytest.raises(ValueError, match=r"^axis must be a non-zero finite 3-vector"):
            vibration_features(rec, 100.0, 0.1, axis)
    for amp in (np.nan, -0.1):
        with pytest.raises(ValueError, match=r"^min_amp_g must be a finite number >= 0 \[g\]"):
            vibration_features(rec, 100.0, 0.1, (0, 0, 1.0), min_amp_g=amp)
    with pytest.raises(ValueError, match=r"^window_s must be a finite number > 0 s; got nan"):
        vibration_features(rec, 100.0, np.nan, (0, 0, 1.0))
    with pytest.raises(ValueError, match=r"^fs must be a finite number > 0 Hz; got inf"):
        vibration_features(rec, np.inf, 0.1, (0, 0, 1.0))
    with pytest.raises(TypeError, match=r"^fs must be a finite number > 0 Hz; got 'a'"):
        tone(np.sin(np.arange(64.0)), "a")
    # a negative standard error gave a negative half-width
    from hrgjax.fog.misalignment import half_width

    for bad in (-1.0, np.inf):
        with pytest.raises(
            ValueError, match=rf"^std must be standard errors >= 0 \(or NaN\); got {bad}"
        ):
            half_width(bad, 7)
    # a NaN σ (an estimate without one) is a NaN half-width, as before the check
    hw = half_width(np.array([np.nan, 1.0]), 14)
    assert np.isnan(hw[0]) and hw[1] == pytest.approx(2.228139, abs=1e-6)
    # a schedule sampled at fs <= 0 gave empty arrays, a NaN lead time was dropped, a
    # segment length of 10.5 samples was cut to 10, a 1-D record raised an IndexError
    from hrgjax.fog.spectrum import psd

    sch = vb.VibrationSchedule.constant(30.0, 1.0, 1.0)
    assert sch.samples(10.0)[0].shape == (10,)
    for fs in (0.0, -10.0):
        with pytest.raises(ValueError, match=r"^VibrationSchedule.samples: fs must be > 0"):
            sch.samples(fs)
    for lead in (np.nan, -1.0):
        with pytest.raises(ValueError, match=r"^VibrationSchedule.on_off: lead_s must be"):
            vb.VibrationSchedule.on_off([(30.0, 1.0)], 1.0, 1.0, lead_s=lead)
    with pytest.raises(ValueError, match=r"^nperseg must be a whole number of samples"):
        psd(np.sin(np.arange(64.0)), 100.0, nperseg=10.5)
    with pytest.raises(ValueError, match=r"^window_means: x must be \(\.\.\., N, c\)"):
        vb.window_means(np.zeros(100), 100.0, 0.1)
    with pytest.raises(ValueError, match=r"^window_means: fs and window_s must be > 0"):
        vb.window_means(np.zeros((100, 3)), 100.0, -0.1)


def test_study_reports_an_unmeasurable_scenario_as_such():
    # study.run reported NaN features as 0.0 Hz / 0.000 g (PSD peak), which reads as rest
    from hrgjax.fog import study

    nan, rest = np.full((5, 2), np.nan), np.zeros((5, 2))
    assert study.scenario_features(nan) == {"freq_hz": None, "amp_g": None,
                                            "windows_not_measurable": 5}  # fmt: skip
    assert study.scenario_features(rest) == {"freq_hz": 0.0, "amp_g": 0.0,
                                             "windows_not_measurable": 0}  # fmt: skip
    mixed = np.array([[10.0, 1.0], [np.nan, np.nan], [12.0, 0.5], [0.0, 0.0]])
    assert study.scenario_features(mixed) == {"freq_hz": 11.0, "amp_g": 0.75,
                                              "windows_not_measurable": 1}  # fmt: skip
    result = {"scenario": "custom", "features": study.scenario_features(nan), "epochs": 1,
              "heading_error_deg": {}, "tilt_error_deg": {}, "prediction_rmse": {},
              "train_s": {}, "heading_limit_deg": {"remaining_drift": 0.0, "raw": 0.0}}  # fmt: skip
    assert "vibration not measurable" in study.table(result).splitlines()[0]


@pytest.mark.parametrize(
    ("fn", "calib", "x", "kind", "match"),
    [
        ("to_body", "gyro", np.ones((4, 2)), ValueError,
         r"^to_body: s must be sensor-axis values of shape \(\.\.\., 3\); got shape \(4, 2\)"),
        ("to_body", "accel", np.ones((4, 4)), ValueError, r"^to_body: s must be .*\(4, 4\)"),
        ("to_sensor", "gyro", np.ones((4, 2)), ValueError,
         r"^to_sensor: b must be body-frame values of shape \(\.\.\., 3\); got shape \(4, 2\)"),
        ("to_sensor", "gyro", np.ones(4), ValueError, r"^to_sensor: b must be .*got shape \(4,\)"),
        ("to_body", "gyro", "abc", TypeError, r"^to_body: s must be .*; got str 'abc'"),
        ("to_body", "imu", np.ones((4, 3)), TypeError,
         r"^to_body: calib must be a TriadCalibration \(e\.g\. imu\.gyro or imu\.accel\); "
         r"got FogImu"),
        ("to_sensor", None, np.ones(3), TypeError, r"^to_sensor: calib must be a "
         r"TriadCalibration .*; got NoneType"),
    ],
)  # fmt: skip
def test_triad_transforms_refuse_a_wrong_last_axis_or_calibration(imu, fn, calib, x, kind,
                                                                   match):  # fmt: skip
    """Audit: a (n, 2) or (n, 4) array raised JAX's dot_general error, a FogImu in place of
    its gyro's calibration an AttributeError; now one line naming the function and field."""
    c = {"gyro": imu.gyro, "accel": imu.accel, "imu": imu, None: None}[calib]
    with pytest.raises(kind, match=match) as err:
        getattr(vb, fn)(c, x)
    assert "\n" not in str(err.value)


def test_heading_limit_refuses_a_c_bn_that_is_not_a_rotation_and_wrong_shapes():
    """(Audit of session 30.) 2·C read −0.847° (the truth −1.708°), a sheared C −19.1°, a
    zero matrix NaN; an eps_body of shape (2,) or c_bn (2, 2) raised JAX broadcasting
    errors. A rotation in float32 (round-off ~1e-7) and vmap over latitude still run."""
    c = _dcm(0.0, 0.0, 30.0)
    eps, nab, lat = np.array([0.0, 0.36, 0.0]) * DEG_PER_H, np.zeros(3), np.radians(45.0)
    ok = cp.heading_limit_deg(eps, nab, c, lat)
    assert ok == pytest.approx(-1.70796, abs=1e-4)
    shear = np.zeros((3, 3))
    shear[0, 1] = 0.3
    for bad in (2.0 * c, c + shear, np.zeros((3, 3)), c @ np.diag([1.0, 1.0, -1.0]),
                np.full((3, 3), np.nan)):  # fmt: skip
        with pytest.raises(ValueError, match=r"^c_bn must be a rotation matrix, the body-to-NED "
                           r"direction cosines \(CᵀC = I within 1e-06, det = \+1\); got "
                           r"max\|CᵀC − I\| = "):  # fmt: skip
            cp.heading_limit_deg(eps, nab, bad, lat)
    assert cp.heading_limit_deg(eps, nab, c.astype(np.float32), lat) == pytest.approx(ok, abs=1e-4)
    for args, match in (
        ((np.zeros(2), nab, c, lat), r"^eps_body must have shape \(3,\), .*; got \(2,\)"),
        ((np.zeros((3, 1)), nab, c, lat), r"^eps_body must have shape \(3,\), .*; got \(3, 1\)"),
        ((eps, np.zeros(4), c, lat), r"^nabla_body must have shape \(3,\)"),
        ((eps, nab, np.eye(2), lat), r"^c_bn must have shape \(3, 3\), the body-to-NED .*; got "
         r"\(2, 2\)"),
        ((eps, nab, c, np.radians([10.0, 45.0])), r"^lat must have shape \(\), one latitude "
         r"\[rad\] \(several: jax.vmap over them\); got \(2,\)"),
    ):  # fmt: skip
        with pytest.raises(ValueError, match=match):
            cp.heading_limit_deg(*args)
    with pytest.raises(TypeError, match=r"^c_bn must be the body-to-NED direction cosine matrix"):
        cp.heading_limit_deg(eps, nab, "eye", lat)
    lats = np.radians([10.0, 45.0])
    got = jax.vmap(lambda p: cp.heading_limit_deg(eps, nab, c, p))(jnp.asarray(lats))
    np.testing.assert_allclose(got, [cp.heading_limit_deg(eps, nab, c, p) for p in lats],
                               rtol=1e-12)  # fmt: skip


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("arw", -1e-7, r"^FogImu\.arw \[rad/√s\] = -1e-07 is outside the plausible range 0 … "),
        ("arw", np.nan, r"^FogImu\.arw \[rad/√s\] must be finite; got nan"),
        ("vrw", 1.0, r"^FogImu\.vrw \[m/s/√s\] = 1 is outside .*µg/√Hz"),
        ("gyro", 30.0, r"^FogImu\.gyro\.bias \[rad/s\] = 30 at index 0 .*°/s → ×hrgjax"),
        ("accel", 9.81, r"^FogImu\.accel\.bias \[m/s²\] = 9\.81 at index 0 is outside"),
    ],
)  # fmt: skip
def test_fog_imu_refuses_impossible_noise_and_biases(imu, field, value, match):
    """(Audit of session 33.) A negative or NaN noise density, a gyro bias of 30 rad/s (°/s
    typed as rad/s) or an accelerometer bias of 1 g built a FogImu that `simulate` ran;
    now one line with the unit hint, as `ImuModel` refuses them."""
    parts = {"gyro": imu.gyro, "accel": imu.accel, "vibration": imu.vibration,
             "arw": imu.arw, "vrw": imu.vrw}  # fmt: skip
    if field in ("gyro", "accel"):
        parts[field] = eqx.tree_at(lambda t: t.bias, parts[field], jnp.array([value, 0.0, 0.0]))
    else:
        parts[field] = jnp.asarray(value)
    with pytest.raises(ValueError, match=match) as err:
        vb.FogImu(**parts)
    assert "\n" not in str(err.value)
    vb.FogImu(imu.gyro, imu.accel, imu.vibration, imu.arw, imu.vrw)  # the default builds


def test_calibrated_names_a_dwell_or_latitude_it_cannot_use(imu):
    """(Audit of session 33.) `dwell_s` of 0 or −1 read "b and s must be finite" (its noise
    1/√dwell_s, with a RuntimeWarning); `lat_deg=4000` read "lat = 69.8132 rad … the
    latitude is in radians here (degrees? …)", for a latitude given in degrees."""
    from hrgjax.fog import study

    for kw, match in (
        ({"dwell_s": 0.0}, r"^dwell_s must be > 0 s \(the time per position\); got 0$"),
        ({"dwell_s": -1.0}, r"^dwell_s must be > 0 s .*; got -1$"),
        ({"lat_deg": 4000.0}, r"^lat_deg must be the table's latitude in degrees, -90 … 90; "
         r"got 4000$"),
        ({"lat_deg": float("nan")}, r"^lat_deg must be finite \[°\]; got nan$"),
    ):  # fmt: skip
        with pytest.raises(ValueError, match=match):
            study.calibrated(imu, jax.random.key(1), **kw)
