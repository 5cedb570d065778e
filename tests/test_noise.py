"""Noise and Allan deviations: NBS14 reference values, round trips through simulate."""

import equinox as eqx
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
    # audit (paved path): complex or boolean samples were read as their real part or 0/1; a
    # 2-D, empty, NaN or text ms was flattened or failed inside JAX / int(); a list kind
    # was "unhashable type"
    with pytest.raises(TypeError, match=r"^oadev: y must be real rate samples"):
        hg.oadev(NBS14 + 1j, 1)
    with pytest.raises(TypeError, match=r"^allan_deviation: y must be real rate samples"):
        hg.allan_deviation(NBS14 > 800, 1.0)
    for bad in ([[1, 2], [4, 8]], [], "abc"):
        with pytest.raises((ValueError, TypeError), match=r"^allan_deviation: ms must be the av"):
            hg.allan_deviation(NBS14, 1.0, ms=bad)
    for bad in (np.nan, 2.5):  # named as allan_deviation's ms (was "oadev: m …")
        with pytest.raises(ValueError, match=rf"^allan_deviation: ms must be the av.*; got {bad}"):
            hg.allan_deviation(NBS14, 1.0, ms=[bad])
    with pytest.raises(ValueError, match=r"^kind must be one of"):
        hg.allan_deviation(NBS14, 1.0, kind=["oadev"])


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
    # keywords are bound as before (the jitted function took them), and `.lower` stays
    by_name = hg.noise.gauss_markov(jax.random.key(1), ts + 1, sigma=3.0, correlation_time=50.0)
    assert np.array_equal(by_name, gm)
    with pytest.raises(TypeError):
        hg.noise.gauss_markov(jax.random.key(1), ts, sigma=3.0, tau=50.0)
    assert hg.noise.rate_noise_angle.lower(jax.random.key(1), ts + 1, noise=noise) is not None
    assert angle.shape == ts.shape and np.isfinite(angle).all()


def test_noise_deterministic_for_key_and_needs_key():
    nz = hg.Noise(angle_white=1e-6, angle_random_walk=1e-6, run_bias=1.0 * DEG_PER_H)
    gyro = hg.Gyro(resonator(), control=hg.Control(ideal=True), noise=nz)
    prof = hg.Profile.static(10.0)
    a = hg.simulate(gyro, prof, key=jax.random.key(1)).wave_angle
    b = hg.simulate(gyro, prof, key=jax.random.key(1)).wave_angle
    c = hg.simulate(gyro, prof, key=jax.random.key(2)).wave_angle
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    # a window late in the run carries the switch-on bias's angle from the profile's start,
    # not from its first sample (it read b·(t − ts[0])): the full record's angles again
    biased = eqx.tree_at(lambda g: g.noise, gyro, hg.Noise(run_bias=1.0 * DEG_PER_H))
    whole = hg.simulate(biased, prof, key=jax.random.key(1), ts=jnp.array([0.0, 5.0, 10.0]))
    late = hg.simulate(biased, prof, key=jax.random.key(1), ts=jnp.array([5.0, 10.0]))
    np.testing.assert_allclose(late.wave_angle, whole.wave_angle[1:], rtol=1e-12, atol=1e-18)
    assert abs(float(late.wave_angle[0])) > 1e-8  # ≈ k_e b · 5 s, not 0


def test_a_switch_on_bias_reads_through_the_pickoffs_as_a_rate_bias_does():
    """Audit (s33): the rate noise's angle was added after the readout map, where a rate
    bias moves the wave and is read through the pickoffs' errors: a switch-on bias moved
    the grey box's cross_talk 0.86 σ (11 σ on a plan 4× longer), the same bias as
    `Gyro.rate_bias` nothing. Now it reads through `Readout.angle_slope` (dθ̂/dθ, exact:
    autodiff of the pickoffs' direction): a switch-on bias (σ 10 °/h) equals that rate bias on
    a wave turning 5 °/s through pickoff errors of 1 %, to 1e-9 rad (the old reading was
    off by the readout ripple on the bias's angle, up to 1.6e-6 rad)."""
    readout = hg.Readout(gain_mismatch=0.01, cross_talk=0.003, misalignment=0.002)
    theta = jnp.linspace(-3.0, 3.0, 7)
    (a, b), (c, d) = readout.matrix()
    direction = jax.vmap(jax.grad(lambda t: jnp.arctan2(c * jnp.cos(t) + d * jnp.sin(t),
                                                        a * jnp.cos(t) + b * jnp.sin(t))))  # fmt: skip
    np.testing.assert_allclose(readout.angle_slope(theta), direction(theta), rtol=1e-14)
    key, bias_key = jax.random.key(3), jax.random.key(5)
    base = hg.Gyro(resonator(), control=hg.Control(ideal=True), readout=readout)
    noise = hg.Noise(run_bias=10.0 * DEG_PER_H)
    noisy = eqx.tree_at(lambda g: g.noise, base, noise, is_leaf=lambda x: x is None)
    bias = float(hg.noise.draw_run_bias(bias_key, noise))  # the switch-on [rad/s]
    law = eqx.tree_at(lambda g: g.rate_bias, base, jnp.asarray(bias))
    prof = hg.Profile.constant_rate(5.0, 20.0, 20.0, 0.0)
    got = hg.simulate(noisy, prof, key=key, bias_key=bias_key, dt_out=0.5).wave_angle
    want = hg.simulate(law, prof, dt_out=0.5).wave_angle
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    assert 0.02 * 0.554 * abs(bias) * 20.0 > 1e-6  # the ripple's scale, 2g·k_e·b·t: 3.7e-6 rad


