"""Ferraris calibration: what the data cannot show must not pass as a tight result (audit of
2026-11-30). A gyro clipped during the turns (M_g read 15 % low with σ 4e-5, z ≈ −3000) is
refused naming the channel; an accelerometer clipped on a face likewise; a turn-angle
uncertainty (`turn_deg_std`) enters M_g's σ as the analytic M_g,ii · σ_φ / φ."""

import jax
import numpy as np
import pytest

import hrgjax as hg
from hrgjax.imu import ImuCalibration, ImuData

RANGE_DPS = 250.0  # the default range of common MEMS gyros (MPU-6050, ICM-20602)


def _session(**kw):
    return hg.imu.ferraris_session(ImuCalibration.known(), jax.random.key(0), **kw)


def _clip_gyro(data, dps):
    lim = np.deg2rad(dps)
    return ImuData(data.time, np.clip(data.gyro, -lim, lim), data.accel, rate_hz=data.rate_hz)


@pytest.mark.parametrize("turn_s", [2.0, 2.5])  # (1 − cos) 360° turns peak at 720/T: 360, 288 °/s
def test_gyro_clipped_in_the_turns_is_refused_naming_the_channel(turn_s):
    data, sections = _session(turn_s=turn_s)
    assert np.rad2deg(np.abs(data.gyro).max()) == pytest.approx(720.0 / turn_s, rel=1e-3)
    clipped = _clip_gyro(data, RANGE_DPS)
    with pytest.raises(
        ValueError, match=r"turn 'x_rot': gyro x saturates.*250 °/s.*turn more slowly"
    ):
        hg.imu.ferraris(clipped, sections)
    # the sections found in the data: refused too (2 s: detect_sections names the clipping)
    with pytest.raises(ValueError, match=r"gyro x saturates"):
        hg.imu.ferraris(clipped)
    # an explicit range refuses a sample at it, even one not on a flat top
    with pytest.raises(ValueError, match=r"turn 'x_rot': gyro x reads .* at its range ±250"):
        hg.imu.ferraris(clipped, sections, gyro_range_dps=RANGE_DPS)


def test_unclipped_sessions_are_unchanged():
    """Genuine data reaches its extreme once: the same session unclipped, noise-free, or
    quantised like a 16-bit part (±2000 °/s, ±4 g) with and without noise, calibrates as
    before, M_g within 5σ of the truth (1)."""
    data, sections = _session(turn_s=2.0)
    cal = hg.imu.ferraris(data, sections, earth_rate=0.0)  # simulated without it
    z = (np.diag(np.asarray(cal.gyro_matrix)) - 1.0) / np.diag(np.asarray(cal.gyro_matrix_std))
    assert np.all(np.abs(z) < 5.0), z
    assert cal.sigma_source == "white noise and bias drift"
    assert hg.imu.ferraris(data, sections, gyro_range_dps=400.0).gyro_matrix == pytest.approx(
        cal.gyro_matrix, abs=0.0
    )
    lg, la = np.deg2rad(2000.0 / 32768), 4 * 9.81 / 32768
    for noise in (1e-3, 0.0):
        d, s = _session(gyro_noise=noise, accel_noise=10 * noise)
        q = ImuData(d.time, np.round(d.gyro / lg) * lg, np.round(d.accel / la) * la, rate_hz=100.0)
        got = np.diag(np.asarray(hg.imu.ferraris(q, s).gyro_matrix))
        assert got == pytest.approx(1.0, abs=2e-3)


def test_accelerometer_clipped_on_a_face_is_refused():
    data, sections = _session()
    lim = 0.98 * 9.81  # a range below 1 g: the x_p face is pinned
    clipped = ImuData(data.time, data.gyro, np.minimum(data.accel, lim), rate_hz=data.rate_hz)
    with pytest.raises(ValueError, match=r"face 'x_p': accel x reads"):
        hg.imu.ferraris(clipped, sections, accel_range_g=0.98)


def test_quantised_faces_are_not_taken_for_clipping():
    """A face logged to 1 mg sits on its top level for runs of samples: a flat top at 1 g is
    the quantisation, not a clip (no part's range is below 2 g), and was refused (a
    reviewer's finding); a given range is the only test then."""
    data, sections = _session(accel_noise=0.003)
    lsb = 0.001 * 9.81
    acc = np.round((np.asarray(data.accel) + np.array([0.002, -0.003, 0.0049])) / lsb) * lsb
    quantised = ImuData(data.time, data.gyro, acc, rate_hz=data.rate_hz)
    for kw in ({}, {"accel_range_g": 16.0}):
        cal = hg.imu.ferraris(quantised, sections, **kw)
        np.testing.assert_allclose(np.diag(np.asarray(cal.gyro_matrix)), 1.0, atol=1e-3)


