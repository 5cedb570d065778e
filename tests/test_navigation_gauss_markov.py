"""The loosely-coupled filter's Gauss–Markov bias states (`LooselyCoupled(gauss_markov=True)`):
their discretisation against the exact Van Loan exponential and the process's closed form at
any T/τ, their σ against Monte Carlo truth where the fold into a random walk overstates them,
and the limit τ → ∞, where they are the fold's constant bias split in two."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter, flight_motion
from scipy.integrate import quad

from hrgjax import kalman
from hrgjax.ins import ekf, gnss, sensors
from hrgjax.ins.strapdown import error_matrices_at
from hrgjax.units import DEG_PER_H, DEG_PER_SQRT_H

OUTAGE = (70.0, 90.0)
SIGMA_G, SIGMA_A = 30 * DEG_PER_H, 500 * sensors.MICRO_G


def imu(tau, **kw):
    """benchmarks/nav_gm_fold.py's sensor (`--gauss-markov`): Gauss–Markov biases of σ
    30 °/h and 500 µg, fixed biases a tenth of that."""
    fields = dict(
        gyro_bias=3 * DEG_PER_H,
        accel_bias=50 * sensors.MICRO_G,
        arw=0.01 * DEG_PER_SQRT_H,
        vrw=10 * sensors.MICRO_G,
        gyro_bias_instability=SIGMA_G,
        accel_bias_instability=SIGMA_A,
        gyro_correlation_time=tau,
        accel_correlation_time=tau,
    )
    return sensors.ImuModel(**(fields | kw))


@pytest.fixture(scope="module")
def truth():
    """tests/test_navigation_filter.py's 120-s flight, 10 Hz."""
    return flight_motion().truth(10.0)