def test_rate_noise_from_a_start_before_the_first_sample_has_the_exact_moments():
    """`rate_noise_angle(…, start=0)` at ts = (50, 60) s: E[θ²] = N²t + 2σ²T_c[t − T_c(1 −
    e^{−t/T_c})] at each t, and E[θ(50)θ(60)] the same at 50 plus the Gauss–Markov integral's
    covariance with the next 10 s, σ²T_c²(1 − e^{−50/T_c})(1 − e^{−10/T_c}) (`simulate`'s
    noise counted from the profile's start; from the first sample, an output window at 50 s
    read 0 there); `start` = ts[0] is the draw without it, bit for bit."""
    n, sigma, tc = 1e-5, 1e-5, 30.0
    nz = hg.Noise(angle_random_walk=n, bias_instability=sigma, correlation_time=tc)
    ts = jnp.array([50.0, 60.0])
    draw = jax.jit(jax.vmap(lambda k: hg.noise.rate_noise_angle(k, ts, nz, 0.0)))
    theta = np.asarray(draw(jax.random.split(jax.random.key(8), 40_000)))
    want = [n**2 * t + _gm_integral_second_moment(sigma, tc, t) for t in (50.0, 60.0)]
    np.testing.assert_allclose(np.mean(theta**2, axis=0), want, rtol=0.03)
    cross = want[0] + sigma**2 * tc**2 * -np.expm1(-50.0 / tc) * -np.expm1(-10.0 / tc)
    assert np.mean(theta[:, 0] * theta[:, 1]) == pytest.approx(cross, rel=0.03)
    key = jax.random.key(2)
    np.testing.assert_array_equal(hg.noise.rate_noise_angle(key, ts, nz, 50.0),
                                  hg.noise.rate_noise_angle(key, ts, nz))  # fmt: skip
    with pytest.raises(ValueError, match=r"^rate_noise_angle: start must be <= ts\[0\] = 50 s"):
        hg.noise.rate_noise_angle(key, ts, nz, 55.0)


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
    sigma, tc = 2.0, 1.0  # a unit process (2 rad/s is no gyro's: `relaxed` takes it)
    with hg.plausible.relaxed(noise_bias_instability=(0.0, 10.0)):
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

    def loss(sigma, tc):  # σ = 2 rad/s: a unit process, no gyro's (`relaxed` takes it)
        with hg.plausible.relaxed(noise_bias_instability=(0.0, 10.0)):
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


