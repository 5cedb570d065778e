"""One pattern-angle noise model (issue 45): `hrgjax.pattern_noise.NoiseModel` is the model
the discovery re-exports and the bench design converts a gyro's noise with; its closed forms
agree with its general second moments, and the design's JAX forms are built from them."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hrgjax.discovery
import hrgjax.discovery.noise
from hrgjax import pattern_noise as pn
from hrgjax.calibration import design as d
from hrgjax.presets import tvg3_like

ARW, WHITE = 3.2e-7, 4.8e-6  # the default gyro's pattern-angle N [rad/√s] and σ_w [rad]


def test_the_discovery_reexports_the_one_model():
    assert hrgjax.discovery.NoiseModel is pn.NoiseModel
    assert hrgjax.discovery.noise.NoiseModel is pn.NoiseModel
    assert hrgjax.discovery.noise.GM_TIMES is pn.GM_TIMES
    assert hrgjax.discovery.noise.MIN_STRETCH == pn.MIN_STRETCH
    assert hrgjax.discovery.noise.TEMPERATURE_TOLERANCE_C == pn.TEMPERATURE_TOLERANCE_C


def test_the_design_noise_is_the_model_of_the_gyro():
    """`pattern_arw`, `pattern_gauss_markov`, `pattern_angle_white` are the fields of
    `NoiseModel.from_gyro(noise, k_e)` — the discovery's conversion of a known gyro."""
    g = tvg3_like()
    model = pn.NoiseModel.from_gyro(g.noise, float(d.nominal_values(g)[0]))  # k_e
    assert d.pattern_arw() == model.angle_random_walk
    assert d.pattern_gauss_markov() == (model.gm_sigma, model.gm_time)
    assert d.pattern_angle_white() == model.angle_white
    assert d.pattern_arw(g) == model.angle_random_walk


@pytest.mark.parametrize("samples, dt", [(3, 0.5), (20, 0.5), (61, 1.0), (301, 0.25)])
def test_slope_variance_is_slope_sigma_of_equally_spaced_samples(samples, dt):
    """The closed form of the white + walk least-squares slope variance of n equally spaced
    samples is the model's general `slope_sigma`² (wᵀ C w) — exactly, to rounding — and the
    design's `window_density`² / length is it."""
    t = 7.0 + dt * np.arange(samples)
    for white, arw in [(WHITE, ARW), (WHITE, 0.0), (0.0, ARW)]:
        model = pn.NoiseModel(white, arw)
        closed = pn.slope_variance(white, arw, samples, dt)
        assert isinstance(closed, float)
        assert closed == pytest.approx(model.slope_sigma(t) ** 2, rel=1e-12)
        length = samples * dt
        density = d.window_density(arw, white, float(samples), dt, length)
        assert float(density) ** 2 / length == pytest.approx(closed, rel=1e-14)


@pytest.mark.parametrize("duration, tau", [(1e-3, 600.0), (20.0, 600.0), (600.0, 600.0),
                                           (3600.0, 100.0)])  # fmt: skip
def test_gauss_markov_mean_variance_is_the_covariance_of_the_model(duration, tau):
    """The variance of a Gauss–Markov rate's mean over D is the model's angle covariance at
    (D, D) / D², and the design's `gauss_markov_discount` is (N²/D) / (N²/D + it)."""
    sigma = 8e-9
    model = pn.NoiseModel(0.0, gm_sigma=sigma, gm_time=tau)
    v = model.gauss_markov_mean_variance(duration)
    assert v == pn.gauss_markov_mean_variance(sigma, tau, duration)
    assert v == pytest.approx(model.angle_covariance([0.0, duration])[1, 1] / duration**2,
                              rel=1e-6 if duration < 1 else 1e-12)  # fmt: skip
    white = ARW**2 / duration
    share = d.gauss_markov_discount(jnp.asarray(duration), ARW, sigma, tau)
    assert float(share) == pytest.approx(white / (white + v), rel=1e-13)


def test_closed_forms_work_on_numpy_and_traced_jax():
    """NumPy in, NumPy out; traced JAX (`jit`, `grad`) in, JAX out, the same numbers."""
    args = (WHITE, ARW, 20.0, 0.5)
    ref = pn.slope_variance(*args)
    jitted = jax.jit(pn.slope_variance)(*(jnp.asarray(a) for a in args))
    assert float(jitted) == pytest.approx(ref, rel=1e-14)
    assert isinstance(pn.gauss_markov_mean_variance(8e-9, 600.0, 20.0), float)
    assert isinstance(pn.gauss_markov_mean_factor(np.array([0.1, 1.0])), np.ndarray)
    gm = jax.jit(pn.gauss_markov_mean_variance)(8e-9, 600.0, jnp.asarray(20.0))
    assert isinstance(gm, jax.Array)
    assert float(gm) == pytest.approx(pn.gauss_markov_mean_variance(8e-9, 600.0, 20.0), rel=1e-14)
    grad = jax.grad(pn.gauss_markov_mean_variance, argnums=2)(8e-9, 600.0, jnp.asarray(20.0))
    h = 1e-3
    fd = (pn.gauss_markov_mean_variance(8e-9, 600.0, 20.0 + h)
          - pn.gauss_markov_mean_variance(8e-9, 600.0, 20.0 - h)) / (2 * h)  # fmt: skip
    assert float(grad) == pytest.approx(fd, rel=1e-6)


