"""`ImuModel.apply`'s Gauss–Markov and random-walk biases are exact interval means, for any
correlation time against the sample interval: their Monte Carlo moments against the
continuous processes' closed forms, written here in 50-digit decimals (no cancellation at
τ/Δt = 1e-3 or 1e6)."""

from decimal import Decimal, localcontext

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hrgjax.ins import sensors

DT, N, RUNS = 0.1, 12, 4000
SIGMA = 1e-4  # gyro Gauss–Markov σ [rad/s]
K = 1e-5  # accelerometer bias random walk [m/s²/√s]
RATIOS = (1e-3, 0.1, 1.0, 10.0, 1e3, 1e6)  # τ / Δt


def _gm_moments(tau, dt, k):
    """Exact moments of a stationary first-order Gauss–Markov x (σ, τ; E[x(s)x(t)] =
    σ²e^(−|t−s|/τ)) over intervals dt: the variance of one interval mean, of the difference
    of two neighbours', and of ∫x over k intervals [rad²]."""
    with localcontext() as c:
        c.prec = 50
        s2, tau, dt = Decimal(SIGMA) ** 2, Decimal(tau), Decimal(dt)
        r = dt / tau
        a = (-r).exp()
        v = s2 * 2 * (r - 1 + a) / (r * r)  # ∬ over one interval, / dt²
        c1 = s2 * ((1 - a) / r) ** 2  # neighbours' covariance
        big_r = k * r
        total = 2 * s2 * tau * tau * (big_r - 1 + (-big_r).exp())
        return float(v), float(2 * (v - c1)), float(total)


@pytest.fixture(scope="module")
def draws():
    """Per τ/Δt: (RUNS·3, N) interval-mean gyro biases of a GM-only gyro and accelerometer
    biases of a random-walk-only accelerometer."""
    z = jnp.zeros((N, 3))
    keys = jax.random.split(jax.random.key(11), RUNS)

    def biases(k, tau):
        imu = sensors.ImuModel(
            gyro_bias_instability=SIGMA, gyro_correlation_time=tau, accel_random_walk=K
        )
        return imu.apply(k, z, z, DT, return_bias=True)[2:]

    run = jax.jit(jax.vmap(biases, in_axes=(0, None)))  # τ a value: one program for all six
    out = {}
    for ratio in RATIOS:
        bg, ba = run(keys, ratio * DT)
        out[ratio] = tuple(np.moveaxis(np.asarray(b), 2, 1).reshape(-1, N) for b in (bg, ba))
    return out


@pytest.mark.parametrize("ratio", RATIOS)
def test_gauss_markov_interval_means_have_the_processes_moments(draws, ratio):
    b = draws[ratio][0]
    assert np.all(np.isfinite(b))
    v, v_diff, v_total = _gm_moments(ratio * DT, DT, 10)
    # 12 000 samples: a variance's relative standard error is 1.3 %; the old trapezoid was
    # 2.8× (τ = Δt/10) and 250× (Δt/1000) on the mean, 0.75× on the difference (τ ≫ Δt)
    np.testing.assert_allclose(np.var(b[:, 1]) / v, 1.0, atol=0.06)
    np.testing.assert_allclose(np.var(b[:, 2] - b[:, 1]) / v_diff, 1.0, atol=0.06)
    np.testing.assert_allclose(np.var(b[:, 1:11].sum(1) * DT) / v_total, 1.0, atol=0.06)


def test_random_walk_interval_means_carry_their_bridge(draws):
    b = draws[1.0][1]  # walk from 0: Var ∫₀ᵀ = K²T³/3, the first mean K²Δt/3 (trapezoid: /4)
    np.testing.assert_allclose(np.var(b[:, 0]) / (K**2 * DT / 3), 1.0, atol=0.06)
    np.testing.assert_allclose(np.var(b[:, 1] - b[:, 0]) / (2 * K**2 * DT / 3), 1.0, atol=0.06)
    np.testing.assert_allclose(np.var(b[:, :3].sum(1) * DT) / (K**2 * (3 * DT) ** 3 / 3), 1.0,
                               atol=0.06)  # fmt: skip


def test_bias_paths_are_linear_in_their_sigmas_and_differentiable_at_zero():
    z = jnp.zeros((N, 3))

    def total(s, k):
        imu = sensors.ImuModel(
            gyro_bias_instability=s, gyro_correlation_time=0.01, accel_random_walk=k
        )
        th, dv = imu.apply(jax.random.key(3), z, z, DT)
        return jnp.sum(th) + jnp.sum(dv)

    g = jax.grad(total, argnums=(0, 1))(0.0, 0.0)
    np.testing.assert_allclose(g[0] * SIGMA + g[1] * K, total(SIGMA, K), rtol=1e-12)


