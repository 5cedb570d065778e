"""Are the filter bank's probabilities honest? Against known truth (docs/diagnosis.md,
"Calibration"):

- records drawn from the bank's own prior for a fault present from the first sample
  (hypothesis uniform over S0 … S3, size ~ N(0, fault_sigma²)): the independent bank with
  `switch_prob` 0 and `fault_walk` 0 is then the exact Bayes posterior, so its mean
  reported max-probability must equal the share of runs its argmax gets right, within the
  binomial scatter; the default bank must too (with `fault_walk` 1e-8 it reported S0 at
  p ≈ 1 on every run: accuracy 1/4);
- the model-fit test (windowed NIS, χ²) fails a right model on a share ≈ its level;
- measurement noise 3× the assumed `meas_sigma` is flagged "does not fit" (−2) instead of
  being decided a fault at p ≈ 0.99.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hrgjax.diagnosis import complex as cx
from hrgjax.diagnosis import filter_bank as fb
from hrgjax.ins.platform import FAULTS, Fault, PlatformINS, simulate

INS = PlatformINS()
COL = FAULTS.index("accel_y")


@jax.jit
def _records(keys, e, t_fault, sigma):
    """(R, K, 2) north-accelerometer measurements of 3-INS complexes: INS i's fault e[r, i]
    from t_fault[r, i], white measurement noise sigma[r]."""

    def one(key, e3, t3, s):
        k_sim, k_noise = jax.random.split(key)
        f = Fault(jnp.zeros((3, 6)).at[:, COL].set(e3), t3)
        run = lambda k, f: simulate(INS, dt=1.0, n_steps=K_LEN, key=k, fault=f)[2]
        nav = jax.vmap(run)(jax.random.split(k_sim, 3), f)
        z = cx.measurements(nav, 1.0, "accel_y", INS)
        return z + s * jax.random.normal(k_noise, z.shape)

    return jax.vmap(one)(keys, e, t_fault, sigma)


K_LEN = 60
N_PRIOR = 240  # runs drawn from the prior (60 per hypothesis)
N_HEALTHY = 16


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(3)
    truth = np.arange(N_PRIOR) % 4
    e = np.zeros((N_PRIOR + 2 * N_HEALTHY, 3))
    t = np.full(e.shape, np.inf)
    rows = np.flatnonzero(truth > 0)
    e[rows, truth[rows] - 1] = rng.normal(0.0, 3e-7, rows.size)
    t[rows, truth[rows] - 1] = 0.0
    sigma = np.r_[np.full(N_PRIOR + N_HEALTHY, 1e-9), np.full(N_HEALTHY, 3e-9)]
    keys = jax.random.split(jax.random.key(11), e.shape[0])
    z = np.asarray(_records(keys, jnp.asarray(e), jnp.asarray(t), jnp.asarray(sigma)))
    return truth, z[:N_PRIOR], z[N_PRIOR : N_PRIOR + N_HEALTHY], z[N_PRIOR + N_HEALTHY :]


def _reliability(probs, truth):
    """Mean reported max-probability and accuracy of the argmax at the last step, and the
    binomial tolerance (3σ of the accuracy, plus 0.02 for the finite sample of the mean)."""
    p = np.asarray(probs)[:, -1]
    acc = np.mean(p.argmax(-1) == truth)
    return p.max(-1).mean(), acc, 3.0 * np.sqrt(acc * (1 - acc) / len(truth)) + 0.02


def test_default_bank_is_calibrated_on_a_fault_present_from_the_start(data):
    truth, z, _, _ = data
    uniform = jnp.full(4, 0.25)
    exact = cx.fault_bank(INS, "accel_y", 1.0, switch_prob=0.0, fault_walk=0.0)
    default = cx.fault_bank(INS, "accel_y", 1.0, switch_prob=0.0)
    run = jax.jit(jax.vmap(lambda b, z: fb.run_bank(b, z, prior=uniform, floor=1e-12)[0],
                           in_axes=(None, 0)))  # fmt: skip
    for name, probs in (("exact posterior", run(exact, z)), ("default bank", run(default, z))):
        mean_p, acc, tol = _reliability(probs, truth)
        # a constant fault from t = 0 looks like the Markov sensor error: barely identifiable
        assert acc < 0.7, (name, acc)
        assert abs(mean_p - acc) < tol, (name, mean_p, acc, tol)


def test_model_fit_test_fails_a_right_model_at_its_level(data):
    _, _, healthy, _ = data
    bank = cx.fault_bank(INS, "accel_y", 1.0, switch_prob=0.0, fault_walk=0.0)
    # the independent bank's S0 filter is the exact Kalman filter of the healthy records:
    # its NIS is χ²(2) and white, so each windowed test fails it at its level
    run = jax.vmap(lambda z: fb.run_bank(bank, z, fit_window=10, fit_level=0.05,
                                         return_fit=True))  # fmt: skip
    probs, dec, _, fit = run(jnp.asarray(healthy))
    assert set(fit) >= {"stat", "dof", "p_value", "fits", "nis"}
    nis = np.asarray(fit["nis"])  # (runs, K, M)
    for window, level in ((1, 0.05), (10, 0.05), (10, 0.01)):
        test = lambda x, w=window, lv=level: fb.model_fit(x, 2, window=w, level=lv)["fits"]
        fits = np.asarray(jax.vmap(test)(nis))[..., 0]
        n_eff = fits.size / window  # overlapping windows: about one independent test each
        tol = 3.0 * np.sqrt(level * (1 - level) / n_eff) + 0.5 / n_eff
        assert abs(np.mean(~fits) - level) < tol, (window, level, np.mean(~fits), tol)
    # run_bank's own test is model_fit's on its NIS, and a failing leader is decided −2
    np.testing.assert_array_equal(fit["fits"][0], fb.model_fit(nis[0], 2, window=10,
                                                               level=0.05)["fits"])  # fmt: skip
    best = np.asarray(probs).argmax(-1)[..., None]
    lead_fits = np.take_along_axis(np.asarray(fit["fits"]), best, -1)[..., 0]
    assert (~lead_fits).any() and np.all((np.asarray(dec) == -2) == ~lead_fits)
    # the statistic by hand: window sums of the NIS, χ² tail
    nis = np.random.default_rng(0).chisquare(2, (30, 1))
    fit = fb.model_fit(nis, 2, window=5, level=0.01)
    assert fit["dof"].tolist() == [2, 4, 6, 8] + [10] * 26
    np.testing.assert_allclose(fit["stat"][7, 0], nis[3:8, 0].sum())
    np.testing.assert_allclose(fit["stat"][2, 0], nis[:3, 0].sum())
    p = fit["p_value"][7, 0]  # χ²(10) upper tail, by its closed form for even dof
    x = nis[3:8, 0].sum() / 2
    np.testing.assert_allclose(
        p, np.exp(-x) * sum(x**j / np.prod(np.arange(1, j + 1)) for j in range(5)), rtol=1e-10
    )


def test_measurement_noise_three_times_meas_sigma_is_flagged_not_decided_a_fault(data):
    _, _, healthy, noisy = data
    bank = cx.fault_bank(INS, "accel_y", 1.0, switch_prob=1e-4)  # as compare builds it
    gains = fb.GainBank.from_bank(bank, K_LEN)
    prior = jnp.asarray([0.97, 0.01, 0.01, 0.01])
    kw = dict(interacting=True, prior=prior, fit_level=fb.FIT_LEVEL)
    full = jax.jit(jax.vmap(lambda z: fb.run_bank(bank, z, **kw)[1]))
    for name, run in (("full IMM", full), ("gain IMM", lambda z: fb.run_gains(gains, z, **kw)[1])):
        d_ok, d_bad = np.asarray(run(healthy)), np.asarray(run(noisy))
        assert np.mean(d_ok > 0) == 0.0 and np.mean(d_ok == -2) < 0.02, name
        late = d_bad[:, 20:]  # the test needs a few steps of evidence
        assert np.mean(late > 0) < 0.05, (name, np.mean(late > 0))
        assert np.mean(late == -2) > 0.7, (name, np.mean(late == -2))


def test_a_fault_between_samples_acts_from_its_onset_and_has_a_gradient():
    """`Fault.t_fault` between two samples: the step that holds it counts its share after the
    onset, so a coarse grid (20 s) gives a fine one's (1 s, onset on the grid) navigation
    error at 600 s (2.5e-4 relative; a 0/1 switch at the next sample: 1.9e-2) and
    ∂/∂t_fault is the onset's sensitivity (within 1 % of the fine grid's central difference;
    the 0/1 switch gave 0)."""

    def end(dt, n, t_fault):  # the first navigation error at the end of the run
        fault = Fault.on("accel_y", 1e-6, t_fault)
        return simulate(INS, dt=dt, n_steps=n, key=None, fault=fault)[2][-1, 0]

    fine = float(end(1.0, 600, 95.0))
    assert float(end(20.0, 30, 95.0)) == pytest.approx(fine, rel=1e-3)
    grad = jax.grad(lambda t: end(20.0, 30, t))(95.0)
    fd = (float(end(1.0, 600, 96.0)) - float(end(1.0, 600, 94.0))) / 2.0
    assert fd < 0 and float(grad) == pytest.approx(fd, rel=0.015)
