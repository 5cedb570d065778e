"""Ferraris calibration on a bench that turns with the Earth (audit of 2026-11-30): each face
pair's difference (w⁺ − w⁻)/2g takes the Earth's rate into G — Ω sin φ / g on the diagonal
and Ω cos φ / g across it, 5.26e-6 rad/s per m/s² at 45° — and a tactical session's σ(G),
3e-8, missed it by z ≈ 170. `lat_deg` removes the vertical part exactly; the horizontal
part (the faces' headings) and an unknown latitude enter the covariance."""

import jax
import numpy as np
import pytest

import hrgjax as hg
from hrgjax.imu import ImuCalibration
from hrgjax.units import EARTH_RATE

G = 9.81


@pytest.fixture(scope="module")
def truth():
    rng = np.random.default_rng(1)
    return ImuCalibration.known(
        accel_matrix=np.eye(3) + rng.normal(0, 0.01, (3, 3)), accel_bias=[0.1, -0.05, 0.2],
        gyro_matrix=np.eye(3) + rng.normal(0, 0.01, (3, 3)), gyro_bias=[0.009, -0.005, 0.002],
        gyro_g_sensitivity=rng.normal(0, 1e-4, (3, 3)),
    )  # fmt: skip


@pytest.mark.parametrize("lat_deg", [45.0, -30.0])
def test_noise_free_g_sensitivity_is_off_by_the_analytic_earth_rate(truth, lat_deg):
    """Noise-free session (`ferraris_session`'s faces: the next axis east, so axis i + 2
    points north on i₊ and south on i₋). The pair difference holds M_g (Ω sin φ e_i +
    Ω cos φ e_{i+2}); with `lat_deg` only the horizontal part is left in G, as predicted
    (to 1e-10: the old method's error, Ω sin φ / g on the diagonal, is 5.2e-6)."""
    data, sections = hg.imu.ferraris_session(truth, jax.random.key(0), gyro_noise=0.0,
                                             accel_noise=0.0, lat_deg=lat_deg)  # fmt: skip
    lat = np.deg2rad(lat_deg)
    m_g = np.asarray(truth.gyro_matrix)
    horizontal = EARTH_RATE * np.cos(lat) * np.roll(np.eye(3), 2, axis=0)  # column i: e_{i+2}
    vertical = EARTH_RATE * np.sin(lat) * np.eye(3)
    known = hg.imu.ferraris(data, sections, lat_deg=lat_deg)
    err = np.asarray(known.gyro_g_sensitivity - truth.gyro_g_sensitivity)
    # to second order: M_g, which removes Ω sin φ / g M_g, reads the turns' horizontal rate
    np.testing.assert_allclose(err, m_g @ horizontal / G, rtol=0, atol=2e-10)
    plain = hg.imu.ferraris(data, sections, earth_rate=0.0)  # the textbook method
    err = np.asarray(plain.gyro_g_sensitivity - truth.gyro_g_sensitivity)
    np.testing.assert_allclose(err, m_g @ (vertical + horizontal) / G, rtol=0, atol=1e-13)


@pytest.fixture(scope="module")
def tactical(truth):
    """A tactical-grade session at 45° (1e-5 rad/s and 1e-3 m/s² per sample)."""
    return [hg.imu.ferraris_session(truth, jax.random.key(k), gyro_noise=1e-5, accel_noise=1e-3,
                                    lat_deg=45.0) for k in range(3)]  # fmt: skip


def _z(cal, truth):
    return (np.asarray(cal.vector()) - np.asarray(truth.vector())) / np.sqrt(
        np.diag(np.asarray(cal.covariance))
    )