def test_discretisation_is_exact_for_any_interval_over_tau(truth):
    """Φ and Q_d of the 21-state model (15 + 6 Gauss–Markov) in the banked turn, against
    `kalman.van_loan` (in units of the states' σ) and the Gauss–Markov block against its
    closed form e^(−T/τ), σ²(1 − e^(−2T/τ)), from T/τ = 1e-3 to 1e3 (the series
    alone, without `fastest`, had the decay e^(−T/τ) 0.8 off at T/τ = 3, 3e7× at 10)."""
    k = 400
    s, f = truth.states[k], truth.dv[k] / truth.dt
    f9, gg, ga = error_matrices_at(truth.earth, False, s.lat, s.h, s.v_ned, s.c_bn, s.c_bn @ f)
    sig = np.r_[1.6e-7, 1.6e-7, 1.0, [0.1] * 3, [1e-3] * 3, [SIGMA_G] * 3, [SIGMA_A] * 3]
    sig = np.r_[sig, sig[9:]]
    noise = jnp.concatenate([jnp.concatenate([gg, ga], -1), jnp.zeros((12, 6))])
    q0 = noise @ jnp.diag(jnp.r_[jnp.full(3, 1e-7), jnp.full(3, 2e-6)] ** 2) @ noise.T
    top = jnp.concatenate([f9, gg, ga, gg, ga], -1)

    def model(tau):
        big = jnp.concatenate([top, jnp.zeros((12, 21))]).at[15:, 15:].set(-jnp.eye(6) / tau)
        drive = 2 * jnp.r_[jnp.full(3, SIGMA_G**2), jnp.full(3, SIGMA_A**2)] / tau
        return big, q0 + jnp.diag(jnp.r_[jnp.zeros(9), jnp.full(6, 1e-16), drive])

    # τ is a value (the squarings' count too): one program per interval T for every τ
    step = jax.jit(lambda tau, T: ekf.discretise(*model(tau), T, fastest=1.0 / tau),
                   static_argnums=1)  # fmt: skip
    for T, r in [(1.0, x) for x in (1e-3, 1e-2, 0.1, 1.0, 3.0, 10.0, 100.0, 1e3)] + [
        (10.0, 0.1),
        (30.0, 10.0),
    ]:
        tau = T / r
        big, q = model(tau)
        phi, qd = (np.asarray(a) for a in step(tau, T))
        phi_x, qd_x = (np.asarray(a) for a in kalman.van_loan(big, q, T))
        err_phi = np.abs((phi - phi_x) * sig[None] / sig[:, None]).max()
        err_q = np.abs((qd - qd_x) / np.outer(sig, sig)).max()
        assert err_phi < 1e-10 and err_q < 1e-10, (T, r, err_phi, err_q)  # ≤ 1.1e-11, 3e-12
        gm = np.diag(phi)[15:], np.diag(qd)[15:] / np.r_[[SIGMA_G**2] * 3, [SIGMA_A**2] * 3]
        np.testing.assert_allclose(gm[0], np.exp(-r), rtol=1e-11, atol=0)
        np.testing.assert_allclose(gm[1], -np.expm1(-2 * r), rtol=1e-11, atol=0)
    assert step._cache_size() == 3
    # and its derivative reaches τ: d e^(−T/τ)/dτ = e^(−T/τ)·T/τ², on both sides of a squaring
    for tau in (0.3, 2.0):
        got = jax.grad(lambda t: step(t, 1.0)[0][15, 15])(tau)
        assert float(got) == pytest.approx(np.exp(-1.0 / tau) / tau**2, rel=1e-9), tau
    # called eagerly: one program, which another τ's call does not compile again (the
    # squarings' conds were traced anew on each call: 6 compiles), equal to the jitted one
    tau = 0.3
    big, q = model(tau)
    ekf.discretise(*model(2.0), 1.0, fastest=0.5)
    with CompileCounter() as c:
        phi, qd = ekf.discretise(big, q, 1.0, fastest=1.0 / tau)
    assert c.compiles == 0, c.names
    for got, want in zip((phi, qd), step(tau, 1.0), strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-30)
    # a Gauss–Markov decay the series cannot take over the step without `fastest` (it read
    # e^(−10) as 1343), and a q that is no spectral density, are refused in one line
    for fastest in (0.0, 1.0):
        with pytest.raises(ValueError, match=r"^discretise: F has a decay rate \|F_ii\| = 3.33333"
                           r" /s, too fast .* pass fastest=3.33333"):  # fmt: skip
            ekf.discretise(big, q, 1.0, fastest=fastest)
    with pytest.raises(ValueError, match=r"^discretise: q must be positive semi-definite"):
        ekf.discretise(big, -q, 1.0, fastest=1.0 / tau)


def _z(res, e):
    """(…, M, 15) error / σ, the bias columns the total bias's (fixed + Gauss–Markov)."""
    p = res.P
    var = jnp.diagonal(p, axis1=-2, axis2=-1)
    if not res.gauss_markov:
        return e / jnp.sqrt(var)
    k, g = jnp.arange(9, 15), jnp.arange(15, 21)
    v = var[..., 9:15] + var[..., 15:21] + 2 * p[..., k, g]
    total = (e[..., 9:15] + e[..., 15:21]) / jnp.sqrt(v)
    return jnp.concatenate([e[..., :9] / jnp.sqrt(var[..., :9]), total], -1)