def test_design_forms_keep_their_numbers():
    """`window_density` and `gauss_markov_discount` give the numbers of their former inline
    expressions bit for bit (design criteria unchanged)."""
    n, dt, length = jnp.asarray([20.0, 2401.0]), 0.5, jnp.asarray([10.0, 1200.0])
    m = n * (n**2 - 1.0)
    var = 6.0 * (n**2 + 1.0) / (5.0 * m) * ARW**2 / dt + 12.0 * WHITE**2 / (dt**2 * m)
    assert np.array_equal(d.window_density(ARW, WHITE, n, dt, length), jnp.sqrt(var * length))
    dur, sigma, tau = jnp.asarray([10.0, 1200.0]), 8e-9, 600.0
    x = dur / tau
    excess = 2.0 * sigma**2 * tau / ARW**2 * (1.0 + jnp.expm1(-x) / x)
    assert np.array_equal(d.gauss_markov_discount(dur, ARW, sigma, tau), 1.0 / (1.0 + excess))


def _static_log(seed, *, gap_s=None, rate_jitter_dps=0.0, thermometer_c=0.0, runs=12, n=600):
    """Static runs (0.5-s samples, 300 s) whose angle is a known white + walk noise
    (σ_w 5e-6 rad, N 1e-6 rad/√s) on a large drift (~1e-4 rad/s, a fresh one per run); a
    sample dropout over `gap_s` = (start, stop) [s] of each run, table-rate readback jitter
    and thermometer noise as asked."""
    rng = np.random.default_rng(seed)
    cols = {k: [] for k in ("time_s", "run", "temperature_c", "table_rate_dps", "wave_angle_deg")}
    for r in range(runs):
        t = np.arange(n) * 0.5
        walk = np.r_[0.0, np.cumsum(rng.normal(0.0, 1e-6 * np.sqrt(0.5), n - 1))]
        theta = rng.uniform(-1, 1) + rng.normal(0.0, 1e-4) * t + walk + rng.normal(0, 5e-6, n)
        keep = np.ones(n, bool) if gap_s is None else ~((t >= gap_s[0]) & (t < gap_s[1]))
        for k, v in (
            ("time_s", t),
            ("run", np.full(n, r)),
            ("temperature_c", 20.0 + 10.0 * r + rng.normal(0.0, thermometer_c, n)),
            ("table_rate_dps", rng.normal(0.0, rate_jitter_dps, n)),
            ("wave_angle_deg", np.degrees(theta)),
        ):
            cols[k].append(v[keep])
    return hrgjax.MeasuredData({k: np.concatenate(v) for k, v in cols.items()})


def test_a_dropout_inside_static_runs_leaves_the_noise_estimate_as_it_is():
    """Audit finding 2: 30 s of samples missing mid-run. Differences that straddled the gap
    were labelled with the lag of equally spaced samples, and the drift times the time
    imbalance (1e-4 rad/s × 30 s) was read as angle random walk (200× the truth). On the
    samples' true times the drift cancels: the same N, and the truth, with or without it."""
    full = pn.NoiseModel.estimate(_static_log(0))
    gap = pn.NoiseModel.estimate(_static_log(0, gap_s=(100.0, 130.0)))
    for m in (full, gap):
        assert m.angle_random_walk == pytest.approx(1e-6, rel=0.2)
        assert m.angle_white == pytest.approx(5e-6, rel=0.05)
    assert gap.angle_random_walk == pytest.approx(full.angle_random_walk, rel=0.1)


