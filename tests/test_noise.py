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


def test_noise_draws_compile_once_per_shape():
    """Audit: an eager `gauss_markov` or `rate_noise_angle` compiled its `lax.scan` on every
    call (≈ 80–160 ms each); a second call on new values of the same shapes compiles
    nothing, and the draw is the plain function's to round-off."""
    ts, noise = jnp.arange(0.0, 50.0, 0.5), hg.Noise(angle_random_walk=1e-6, bias_instability=1e-6)
    for k in (0, 1):  # the second round: new values, same shapes
        with CompileCounter() as c:
            gm = hg.noise.gauss_markov(jax.random.key(k), ts + k, 2.0 + k, 50.0)
            angle = hg.noise.rate_noise_angle(jax.random.key(k), ts + k, noise)
        assert k == 0 or c.compiles == 0, c.names
    plain = hg.noise.gauss_markov.__wrapped__(jax.random.key(1), ts + 1, 3.0, 50.0)
    np.testing.assert_allclose(gm, plain, rtol=1e-12, atol=1e-14)  # XLA may round by an ulp
    assert angle.shape == ts.shape and np.isfinite(angle).all()


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


def _gm_integral_second_moment(sigma, tc, t):
    """E[(∫₀ᵗ x dt)²] of a stationary first-order Gauss–Markov rate (σ, T_c)."""
    return 2.0 * sigma**2 * tc * (t - tc * (1.0 - np.exp(-t / tc)))


def test_gauss_markov_angle_has_the_continuous_allan_deviation_at_a_coarse_interval():
    """The Gauss–Markov rate's angle sampled every 10 s with T_c = 1 s: its Allan deviation at
    τ = 10 s and 100 s is the continuous process's, (2σ²T_c/τ)[1 − T_c/(2τ)(3 − 4e^{−τ/T_c} +
    e^{−2τ/T_c})] (the trapezoid of the samples read 2.1× at 100 s: white rate noise σ²Δt)."""
    sigma, tc, dt = 1e-5, 1.0, 10.0
    nz = hg.Noise(bias_instability=sigma, correlation_time=tc)
    ts = jnp.arange(201.0) * dt
    keys = jax.random.split(jax.random.key(0), 2000)
    theta = np.asarray(jax.vmap(lambda k: hg.noise.rate_noise_angle(k, ts, nz))(keys))
    for m in (1, 10):
        tau = m * dt
        d = theta[:, 2 * m :] - 2 * theta[:, m:-m] + theta[:, : -2 * m]
        adev = np.sqrt(np.mean(d**2) / (2 * tau**2))
        x = tau / tc
        truth = np.sqrt(2 * sigma**2 * tc / tau
                        * (1 - (3 - 4 * np.exp(-x) + np.exp(-2 * x)) / (2 * x)))  # fmt: skip
        assert adev / truth == pytest.approx(1.0, abs=0.04), (tau, adev / truth)


def test_gauss_markov_integral_over_irregular_intervals_has_the_exact_moments():
    """Monte Carlo over one record of intervals 0.05, 3 and 47 T_c: each interval's integral
    and the whole one have E[I²] = 2σ²T_c[t − T_c(1 − e^{−t/T_c})], and each integral's
    covariance with the rate at its start is σ²T_c(1 − e^{−Δt/T_c}) (the trapezoid gave
    E[I²] 15 % high at 3 T_c and 12× at 47 T_c)."""
    sigma, tc = 2.0, 1.0
    nz = hg.Noise(bias_instability=sigma, correlation_time=tc)
    ts = jnp.array([0.0, 0.05, 3.05, 50.05])
    dts = np.diff(np.asarray(ts))

    def one(key):
        x = hg.noise.gauss_markov(jax.random.split(key)[1], ts, sigma, tc)  # its own samples
        return hg.noise.rate_noise_angle(key, ts, nz), x

    theta, x = (np.asarray(a) for a in jax.vmap(one)(jax.random.split(jax.random.key(3), 100_000)))
    inc = np.diff(theta, axis=1)
    np.testing.assert_allclose(np.mean(inc**2, axis=0), _gm_integral_second_moment(sigma, tc, dts),
                               rtol=0.03)  # fmt: skip
    assert np.mean(theta[:, -1] ** 2) == pytest.approx(
        _gm_integral_second_moment(sigma, tc, 50.05), rel=0.03
    )
    np.testing.assert_allclose(np.mean(inc * x[:, :-1], axis=0),
                               sigma**2 * tc * -np.expm1(-dts / tc), rtol=0.03, atol=0.01)  # fmt: skip