@pytest.mark.parametrize(
    "r", [1e-8, 1e-4, 0.01, 0.3, 0.5, 0.9, 0.999, 1.0, 1.001, 2.0, 10.0, 1e4, 1e8]
)
def test_gauss_markov_interval_coefficients_equal_80_digit_decimals(r):
    """`_gm_interval(r)` (r = Δt/τ) against its closed forms in 80-digit decimals, on both
    sides of its series/closed-form switch at r = 1 — the Monte Carlo above would not see a
    series cut short (a 4-term series is 71 % wrong in l22 at r = 0.9 and passes it)."""
    with localcontext() as c:
        c.prec = 80
        x = Decimal(r)
        a = (-x).exp()
        v11 = 1 - a * a  # the end value's innovation variance (unit σ)
        c12 = (1 - a) ** 2 / x  # its covariance with the mean's innovation
        v22 = 2 * (2 * x - 3 + 4 * a - a * a) / (2 * x * x)  # the mean's, given the start
        l11 = v11.sqrt()
        l21 = c12 / l11
        want = [a, (1 - a) / x, l11, l21, (v22 - l21 * l21).sqrt()]
    got = sensors._gm_interval(r)
    np.testing.assert_allclose(got, [float(w) for w in want], rtol=1e-13, atol=0)


_GM_INTERVAL = jax.jit(sensors._gm_interval)


@pytest.mark.parametrize("r", [1e-300, 1e-170, 1e-90, 1e170, 1e300, float("inf")])
def test_gauss_markov_interval_coefficients_stay_finite_at_extreme_ratios(r):
    """Any finite τ > 0 is a valid model: τ ≫ Δt leaves the bias constant over the interval
    (a = 1, b = 1, no innovation: r is taken ≥ 1e-80, 1e-40 of σ), τ ≪ Δt leaves no memory
    (a = b = 0, the end value a fresh draw, the mean's variance → 0). Eagerly and compiled
    (review of fa3b04e: compiled, XLA made c12/l11 one division whose denominator underflowed,
    0/0 below r ≈ 6e-206), and their derivatives too (NaN below r ≈ 1e-90 without the clip)."""
    for fn in (sensors._gm_interval, _GM_INTERVAL):
        a, b, l11, l21, l22 = (float(x) for x in fn(r))
        assert all(np.isfinite([a, b, l11, l21, l22]))
        if r < 1:
            np.testing.assert_allclose([a, b], 1.0, rtol=1e-12)
            assert l11 < 1e-39 and l22 < 1e-39
        else:
            assert a == 0.0 and b < 1e-160 and l11 == 1.0 and l22 < 1e-80
    jac = jax.jacfwd(_GM_INTERVAL)(r), jax.jacrev(sensors._gm_interval)(r)
    assert np.all(np.isfinite(np.asarray(jac)))


def test_the_correlation_time_is_a_value_one_program_for_any_tau_and_its_gradient():
    """τ is a leaf (it was a static field: a sweep over it compiled a program per value, and
    `vmap` or `grad` over it were refused): one program for every τ, `vmap` over τ equals the
    loop, the interval means' derivative in τ equals central differences, and a traced τ
    ≤ 0 is refused when the program runs, naming the field."""
    z = jnp.zeros((N, 3))

    def means(tau):
        imu = sensors.ImuModel(gyro_bias_instability=SIGMA, gyro_correlation_time=tau)
        return imu.apply(jax.random.key(5), z, z, DT, return_bias=True)[2]

    f = jax.jit(means)
    taus = jnp.array([0.05, 1.0, 300.0])  # r = Δt/τ across the series/closed-form switch
    loop = np.stack([f(t) for t in taus])
    assert f._cache_size() == 1
    np.testing.assert_allclose(jax.vmap(means)(taus), loop, rtol=1e-12, atol=1e-20)
    for tau in (0.05, 300.0):
        g = jax.grad(lambda t: jnp.sum(f(t)))(tau)
        h = 1e-6 * tau
        fd = (jnp.sum(f(tau + h)) - jnp.sum(f(tau - h))) / (2 * h)
        assert float(g) == pytest.approx(float(fd), rel=1e-5), tau
    with pytest.raises(Exception, match="ImuModel.gyro_correlation_time must be a finite time"):
        f(-1.0)