@pytest.fixture(scope="module")
def monte_carlo(truth):
    """32 runs at τ = 1 s through both filters on the same draws: z-RMS after the start of
    attitude and total gyro bias, and the mean NIS / 6 (fold, Gauss–Markov); the
    Gauss–Markov filter's gyro and accelerometer Gauss–Markov states' own z-RMS (against the
    bias at the fix) and its estimates `estimates` (R, M, 6) with the outage's epochs."""
    rx = gnss.Gnss()
    sensor = imu(1.0)
    t = np.concatenate([[0.0], rx.epochs(truth.dtheta.shape[0], truth.dt) * truth.dt])
    mask = jnp.asarray(~((t[1:] >= OUTAGE[0]) & (t[1:] <= OUTAGE[1])))
    m = 10
    at = jnp.concatenate([jnp.zeros(1, int), jnp.arange(m - 1, truth.dtheta.shape[0], m)])
    tn = truth.states[::m]

    def one(key, tau):  # the filters' τ a value (the sensor's is 1 s)
        fold = ekf.LooselyCoupled(imu(tau), rx)
        gm = ekf.LooselyCoupled(imu(tau), rx, gauss_markov=True)
        k_unit, k_imu, k_gnss, k_init = jax.random.split(key, 4)
        unit = sensors.random_unit(sensor, k_unit)
        dth, dv, bg, ba, gg, ga = unit.apply(
            k_imu, truth.dtheta, truth.dv, truth.dt, return_bias="gauss_markov"
        )
        fixes = gnss.measure(truth, rx, k_gnss)
        fixes = eqx.tree_at(lambda f: f.valid, fixes, fixes.valid & mask)
        p0 = fold.initial_covariance(truth.initial)
        start = ekf.feedback(
            truth.initial, -kalman.psd_factor(p0[:9, :9]) @ jax.random.normal(k_init, (9,))
        )
        out = []
        for s in (fold, gm):
            res = ekf.loosely_coupled(s, start, dth, dv, truth.dt, fixes)
            e = ekf.error_states(res, tn, bg[at], ba[at], gyro_gm=gg[at], accel_gm=ga[at])
            out += [_z(res, e), res.nis]
        own = e[:, 15:21] / jnp.sqrt(jnp.diagonal(res.P, axis1=-2, axis2=-1)[:, 15:21])
        return (*out, own, jnp.concatenate([res.gyro_gm, res.accel_gm], -1))

    run = jax.jit(jax.vmap(one, in_axes=(0, None)))
    zf, nf, zg, ng, own, est = run(keys := jax.random.split(jax.random.key(0), 32), 1.0)
    rms = lambda z, s: float(jnp.sqrt(jnp.mean(z[:, 1:, s] ** 2)))  # noqa: E731
    out = {
        name: (rms(z, slice(6, 9)), rms(z, slice(9, 12)), float(jnp.nanmean(n[:, 1:]) / 6))
        for name, z, n in (("fold", zf, nf), ("gm", zg, ng))
    }
    out["gm_states"] = (rms(own, slice(0, 3)), rms(own, slice(3, 6)))
    return out | {"estimates": np.asarray(est), "outage": np.flatnonzero(~np.asarray(mask)) + 1,
                  "run": lambda tau: run(keys, tau)}  # fmt: skip


def test_gauss_markov_states_give_honest_sigma_where_the_fold_overstates_them(monte_carlo):
    """τ = 1 s (one fix interval), 32 runs: the fold's attitude and gyro-bias z-RMS 0.44,
    0.39 (σ 2.3×, 2.6× the errors' RMS), mean NIS / 6 0.927; the Gauss–Markov filter's 0.99,
    1.00, 0.997, its Gauss–Markov states' own 1.01 (gyro), 1.00 (accelerometer) against the
    bias at the fix (64 runs, benchmarks/nav_gm_fold.py --gauss-markov: 1.06, 0.99 at
    τ = 1 s). The bounds hold the Monte Carlo's spread (the 64-run rows' 1.01–1.06 and
    0.95–1.03 from τ = 0.3 to 100 s, another seed's 32 runs 1.10, 0.99) with room; the
    NIS's 99 % band over ~3 000 fixes is ±0.027."""
    att, bg, nis = monte_carlo["gm"]
    assert 0.8 < att < 1.25 and 0.8 < bg < 1.25, monte_carlo
    assert all(0.85 < z < 1.2 for z in monte_carlo["gm_states"]), monte_carlo
    assert 0.97 < nis < 1.03, monte_carlo  # the fold's 0.925 is below the 99 % band
    att, bg, nis = monte_carlo["fold"]
    assert att < 0.6 and bg < 0.6 and nis < 0.95, monte_carlo