def test_gauss_markov_bridge_is_exact_from_tiny_to_huge_intervals():
    """`gauss_markov_bridge`'s (a, s) at Δt/T_c from 1e-8 to 1e4, against 60-digit arithmetic:
    a(x_k + x_{k+1}) + s·w reproduces the exact second moment of the integral and its
    covariance with the rate at either end, to float64 precision (the variance by a series
    where Δt − 2T_c tanh(Δt/2T_c) cancels)."""
    from decimal import Decimal, localcontext

    sigma, tc = 1.0, 37.0
    dts = np.logspace(-8, 4, 121) * tc
    a, s = (np.asarray(v) for v in hg.noise.gauss_markov_bridge(jnp.asarray(dts), sigma, tc))
    with localcontext() as ctx:
        ctx.prec = 60
        big_t = Decimal(tc)
        for dt, a_k, s_k in zip(dts, a, s, strict=True):
            h = Decimal(float(dt))
            phi = (-h / big_t).exp()
            # E[I x_k] = a σ²(1 + φ) must be σ²T_c(1 − φ); E[I²] = 2a²σ²(1 + φ) + s²
            a_true = big_t * (1 - phi) / (1 + phi)
            second = 2 * big_t * (h - big_t * (1 - phi))
            s2_true = second - 2 * a_true**2 * (1 + phi)
            assert abs(Decimal(float(a_k)) / a_true - 1) < Decimal("4e-15"), dt
            assert abs(Decimal(float(s_k)) ** 2 / s2_true - 1) < Decimal("4e-15"), dt


def test_gauss_markov_angle_at_a_fine_interval_is_the_trapezoid_and_differentiable():
    """At Δt ≪ T_c (0.01 s, T_c = 1000 s) the angle is the trapezoid of the same samples to
    1e-4 of its rms over the record and the ARW draws are unchanged (results there do not move); on an
    irregular grid reaching Δt = 1e4 T_c it stays finite under jit, vmap and grad in σ and
    T_c, and the gradients agree with finite differences."""
    key = jax.random.key(4)
    nz = hg.Noise(angle_random_walk=1e-7, bias_instability=1e-5, correlation_time=1000.0)
    ts = jnp.arange(10_001.0) * 0.01
    got = np.asarray(hg.noise.rate_noise_angle(key, ts, nz))
    k_arw, k_gm = jax.random.split(key)
    dts = np.diff(np.asarray(ts))
    arw = 1e-7 * np.sqrt(dts) * np.asarray(jax.random.normal(k_arw, dts.shape))
    x = np.asarray(hg.noise.gauss_markov(k_gm, ts, 1e-5, 1000.0))
    trapezoid = np.concatenate([[0.0], np.cumsum(arw + 0.5 * (x[1:] + x[:-1]) * dts)])
    rms = np.sqrt(_gm_integral_second_moment(1e-5, 1000.0, 100.0))  # ≈ σ·100 s
    assert np.max(np.abs(got - trapezoid)) <= 1e-4 * rms
    white = hg.Noise(angle_random_walk=1e-7)
    np.testing.assert_allclose(hg.noise.rate_noise_angle(key, ts, white),
                               np.concatenate([[0.0], np.cumsum(arw)]), rtol=0, atol=1e-18)  # fmt: skip

    grid = jnp.array([0.0, 1e-8, 1e-3, 0.5, 2.5, 40.0, 1e4, 1e4 + 3.0])

    def loss(sigma, tc):
        n = hg.Noise(bias_instability=sigma, correlation_time=tc)
        return jnp.sum(hg.noise.rate_noise_angle(key, grid, n) ** 2)

    grads = jax.jit(jax.grad(loss, argnums=(0, 1)))(2.0, 1.0)
    assert np.all(np.isfinite(grads))
    eps = 1e-6
    for i, g in enumerate(grads):
        up = [2.0, 1.0]
        dn = [2.0, 1.0]
        up[i] += eps
        dn[i] -= eps
        fd = (loss(*up) - loss(*dn)) / (2 * eps)
        assert float(g) == pytest.approx(float(fd), rel=1e-5)
    batched = jax.vmap(jax.grad(loss, argnums=1), in_axes=(None, 0))(
        2.0, jnp.array([0.1, 1.0, 1e3])
    )
    assert np.all(np.isfinite(batched))