def test_tactical_session_sigma_holds_the_earth_rate(truth, tactical):
    """The method's σ(G) is 3e-8 against a 5.26e-6 bias (z ≈ 170, the audit's 165–168);
    with the latitude, or without it, every parameter is within 3σ, and G's σ without the
    latitude holds an Earth's rate anywhere on the globe (Ω/√3 g on the diagonal)."""
    g_at = slice(24, 33)
    for data, sections in tactical:
        plain = hg.imu.ferraris(data, sections, earth_rate=0.0)
        assert np.max(np.abs(_z(plain, truth)[g_at])) > 100.0
        assert plain.sigma_source == "white noise and bias drift"
        for kw in ({"lat_deg": 45.0}, {}):
            cal = hg.imu.ferraris(data, sections, **kw)
            z = _z(cal, truth)
            assert np.all(np.abs(z) < 3.0), (kw, np.round(z, 2))
            assert cal.sigma_source == "white noise and bias drift and the Earth's rate"
        # unknown latitude: G's diagonal σ is the vertical rate's, Ω/√3 · M_g,ii / g
        np.testing.assert_allclose(np.diag(np.asarray(cal.gyro_g_sensitivity_std)),
                                   EARTH_RATE / np.sqrt(3) / G * np.diag(cal.gyro_matrix),
                                   rtol=1e-3)  # fmt: skip
        np.testing.assert_array_equal(cal.gyro_matrix, plain.gyro_matrix)  # only σ change


@pytest.mark.parametrize("kw", [{"lat_deg": 91.0}, {"lat_deg": "north"}, {"earth_rate": -1.0},
                                {"earth_rate": float("nan")}])  # fmt: skip
def test_bad_latitude_or_rate_is_refused(truth, tactical, kw):
    data, sections = tactical[0]
    with pytest.raises(ValueError, match=next(iter(kw))):
        hg.imu.ferraris(data, sections, **kw)
    if "lat_deg" in kw:
        with pytest.raises(ValueError, match="lat_deg"):
            hg.imu.ferraris_session(truth, jax.random.key(0), **kw)


def test_an_earth_rate_in_another_unit_is_refused_naming_it(tactical):
    """(Audit of session 30.) `earth_rate=15.04` (°/h for rad/s) was taken: G came out as
    −1.09 on its diagonal with a σ of 3.7 (truth ~1e-4). Rates beyond
    `hrgjax.plausible.RANGES["earth_rate_radps"]` (0 … 1e-4 rad/s) are refused, naming the
    unit the value is the Earth's rate in."""
    data, sections = tactical[0]
    for rate, unit in ((15.04, r"°/h \(×hrgjax.units.DEG_PER_H\)"),
                       (15.04 / 3600.0, r"°/s \(×hrgjax.units.DEG\)"),
                       (EARTH_RATE * 3600.0, r"rad/h \(÷3600\)")):  # fmt: skip
        with pytest.raises(ValueError, match=r"^earth_rate \[rad/s\] = [0-9.e-]+ is outside "
                           r"the plausible range 0 … 0.0001 rad/s \(hrgjax.plausible.relaxed\("
                           r"earth_rate_radps=…\) widens it\); [0-9.e-]+ is the "
                           rf"Earth's rate in {unit}$"):  # fmt: skip
            hg.imu.ferraris(data, sections, earth_rate=rate)
    with pytest.raises(ValueError, match=r"= 0.001 is outside the plausible range .*widens it\)$"):
        hg.imu.ferraris(data, sections, earth_rate=1e-3)  # no unit it matches: no guess


# Free headings (review of 2026-12-01). On face i± the gyros see the Earth's horizontal rate
# as a body vector h± ⟂ e_i, |h±| = Ω cos φ: the pair difference takes (h⁺ − h⁻)/2 into G,
# the pair sum (h⁺ + h⁻)/2 into b_g, which therefore reads M_g Σ h / 6 over the six faces.
# The gyros' bias-drift intensity q read that as drift (bias_walk 1.2e-5 rad/s/√s, ~150× a
# tactical IMU's, σ(b_g) 10 °/h for a model σ of Ω cos φ / 3 = 3.5 °/h at 45°).
FACE_KEYS = ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a")
TUMBLE_NORTH = {"x_p": 90.0, "x_a": 90.0, "z_a": 180.0}  # y north on the x and z faces


def _horizontal_in_body(headings_deg, lat_deg):
    """{face: h (3,)}: the Earth's horizontal rate [rad/s] in the body on each face, from
    `face_attitude` turned about the vertical (world x east, y north, z up)."""
    north = EARTH_RATE * np.cos(np.deg2rad(lat_deg)) * np.array([0.0, 1.0, 0.0])
    out = {}
    for k in FACE_KEYS:
        p = np.deg2rad(headings_deg.get(k, 0.0))
        turn = np.array([[np.cos(p), -np.sin(p), 0.0], [np.sin(p), np.cos(p), 0.0], [0, 0, 1]])
        out[k] = (turn @ hg.imu.face_attitude(k)).T @ north
    return out