def test_allan_statistics_refuse_input_off_the_paved_path():
    """Audit: each of these returned a number or failed in NumPy/Python — a 2-D τ grid
    flattened, `bias_correction="no"` read as True, NaN phase read as "no noise to identify",
    dmax 1.5 a TypeError, a negative deviation a negative interval, mismatched `dev`/`edf`
    broadcast or a NumPy error, B1/R(n) at n = 2.5 or m = 0, a text `terms` split into
    letters, `gauss_markov=1.0` a range() error, τ ≤ 0 read as τ₀, a complex record's real
    part resampled and an infinite sample taken as a gap. Every one is refused on the host
    before any work."""
    from hrgjax import allan

    y = np.random.default_rng(0).normal(size=64)
    x = np.cumsum(y)
    with pytest.raises(ValueError, match=r"^taus must be 'octave', 'decade', 'all' or τ values"):
        allan.deviation(y, 1.0, taus=[[1, 2], [4, 8]])
    with pytest.raises(TypeError, match=r"^taus must be 'octave'"):
        allan.deviation(y, 1.0, taus=["a"])
    with pytest.raises(TypeError, match=r"^bias_correction must be True or False"):
        allan.deviation(y, 1.0, "totdev", bias_correction="no")
    with pytest.raises(ValueError, match=r"^x must be finite; found nan at index 5"):
        allan.noise_id(np.r_[x[:5], np.nan, x[6:]], [1, 2])
    with pytest.raises(TypeError, match=r"^x must be real phase"):
        allan.noise_id(x + 1j, [1])
    for bad in (1.5, 0, "2"):
        with pytest.raises(ValueError, match=r"^dmax must be the highest difference order"):
            allan.noise_id(x, [1], bad)
    with pytest.raises(TypeError, match=r"^overlapping must be True or False"):
        allan.noise_id(x, [1], overlapping="no")
    with pytest.raises(ValueError, match=r"^n must be a whole number of averages"):
        allan.b1_expected(2.5, 1)
    with pytest.raises(ValueError, match=r"^m must be a whole averaging factor ≥ 1; got 0"):
        allan.rn_expected(0, 2)
    for bad in (-1.0, np.inf):
        with pytest.raises(
            ValueError, match=rf"^dev must be deviations >= 0 \(or NaN\); got {bad}"
        ):
            allan.confidence_interval(bad, 10.0)
    with pytest.raises(ValueError, match=r"^dev and edf must have shapes that broadcast"):
        allan.confidence_interval([1.0, 2.0, 3.0], [10.0, 20.0])
    # a NaN deviation (no estimate) is a NaN interval, and shapes broadcast, as before
    low, high = allan.confidence_interval([1.0, np.nan], [2.0, 3.0])
    assert low[0] == pytest.approx(0.737005, abs=1e-6) and np.isnan(low[1]) and np.isnan(high[1])
    low, high = allan.confidence_interval(np.ones((3, 1)), [2.0, 3.0, 4.0])
    assert low.shape == (3, 3) and low[0, 0] == pytest.approx(0.737005, abs=1e-6)
    assert allan.confidence_interval([], [])[0].size == 0  # was a np.vectorize error
    with pytest.raises(TypeError, match=r"^chi2_ppf: q must be a single real number"):
        allan.chi2_ppf("a", 2)
    with pytest.raises(ValueError, match=r"^terms must be a list of names among"):
        allan.identify_noise(y, 1.0, terms="angle_random_walk")
    with pytest.raises(ValueError, match=r"^gauss_markov must be 0, 1 or 2 terms; got 1.0"):
        allan.identify_noise(y, 1.0, gauss_markov=1.0)
    with pytest.raises(TypeError, match=r"^y must be real rate samples"):
        allan.identify_noise(y + 1j, 1.0)
    arw = {"value": 1.0, "low": 0.9, "high": 1.1, "unit": "rate unit·√s"}
    model = allan.CompositeNoise(terms={"angle_random_walk": arw}, unit="", rate_hz=1.0, n=64,
                                 ci=0.95, taus=np.ones(1), avar=np.ones(1),
                                 covariance=np.ones((1, 1)), chi2=0.0, dof=1, p_value=1.0)  # fmt: skip
    assert model.adev([4.0])[0] == pytest.approx(0.5)
    with pytest.raises(ValueError, match=r"^taus must be τ values > 0 \[s\]"):
        model.model_avar([-1.0])
    with pytest.raises(ValueError, match=r"^term_avar: name must be one of the model's terms"):
        model.term_avar("rate_ramp", [1.0])
    zero = dict.fromkeys([n for n, *_ in allan.NOISE_TERMS], 0.0)
    fit = allan.NoiseFit(value=zero, sigma=zero, low=zero, high=zero, chi2=0.0, dof=1)
    with pytest.raises(ValueError, match=r"^taus must be τ values > 0 \[s\]"):
        fit.adev([-5.0])
    t = np.arange(10.0)
    with pytest.raises(ValueError, match=r"^t and y must be 1-D of one length"):
        allan.to_uniform(np.c_[t, t], np.c_[t, t])
    with pytest.raises(TypeError, match=r"^y must be real samples"):
        allan.to_uniform(t, t + 1j)
    with pytest.raises(ValueError, match=r"^y has an infinite value at index 3"):
        allan.to_uniform(t, np.r_[t[:3], np.inf, t[4:]])


