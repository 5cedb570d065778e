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