def test_turn_angle_uncertainty_enters_the_gyro_matrix_sigma():
    """Turns of 357° declared 360°: M_g,ii − 1 = 357/360 − 1 exactly (the method cannot
    see it). With turn_deg_std = 1° its σ is √(σ_noise² + (M_g,ii/360)²) and z ≈ −3."""
    data, sections = _session(turn_deg=357.0)
    plain = hg.imu.ferraris(data, sections, turn_deg=360.0)
    cal = hg.imu.ferraris(data, sections, turn_deg=360.0, turn_deg_std=1.0)
    d = np.diag(np.asarray(cal.gyro_matrix))
    assert d - 1.0 == pytest.approx(
        357.0 / 360.0 - 1.0, abs=3 * np.diag(plain.gyro_matrix_std).max()
    )
    s0, s1 = np.diag(np.asarray(plain.gyro_matrix_std)), np.diag(np.asarray(cal.gyro_matrix_std))
    assert np.all(s0 < 1e-4)  # the noise alone: z ≈ −130 without the turn's σ
    assert s1 == pytest.approx(np.sqrt(s0**2 + (d / 360.0) ** 2), rel=1e-9)
    z = (d - 1.0) / s1
    assert z == pytest.approx((357.0 / 360.0 - 1.0) / (d / 360.0), abs=0.05)  # ≈ −3.0
    assert cal.sigma_source.endswith("and turn angles")
    # only M_g's columns gain variance; the rest of the covariance is untouched
    extra = np.asarray(cal.covariance) - np.asarray(plain.covariance)
    mg = np.zeros(33, bool)
    mg[12:21] = True
    assert np.all(extra[~mg] == 0.0) and np.all(extra[:, ~mg] == 0.0)
    # per-turn values: a (3,) std touches only its own column
    one = hg.imu.ferraris(data, sections, turn_deg=360.0, turn_deg_std=(0.0, 0.0, 2.0))
    s = np.asarray(one.gyro_matrix_std)
    assert s[:, :2] == pytest.approx(np.asarray(plain.gyro_matrix_std)[:, :2], rel=1e-12)
    assert s[2, 2] == pytest.approx(np.hypot(s0[2], 2.0 * d[2] / 360.0), rel=1e-9)


def test_turn_angle_monte_carlo_coverage():
    """Turn angles drawn N(360°, 1°) per turn, declared 360° with turn_deg_std = 1: z of
    M_g's diagonal is standard normal (24 values; |z| < 3.5 and RMS within 0.6–1.5)."""
    rng = np.random.default_rng(7)
    zs = []
    for k in range(8):
        angle = float(360.0 + rng.normal())
        data, sections = hg.imu.ferraris_session(
            ImuCalibration.known(), jax.random.key(k), turn_deg=angle, static_s=3.0
        )
        cal = hg.imu.ferraris(data, sections, turn_deg=360.0, turn_deg_std=1.0)
        zs.append((np.diag(np.asarray(cal.gyro_matrix)) - 1.0) / np.diag(cal.gyro_matrix_std))
    zs = np.concatenate(zs)
    assert np.all(np.abs(zs) < 3.5) and 0.6 < np.sqrt(np.mean(zs**2)) < 1.5, zs


@pytest.mark.parametrize(
    "kw", [{"turn_deg_std": -1.0}, {"turn_deg_std": (1.0, 2.0)}, {"gyro_range_dps": 0.0},
           {"accel_range_g": float("nan")}],
)  # fmt: skip
def test_bad_options_are_refused(kw):
    data, sections = _session()
    with pytest.raises(ValueError, match=next(iter(kw))):
        hg.imu.ferraris(data, sections, **kw)


def test_a_turntables_constant_rate_is_not_taken_for_clipping():
    """Turns at a constant rate with short ramps sit flat at the gyro's extreme for
    hundreds of samples, and were refused as clipped (a reviewer's finding); they integrate
    the whole turn, so they are not. The same session clipped 10 % below the plateau loses
    angle and is refused."""
    data, sections = _session(gyro_noise=0.0, accel_noise=0.0, move_s=6.0)
    gy = np.array(data.gyro)
    for ax, key in enumerate(("x_rot", "y_rot", "z_rot")):
        a, b = sections[key][0]
        rows = a + np.flatnonzero(np.abs(gy[a:b, ax]) > 1e-6)
        ramp = np.linspace(0.0, 1.0, 12)[1:-1]
        prof = np.r_[ramp, np.ones(rows.size - 2 * ramp.size), ramp[::-1]]
        gy[rows, ax] = prof * gy[rows, ax].sum() / prof.sum()  # the same turn, flat-topped
    table = ImuData(data.time, gy, data.accel, rate_hz=data.rate_hz)
    cal = hg.imu.ferraris(table, sections)
    np.testing.assert_allclose(np.diag(np.asarray(cal.gyro_matrix)), 1.0, atol=1e-9)
    lim = 0.9 * np.abs(gy).max()
    with pytest.raises(ValueError, match=r"^turn 'x_rot': gyro x saturates"):
        hg.imu.ferraris(ImuData(data.time, np.clip(gy, -lim, lim), data.accel,
                                rate_hz=data.rate_hz), sections)  # fmt: skip