def test_the_filters_correlation_time_is_a_checked_value(monte_carlo):
    """The filter's τ is a value (the flights' program is the same for any τ) held to
    `ImuModel`'s rule when the program runs (review of fa3b04e: a traced τ ≤ 0 ran, Φ's decay
    e^(+T/|τ|)): the filter refuses it, naming the field."""
    with pytest.raises(Exception, match="ImuModel.gyro_correlation_time must be a finite time"):
        monte_carlo["run"](-1.0)


def test_feedback_decays_the_gauss_markov_estimate_as_the_process_mean(monte_carlo):
    """The feedback rule, pinned: in the 20-s outage (no update) the Gauss–Markov estimates
    are the process's conditional mean, ĝ(t_k) = ĝ(t_k−1)·e^(−T/τ), to rounding (with the
    decay left out at the fix they stay put: ratio 1, not e^(−1)); and each IMU step is
    corrected by the mean of e^(−t/τ) over the step (against quadrature: with the estimate
    at the block's start on every step instead, the Monte Carlo moves by < 1 %, below what
    32 runs resolve — rev3)."""
    est, k = monte_carlo["estimates"], monte_carlo["outage"]
    np.testing.assert_allclose(est[:, k], np.exp(-1.0) * est[:, k - 1], rtol=1e-12, atol=0)
    size = np.abs(est[:, k[0] - 1]) / np.r_[[SIGMA_G] * 3, [SIGMA_A] * 3]
    assert np.median(size) > 0.01, np.median(size)  # the outage starts from real estimates
    settings = ekf.LooselyCoupled(imu(0.7, accel_correlation_time=2.0), gnss.Gnss(),
                                  gauss_markov=True)  # fmt: skip
    mean, decay = settings._gm_decay(0.1, 10)
    t = 0.1 * np.arange(11)
    for col, tau in enumerate((0.7, 2.0)):
        want = [quad(lambda x, c: np.exp(-x / c), a, b, args=(tau,))[0] / 0.1
                for a, b in zip(t[:-1], t[1:], strict=True)]  # fmt: skip
        np.testing.assert_allclose(mean[:, col], want, rtol=1e-13, atol=0)
        assert decay[col] == pytest.approx(np.exp(-1.0 / tau), rel=1e-15)


def test_apply_returns_the_gauss_markov_bias_at_the_interval_end():
    """`return_bias="gauss_markov"` at τ = Δt (where the interval mean's variance is 0.74σ²):
    the Gauss–Markov part is the point process, variance σ² and lag-1 correlation
    e^(−Δt/τ) (20 000 × 3 samples: ±3 %, ±2 % at 3σ); total − that part is the rest (here
    the fixed bias) to rounding, and `return_bias=True`'s total is the increments' mean
    bias. `return_bias` takes bools of any kind and 0 / 1, nothing else."""
    n, dt, s = 20_000, 0.1, SIGMA_G
    unit = sensors.ImuModel(gyro_bias=(1e-5, -2e-5, 3e-5), gyro_bias_instability=s,
                            gyro_correlation_time=dt)  # fmt: skip
    key, z = jax.random.key(5), jnp.zeros((n, 3))
    dth, _, bg, _, gg, _ = unit.apply(key, z, z, dt, return_bias="gauss_markov")
    g = np.asarray(gg) / s
    assert np.var(g) == pytest.approx(1.0, abs=0.03)  # the interval means': 0.74
    lag1 = np.mean(g[1:] * g[:-1]) / np.mean(g * g)
    assert lag1 == pytest.approx(np.exp(-1.0), abs=0.02)
    np.testing.assert_allclose(bg - gg, np.broadcast_to(unit.gyro_bias, (n, 3)), rtol=0,
                               atol=1e-12 * s)  # fmt: skip
    z = z[:4]
    for flag, size in ((True, 4), (np.bool_(True), 4), (1, 4), (jnp.asarray(False), 2), (0, 2)):
        out = unit.apply(key, z, z, dt, return_bias=flag)
        assert len(out) == size, flag
    np.testing.assert_allclose(out[0] / dt, unit.apply(key, z, z, dt, return_bias=1)[2],
                               rtol=1e-12, atol=0)  # fmt: skip
    for bad in (2, "gm", None, (True,)):
        with pytest.raises(ValueError, match=r"^ImuModel.apply: return_bias must be False, True"):
            unit.apply(key, z, z, dt, return_bias=bad)


