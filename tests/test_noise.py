"""Noise and Allan deviations: NBS14 reference values, round trips through simulate."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter, resonator

import hrgjax as hg
from hrgjax.units import DEG_PER_H, DEG_PER_SQRT_H

NBS14 = np.array([892, 809, 823, 798, 671, 644, 883, 903, 677], dtype=float)


@pytest.mark.parametrize(
    "fn,m,expected",
    [
        (hg.adev, 1, 91.22945),
        (hg.adev, 2, 115.8082),
        (hg.oadev, 2, 85.95287),
        (hg.mdev, 2, 74.78849),
        (hg.hdev, 1, 70.80607),
        (hg.hdev, 2, 116.7980),
        (hg.totdev, 2, 93.90379),
    ],
)
def test_nbs14(fn, m, expected):
    assert float(fn(NBS14, m)) == pytest.approx(expected, rel=1e-4)
    # any array-like and any integer m: a list, a NumPy or a 0-d JAX integer (each deviation
    # is one compiled program with m static, behind the eager conversion)
    assert float(fn(NBS14.tolist(), np.int64(m))) == float(fn(NBS14, jnp.asarray(m)))


def test_allan_errors():
    with pytest.raises(ValueError, match="m"):
        hg.oadev(NBS14, 0)
    # a whole real number is the integer; anything else is refused naming m, not by JAX
    assert float(hg.oadev(NBS14, 2.0)) == float(hg.oadev(NBS14, 2))
    for bad in (2.5, [2], "2", float("nan")):
        with pytest.raises(ValueError, match="oadev: m must be a positive integer"):
            hg.oadev(NBS14, bad)
    with pytest.raises(ValueError, match="kind"):
        hg.allan_deviation(NBS14, 1.0, kind="fancy")
    # the sample interval and the samples, named (τ = −1, −2, … and NaN deviations before)
    for bad in (0.0, -1.0, np.nan):
        with pytest.raises(ValueError, match=r"^oadev: tau0 must be the sample interval"):
            hg.oadev(NBS14, 2, bad)
        with pytest.raises(ValueError, match=r"^allan_deviation: dt must be the sample"):
            hg.allan_deviation(NBS14, bad)
    with pytest.raises(ValueError, match=r"^mdev: y must be finite; found nan at index 3 "):
        hg.mdev(np.r_[NBS14[:3], np.nan, NBS14[3:]], 1)


@pytest.mark.parametrize("kind", ["adev", "oadev", "mdev", "hdev", "ohdev", "totdev"])
def test_allan_curve_equals_each_factor_and_compiles_once(kind):
    """The one-program curve (m a run-time value) equals the per-m definitions, and new
    factors of the same count compile nothing."""
    rng = np.random.default_rng(3)
    y = rng.normal(size=600) + 0.05 * np.cumsum(rng.normal(size=600))
    ms = [1, 3, 8, 21, 34]
    taus, dev = hg.allan_deviation(y, 0.5, ms=ms, kind=kind)
    each = [float(getattr(hg, kind)(y, m, 0.5)) for m in ms]
    np.testing.assert_allclose(dev, each, rtol=1e-12)
    np.testing.assert_allclose(taus, 0.5 * np.asarray(ms))
    other = [2, 5, 9, 17, 40]
    with CompileCounter() as c:
        hg.allan_deviation(y, 0.5, ms=other, kind=kind)
    assert c.compiles == 0, c.names


def _rate_from_record(rec):
    th = np.asarray(rec.wave_angle)
    return -np.diff(th) / np.diff(np.asarray(rec.t)) / 0.554


@pytest.fixture(scope="module")
def noisy_rate():
    def make(noise, key, duration=4000.0, dt=1.0):
        gyro = hg.Gyro(resonator(tau=1e3), control=hg.Control(ideal=True), noise=noise)
        rec = hg.simulate(gyro, hg.Profile.static(duration), key=key, dt_out=dt)
        return _rate_from_record(rec)

    return make


def test_arw_round_trip(noisy_rate):
    n = 0.05 * DEG_PER_SQRT_H
    rate = noisy_rate(hg.Noise(angle_random_walk=n), jax.random.key(5))
    taus, dev = hg.allan_deviation(rate, 1.0, ms=[1, 4, 16, 64])
    estimate = np.asarray(dev) * np.sqrt(np.asarray(taus))
    np.testing.assert_allclose(estimate, n, rtol=0.1)


def test_white_angle_noise_slope(noisy_rate):
    """White angle noise → ADEV ∝ τ⁻¹ (√3 Q/τ-type term)."""
    rate = noisy_rate(hg.Noise(angle_white=1e-5), jax.random.key(6))
    taus, dev = hg.allan_deviation(rate, 1.0, ms=[2, 8, 32, 128], kind="oadev")
    slope = np.polyfit(np.log(taus), np.log(dev), 1)[0]
    assert slope == pytest.approx(-1.0, abs=0.08)


def test_gauss_markov_variance_and_correlation():
    ts = jnp.arange(0.0, 20000.0, 1.0)
    x = np.asarray(hg.noise.gauss_markov(jax.random.key(2), ts, 2.0, 50.0))
    assert x.std() == pytest.approx(2.0, rel=0.1)
    lag = 50
    rho = np.corrcoef(x[:-lag], x[lag:])[0, 1]
    assert rho == pytest.approx(np.exp(-1.0), abs=0.1)


def test_noise_deterministic_for_key_and_needs_key():
    nz = hg.Noise(angle_white=1e-6, angle_random_walk=1e-6, run_bias=1.0 * DEG_PER_H)
    gyro = hg.Gyro(resonator(), control=hg.Control(ideal=True), noise=nz)
    prof = hg.Profile.static(10.0)
    a = hg.simulate(gyro, prof, key=jax.random.key(1)).wave_angle
    b = hg.simulate(gyro, prof, key=jax.random.key(1)).wave_angle
    c = hg.simulate(gyro, prof, key=jax.random.key(2)).wave_angle
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_sweep_shape_and_values():
    gyro = hg.Gyro(resonator(), control=hg.Control(ideal=True))  # ideal loops: a light compile

    def final_angle(temperature_c, rate_dps):
        prof = hg.Profile.constant_rate(rate_dps, 10.0, temperature_c)
        return hg.simulate(gyro, prof, dt_out=5.0).wave_angle[-1]

    temps, rates = jnp.array([-40.0, 20.0, 60.0]), jnp.array([0.1, 5.0])
    out = hg.sweep(final_angle, temperature_c=temps, rate_dps=rates)
    assert out.shape == (3, 2)
    assert float(out[1, 1]) == pytest.approx(float(final_angle(20.0, 5.0)), abs=1e-12)
    with pytest.raises(ValueError, match="temperature_c"):
        hg.sweep(final_angle, temperature_c=jnp.zeros((2, 2)), rate_dps=rates)