def test_uneven_spans_give_the_model_variance_of_their_second_differences():
    """The true-time second difference of three samples t − a, t, t + b: no drift left, and
    its variance columns are the model's (Monte Carlo of white + walk + Gauss–Markov), equal
    to the lag-τ closed form where a = b = τ."""
    t = np.array([0.0, 0.5, 20.5, 21.0, 21.5])  # a 20-s gap between the 2nd and 3rd samples
    d2, cols = pn._d2_terms(t, 3.0 + 2e-3 * t, 1)
    assert np.max(np.abs(d2)) < 1e-12
    model = pn.NoiseModel(2e-6, 1e-6, 3e-8, pn.GM_TIMES[1])
    cov = model.angle_covariance(t)
    a, b = t[1:-1] - t[:-2], t[2:] - t[1:-1]
    h = (a + b) / 2
    for i in range(3):
        w = np.zeros(t.size)
        w[i : i + 3] = b[i] / h[i], -2.0, a[i] / h[i]
        coef = np.array([model.angle_white**2, model.angle_random_walk**2, model.gm_sigma**2])
        assert cols[i, [0, 1, 3]] @ coef == pytest.approx(w @ cov @ w, rel=1e-6)
    even = np.arange(9) * 0.5
    _, cols = pn._d2_terms(even, np.zeros(9), 2)
    for j, tc in enumerate(pn.GM_TIMES):
        assert cols[0, [0, 1, 2 + j]] == pytest.approx(pn._d2_basis(np.array([1.0]), tc)[0])


def test_table_rate_readback_jitter_leaves_static_runs_still():
    """Audit finding 4: a table rate read back with 1e-5 °/s of jitter (and a thermometer
    with 5 mK) made a log of static runs have no still stretch. Still is |rate| ≤
    STILL_RATE_DPS: the noise model reads them, and gets the truth; a turning table is not
    still."""
    log = _static_log(1, rate_jitter_dps=1e-5, thermometer_c=0.005)
    m = pn.NoiseModel.estimate(log)
    assert m.angle_random_walk == pytest.approx(1e-6, rel=0.2)
    assert m.angle_white == pytest.approx(5e-6, rel=0.05)
    n = 100
    jitter = np.random.default_rng(2).normal(0.0, 1e-5, n)
    assert pn._still_stretches(jitter, np.full(n, 20.0)) == [(0, n)]
    assert pn._still_stretches(0.01 + jitter, np.full(n, 20.0)) == []


def test_still_stretches_are_the_sample_by_sample_rule():
    """The NumPy search gives the stretches of the rule written sample by sample: still
    (|rate| ≤ STILL_RATE_DPS), the temperature within TEMPERATURE_TOLERANCE_C of the
    stretch's first sample (a sample beyond it starts the next), at least MIN_STRETCH
    samples — on random logs with jumps, drifts, ties and NaN."""
    from hrgjax.pattern_noise import (
        MIN_STRETCH,
        STILL_RATE_DPS,
        TEMPERATURE_TOLERANCE_C,
        _still_stretches,
    )

    def rule(rate, temp):
        out, start = [], None
        for i, (w, c) in enumerate(zip(rate, temp, strict=True)):
            still = abs(w) <= STILL_RATE_DPS
            if start is not None and (not still or abs(c - temp[start]) > TEMPERATURE_TOLERANCE_C):
                if i - start >= MIN_STRETCH:
                    out.append((start, i))
                start = None
            if start is None and still:
                start = i
        if start is not None and len(rate) - start >= MIN_STRETCH:
            out.append((start, len(rate)))
        return out

    rng = np.random.default_rng(1)
    for trial in range(60):
        n = int(rng.integers(1, 1500))
        rate = np.where(rng.random(n) < 0.01, 1.0, 1e-4 * rng.normal(size=n))
        temp = 20.0 + np.cumsum(rng.normal(size=n) * rng.choice([1e-3, 1e-2, 5e-2]))
        if trial % 5 == 0:
            temp[rng.integers(0, n)] = np.nan
        if trial % 7 == 0:
            temp[:] = 20.0 + TEMPERATURE_TOLERANCE_C * (np.arange(n) % 3 == 2)  # ties
        assert _still_stretches(rate, temp) == rule(rate, temp), trial


def test_gauss_markov_structure_and_second_difference_are_exact_where_tc_dwarfs_tau():
    """The Gauss–Markov angle's structure function and the lag-τ second difference's
    variance against 60-digit decimal arithmetic, from τ ≪ T_c (where the closed forms
    cancel: a second difference's column was −1.23 relative off at τ = 0.01 s, T_c = 3000
    s) to τ ≫ T_c; and the continuous records' block covariance equals the structure
    function on its diagonal."""
    from decimal import Decimal, getcontext

    from hrgjax.pattern_noise import _d2_basis, gm_structure

    getcontext().prec = 60

    def g(y):
        return y - 1 + (-y).exp()

    for tau, tc in [(1e-3, 3000.0), (0.01, 3000.0), (0.5, 30.0), (29.0, 3000.0), (100.0, 30.0)]:
        x, c = Decimal(tau) / Decimal(tc), Decimal(tc)
        want_s = float(2 * c**2 * g(x))
        want_d2 = float(2 * c**2 * (4 * g(x) - g(2 * x)))
        assert float(gm_structure(tau, tc)) == pytest.approx(want_s, rel=1e-11), (tau, tc)
        assert float(_d2_basis(np.array([tau]), tc)[0, 2]) == pytest.approx(want_d2, rel=1e-11)
    model = pn.NoiseModel(0.0, 0.0, gm_sigma=2e-6, gm_time=3000.0)
    cov = model.increment_covariance(0.01, 3)
    np.testing.assert_allclose(np.diag(cov), 4e-12 * float(gm_structure(0.01, 3000.0)), rtol=1e-13)