def test_long_tau_is_the_fold_with_its_constant_bias_split_in_two(truth):
    """τ = 1e9 s: no decay, no drive, so the fixed and Gauss–Markov states are one constant
    bias of prior σ² = gyro_bias² + σ², the fold's: the same navigation, total bias and
    covariance of the navigation states, filtered and smoothed (to ≤ 1e-5 of their σ: the
    rounding of two different factorisations). And the new fields, shapes and
    one-line errors."""
    rx = gnss.Gnss()
    fold = ekf.LooselyCoupled(imu(1e9), rx)
    gm = ekf.LooselyCoupled(imu(1e9), rx, gauss_markov=True)
    assert (fold.n_states, gm.n_states) == (15, 21)
    assert (
        ekf.LooselyCoupled(
            imu(1.0, gyro_scale=1e-4, accel_scale=1e-4), rx, scale_factors=True, gauss_markov=True
        ).n_states
        == 27
    )
    unit = sensors.random_unit(fold.imu, jax.random.key(1))
    dth, dv = unit.apply(jax.random.key(2), truth.dtheta, truth.dv, truth.dt)
    fixes = gnss.measure(truth, rx, jax.random.key(3))
    a, b = (ekf.loosely_coupled(s, truth.initial, dth, dv, truth.dt, fixes) for s in (fold, gm))
    assert b.P.shape[-1] == 21 and b.gauss_markov and not a.gauss_markov
    for x, y in ((a, b), (ekf.smooth(a), ekf.smooth(b))):
        np.testing.assert_allclose(y.nav.lat, x.nav.lat, rtol=0, atol=1e-12)
        np.testing.assert_allclose(y.nav.v_ned, x.nav.v_ned, rtol=0, atol=1e-6)
        np.testing.assert_allclose(y.nav.q_bn, x.nav.q_bn, rtol=0, atol=1e-8)
        for tot, ref, s in ((y.gyro_bias + y.gyro_gm, x.gyro_bias, SIGMA_G),
                            (y.accel_bias + y.accel_gm, x.accel_bias, SIGMA_A)):  # fmt: skip
            np.testing.assert_allclose(tot, ref, rtol=0, atol=1e-5 * s)
        d = np.sqrt(np.diagonal(np.asarray(x.P)[:, :9, :9], axis1=1, axis2=2))
        corr = d[:, :, None] * d[:, None, :]  # the covariances in correlation units
        np.testing.assert_allclose(y.P[:, :9, :9] / corr, x.P[:, :9, :9] / corr, rtol=0, atol=1e-6)
    with pytest.raises(ValueError, match=r"^error_states: a filter with Gauss–Markov states"):
        ekf.error_states(b, truth.states[::10], unit.gyro_bias, unit.accel_bias)
    with pytest.raises(ValueError, match=r"^LooselyCoupled: the IMU model's gyro_bias is.*"
                       r"with gauss_markov=True .* give gyro_bias its own σ > 0"):  # fmt: skip
        ekf.LooselyCoupled(eqx.tree_at(lambda i: i.gyro_bias, imu(1.0), jnp.zeros(3)), rx,
                           gauss_markov=True)  # fmt: skip