def test_noise_draws_and_pattern_noise_refuse_input_off_the_paved_path():
    """Audit: times running backwards drew an exploding "Gauss–Markov" process (NaN angles
    from rate_noise_angle), T_c ≤ 0 and σ < 0 drew silently, an int key or a non-Noise failed
    inside JAX; the pattern model's covariances took times backwards (a negative walk
    variance), a negative lag or block length, k = 1.5 as 2, k_e ≤ 0 (ZeroDivisionError, a
    negative noise), and its closed forms a negative dt (a negative variance) or Δ < 0."""
    from hrgjax import pattern_noise as pn

    key, ts = jax.random.key(0), jnp.arange(5.0)
    with pytest.raises(ValueError, match=r"^gauss_markov: ts must not decrease \[s\]; ts\[1\]"):
        hg.noise.gauss_markov(key, ts[::-1], 1.0, 10.0)
    with pytest.raises(ValueError, match=r"^gauss_markov: correlation_time must be one time > 0"):
        hg.noise.gauss_markov(key, ts, 1.0, 0.0)
    with pytest.raises(ValueError, match=r"^gauss_markov: sigma must be one standard deviation"):
        hg.noise.gauss_markov(key, ts, -1.0, 10.0)
    with pytest.raises(TypeError, match=r"^gauss_markov: key must be one JAX PRNG key"):
        hg.noise.gauss_markov(0, ts, 1.0, 10.0)
    noise = hg.Noise(angle_random_walk=1e-6)
    with pytest.raises(ValueError, match=r"^rate_noise_angle: ts must be finite; found nan"):
        hg.noise.rate_noise_angle(key, jnp.asarray([0.0, 1.0, np.nan]), noise)
    with pytest.raises(TypeError, match=r"^rate_noise_angle: noise must be an hrgjax.Noise"):
        hg.noise.rate_noise_angle(key, ts, 5)
    with pytest.raises(TypeError, match=r"^draw_run_bias: key must be one JAX PRNG key"):
        hg.noise.draw_run_bias(0, noise)
    with pytest.raises(ValueError, match=r"^gauss_markov_bridge: dts must be intervals >= 0"):
        hg.noise.gauss_markov_bridge(-jnp.ones(3), 1.0, 10.0)
    model = pn.NoiseModel(1e-6, 1e-7, 1e-7, 100.0)
    with pytest.raises(ValueError, match=r"^NoiseModel.angle_white must be a finite number"):
        pn.NoiseModel(True)
    with pytest.raises(ValueError, match=r"^slope_sigma: t must be finite sample times"):
        model.slope_sigma([3.0, 2.0, 1.0])
    with pytest.raises(ValueError, match=r"^slope_sigma: t must hold at least 2 distinct"):
        model.slope_sigma([1.0])
    with pytest.raises(ValueError, match=r"^angle_covariance: t must be 1-D"):
        model.angle_covariance([[0.0, 1.0], [2.0, 3.0]])
    with pytest.raises(ValueError, match=r"^increment_covariance: delta must be a block length"):
        model.increment_covariance(-1.0, 3)
    with pytest.raises(ValueError, match=r"^increment_covariance: k must be a whole number"):
        model.increment_covariance(1.0, 1.5)
    with pytest.raises(ValueError, match=r"^d2_variance: tau must be lags >= 0"):
        model.d2_variance(-1.0)
    assert model.d2_variance(0.0) == pytest.approx(6 * 1e-12, rel=1e-12)  # τ = 0: 6σ_w², as before
    with pytest.raises(ValueError, match=r"^report: k_e must be the angular gain, > 0"):
        model.report(0.0)
    with pytest.raises(ValueError, match=r"^from_gyro: k_e must be the angular gain"):
        pn.NoiseModel.from_gyro(noise, -1.0)
    with pytest.raises(TypeError, match=r"^noise must be an hrgjax.Noise"):
        pn.NoiseModel.from_gyro(5, 1.0)
    with pytest.raises(TypeError, match=r"^data must be an hrgjax.MeasuredData"):
        pn.NoiseModel.estimate(5)
    with pytest.raises(ValueError, match=r"^slope_variance: dt must be a sample interval > 0"):
        pn.slope_variance(1e-6, 1e-6, 10, -1.0)
    with pytest.raises(ValueError, match=r"^gauss_markov_mean_variance: duration must be > 0"):
        pn.gauss_markov_mean_variance(1.0, 10.0, 0.0)
    with pytest.raises(ValueError, match=r"^gm_structure: tc must be a correlation time > 0"):
        pn.gm_structure(1.0, -10.0)
    with pytest.raises(ValueError, match=r"^gm_structure: delta must be a time difference >= 0"):
        pn.gm_structure(-1.0, 10.0)


def test_gauss_markov_bridge_is_one_program():
    """Compile once: the bridge ran op by op (13 compiles on a new length or input type);
    one program per length now, and a whole-number correlation time is its float (the same
    program and values)."""
    dts, dts2 = jnp.linspace(0.0, 3.0, 17), jnp.linspace(0.5, 900.0, 17)
    with CompileCounter() as c:
        hg.noise.gauss_markov_bridge(dts, 1e-6, 100.0)
    assert c.compiles <= 1, c.names
    with CompileCounter() as c:
        a2, s2 = hg.noise.gauss_markov_bridge(dts2, 2e-6, 50)
    assert c.compiles == 0, c.names
    b2, t2 = hg.noise.gauss_markov_bridge(dts2, 2e-6, 50.0)
    np.testing.assert_array_equal(a2, b2)
    np.testing.assert_array_equal(s2, t2)