def _ramping_log(seed, sw=5e-6, n_arw=3e-7, dt=1.0, duration=3000.0):
    """Six static runs of `duration` [s] whose temperature ramps ±30 °C in 1000-s legs without a
    hold, the drift rate following it (3e-8 rad/s per °C), white angle noise and a walk
    drawn in, sampled every `dt` [s]."""
    rng = np.random.default_rng(seed)
    n = int(round(duration / dt)) + 1
    t = np.arange(n, dtype=float) * dt
    cols = {k: [] for k in ("time_s", "run", "wave_angle_deg", "table_rate_dps", "temperature_c")}
    for r in range(6):
        temp = 20.0 + 30.0 * (1.0 - np.abs((t / 1000.0 + r / 3.0) % 2.0 - 1.0) * 2.0)
        rate = 1e-6 + 3e-8 * (temp - 20.0)
        drift = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]))])
        walk = np.cumsum(rng.normal(0.0, n_arw * np.sqrt(dt), n))
        for k, v in (
            ("time_s", t),
            ("run", np.full(n, r)),
            ("table_rate_dps", np.zeros(n)),
            ("temperature_c", temp),
            ("wave_angle_deg", np.rad2deg(drift + walk + rng.normal(0.0, sw, n))),
        ):
            cols[k].append(v)  # fmt: skip
    return hrgjax.MeasuredData({k: np.concatenate(v) for k, v in cols.items()})


def test_a_log_that_ramps_without_a_hold_gives_the_noise_beside_its_drift():
    """Static runs whose temperature never holds have no still stretch: `estimate` refuses
    them, `estimate_drifting` reads the white angle noise and the walk drawn into them
    (NumPy) beside the drift rate the temperature moves (1.8e-9 rad/s² along a leg), the
    ramps' turns left out. Read as still stretches without the ramp's column, that drift
    was taken for noise. Discovery's `estimated` falls back to it and says so."""
    sw, n_arw = 5e-6, 3e-7
    logs = [_ramping_log(seed) for seed in range(4)]
    with pytest.raises(ValueError, match=r"estimate: .*table still .*temperature constant"):
        pn.NoiseModel.estimate(logs[0])
    models = [pn.NoiseModel.estimate_drifting(data) for data in logs]
    walks = np.array([m.angle_random_walk for m in models]) / n_arw
    assert np.all(np.abs(walks - 1.0) < 0.35), walks  # each: the walk is 7 % of the variance
    assert abs(np.mean(walks) - 1.0) < 0.12, walks  # at 64 s, its sampling spread is ≈ 15 %
    for m in models:
        assert m.angle_white == pytest.approx(sw, rel=0.05)
    data = logs[0]
    flat = hrgjax.MeasuredData(dict(data.columns, temperature_c=np.zeros(len(data))))
    bare = pn.NoiseModel.estimate(flat, max_lag_s=256.0)  # the same stretches, no ramp column
    assert max(bare.angle_random_walk, 10 * bare.gm_sigma) > 3 * n_arw, bare
    model, source = hrgjax.discovery.noise.estimated(data)
    assert model == models[0] and source == hrgjax.discovery.noise.NOISE_DRIFTING
    # sampled at 10 Hz the ramps leave still stretches of 1.7 s (0.1 °C at 0.06 °C/s): read
    # alone, their lags showed no walk at all (review); the fallback takes them too
    dense = _ramping_log(0, dt=0.1, duration=800.0)
    assert 0.0 < pn.longest_still_s(dense) < hrgjax.discovery.noise.SHORT_STILL_S
    assert pn.NoiseModel.estimate(dense).angle_random_walk < 0.5 * n_arw
    model, source = hrgjax.discovery.noise.estimated(dense)
    assert source == hrgjax.discovery.noise.NOISE_DRIFTING
    assert model.angle_random_walk == pytest.approx(n_arw, rel=0.35)
    spun = data["wave_angle_deg"] - 0.5 * data["time_s"]  # the pattern turns with the table
    turning = hrgjax.MeasuredData(
        dict(data.columns, table_rate_dps=np.ones(len(data)), wave_angle_deg=spun)
    )
    with pytest.raises(ValueError, match="table still .* this log has none; pass noise="):
        hrgjax.discovery.noise.estimated(turning)