@pytest.mark.parametrize("layout", ["random", "tumble"])
def test_free_headings_put_the_horizontal_rate_where_the_pairs_take_it(truth, layout):
    """Noise-free, lat 60°: b_g is off by M_g Σh/6 and G's column i by M_g (h⁺ − h⁻)/2g
    (to second order, as above), computed from the faces' attitudes; q is 0 (round-off;
    it read the pair sums' Earth rate as drift: 2e-6 rad/s/√s)."""
    rng = np.random.default_rng(7)
    headings = ({k: float(rng.uniform(0, 360)) for k in FACE_KEYS} if layout == "random"
                else TUMBLE_NORTH)  # fmt: skip
    data, sections = hg.imu.ferraris_session(truth, jax.random.key(0), gyro_noise=0.0,
                                             accel_noise=0.0, lat_deg=60.0,
                                             face_headings_deg=headings)  # fmt: skip
    h = _horizontal_in_body(headings, 60.0)
    m_g = np.asarray(truth.gyro_matrix)
    cal = hg.imu.ferraris(data, sections, lat_deg=60.0)
    bias_err = np.asarray(cal.gyro_bias - truth.gyro_bias)
    np.testing.assert_allclose(bias_err, m_g @ sum(h.values()) / 6, rtol=0, atol=1e-12)
    if layout == "tumble":  # b_g's y takes 2Ω cos φ / 3, the rest nothing
        np.testing.assert_allclose(bias_err, [0, 2 * EARTH_RATE * 0.5 / 3, 0] @ m_g.T,
                                   rtol=0, atol=1e-12)  # fmt: skip
    diff = np.stack([h[f"{a}_p"] - h[f"{a}_a"] for a in "xyz"], axis=1) / 2
    err = np.asarray(cal.gyro_g_sensitivity - truth.gyro_g_sensitivity)
    np.testing.assert_allclose(err, m_g @ diff / G, rtol=0, atol=2e-10)
    assert np.all(np.asarray(cal.bias_walk) < 1e-12), cal.bias_walk  # round-off alone


@pytest.fixture(scope="module")
def tactical_tumble(truth):
    """A tactical session at 45° tumbled about north (b_g's y takes 2Ω cos φ / 3)."""
    return hg.imu.ferraris_session(truth, jax.random.key(5), gyro_noise=1e-5, accel_noise=1e-3,
                                   lat_deg=45.0, face_headings_deg=TUMBLE_NORTH)  # fmt: skip


def test_the_earth_rate_in_the_pair_sums_is_not_read_as_bias_drift(truth, tactical_tumble):
    """The gyros' q from within the faces: a tactical IMU with no drift at all reads a
    bias_walk below 1e-6 rad/s/√s (1.2e-5 before, its pair sums holding 2Ω cos φ), and
    σ(b_g) is the Earth's term, Ω cos φ / 3 per axis (3.5 °/h; 10 °/h before), so the
    tumble's b_g y is at z = 2, its worst case."""
    data, sections = tactical_tumble
    cal = hg.imu.ferraris(data, sections, lat_deg=45.0)
    assert 0.0 < float(cal.bias_walk[0]) < 1e-6, cal.bias_walk
    earth = EARTH_RATE * np.cos(np.deg2rad(45.0)) / 3
    sd = np.asarray(cal.gyro_bias_std) / np.linalg.norm(np.asarray(truth.gyro_matrix), axis=1)
    np.testing.assert_allclose(sd, earth, rtol=0.05)
    z = _z(cal, truth)[21:24]
    np.testing.assert_allclose(np.abs(z), [0, 2, 0], atol=0.05)


@pytest.mark.parametrize("bad", [{"w_p": 1.0}, [0.0] * 5, "north", [0, 0, 0, 0, 0, float("inf")]])
def test_bad_face_headings_are_refused(truth, bad):
    with pytest.raises(ValueError, match="face_headings_deg"):
        hg.imu.ferraris_session(truth, jax.random.key(0), face_headings_deg=bad)
